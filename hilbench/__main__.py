"""``python -m hilbench``: the same as the ``hilbench`` command."""

import sys

from hilbench.bench.cli import main

sys.exit(main())
