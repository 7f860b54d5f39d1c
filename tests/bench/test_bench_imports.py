"""What importing the bench layer costs: the CLI's module and ``hilbench analyse``'s early cluster start import no
numpy and no acquisition module (the cluster's host starts before them: its fork server's imports are the start-up's
critical path), and the protocol table is whole for whoever imports it, however it is reached."""

from __future__ import annotations

import json
import subprocess
import sys


def _fresh(program: str) -> object:
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_the_early_cluster_start_imports_no_numpy():
    heavy = _fresh("import json, sys\n"
                   "import hilbench.bench.cli.main, hilbench.bench.cli.commands.analyse\n"
                   "import hilbench.bench.campaign_analysis.cluster_host, hilbench.bench.campaign_index\n"
                   "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in ('numpy', 'scipy', 'h5py')"
                   " or m.startswith('hilbench.bench.acquisition'))))")
    assert heavy == []


def test_the_protocol_table_is_whole_from_any_door():
    # the break-away probe and the compensated protocol add themselves to the table (bench/acquisition/__init__.py)
    for door in ("hilbench.bench.acquisition.protocols", "hilbench.bench.acquisition.campaign", "hilbench.bench"):
        names = _fresh(f"import json, importlib\nimportlib.import_module({door!r})\n"
                       "from hilbench.bench.acquisition.protocols import PROTOCOLS\n"
                       "print(json.dumps(sorted(PROTOCOLS)))")
        assert {"breakaway_probe", "compensated", "identification"} <= set(names), door
