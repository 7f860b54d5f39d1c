"""The fork server's preload (bench.campaign_analysis.fork_server.WORKER_MODULES) is what the default step imports:
nothing it lists is left unused by an identify task (each costs CPU on the local cluster's start-up path), and after
the preload the task imports no more of numpy, scipy or h5py (a worker would pay that on its first task)."""

from __future__ import annotations

import json
import subprocess
import sys

from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign

#: a fresh interpreter: one identify step on a run as a worker runs it (engine.execute), alone or after the preload;
#: prints the preloaded modules the step never
#: needed (imported by the preload but absent from a fresh interpreter that ran only the step) and what the step
#: imported after the preload
PROBE = """
import json, sys
run = sys.argv[1]
if sys.argv[2] == "step-only":
    from hilbench.bench.campaign_analysis.fork_server import WORKER_MODULES
    from hilbench.bench.campaign_analysis.engine import execute
    from hilbench.bench.campaign_analysis.steps import StepSettings
    assert execute(run, "identify", StepSettings())["status"] == "ok"
    print(json.dumps([m for m in WORKER_MODULES if m not in sys.modules]))
else:
    from hilbench.bench.campaign_analysis.fork_server import warm_up
    warm_up()
    before = set(sys.modules)
    from hilbench.bench.campaign_analysis.engine import execute
    from hilbench.bench.campaign_analysis.steps import StepSettings
    assert execute(run, "identify", StepSettings())["status"] == "ok"
    heavy = ("numpy", "scipy", "h5py", "matplotlib")
    print(json.dumps(sorted(m for m in set(sys.modules) - before if m.split(".")[0] in heavy)))
"""


def _probe(run: str, mode: str) -> list[str]:
    done = subprocess.run([sys.executable, "-c", PROBE, run, mode], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_preload_is_what_the_identify_step_imports(tmp_path):
    write_campaign(tmp_path / "c", SyntheticCampaign(runs=1, duration=2.0, sample_rate=1000.0, seed=1))
    run = str(next((tmp_path / "c").glob("*.h5")))
    assert _probe(run, "step-only") == []  # every preloaded module is one the step imports
    assert _probe(run, "preloaded") == []  # and the preload leaves none of the heavy ones for the first task
