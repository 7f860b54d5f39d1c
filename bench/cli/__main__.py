"""``python -m hilbench.bench.cli``: the ``hilbench`` command."""

import sys

from hilbench.bench.cli.main import main

sys.exit(main())
