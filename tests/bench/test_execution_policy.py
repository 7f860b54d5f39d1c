"""Every consumer runs an analysis under the execution policy (analysis/execution.py: one BLAS thread): the
``hilbench`` command and the GUI's analysis worker, each in a fresh process without the thread variables that
make test sets, the fit's BLAS libraries read with threadpoolctl while it runs. (The campaign workers, serial
and on Dask: tests/bench/campaign_analysis/test_analyse.py.)"""

import json
import os
import subprocess
import sys

import pytest

from hilbench.analysis import execution
from tests.bench.test_identify_command import _write_run

_CHILD = """
import json, sys
from hilbench.analysis import execution
from hilbench.analysis.identification import maxwell_fit

seen = []
real = maxwell_fit.fit_lip_chunks

def probe(*args, **kwargs):  # the fit, with its BLAS libraries' threads read as it starts and as it ends
    seen.append(execution.blas_threads())
    try:
        return real(*args, **kwargs)
    finally:
        seen.append(execution.blas_threads())  # by now scipy's own OpenBLAS is loaded too

maxwell_fit.fit_lip_chunks = probe
path, out, mode = sys.argv[1:4]
if mode == "cli":
    from hilbench.bench.cli.main import main
    rc = main(["identify", path, "--json", out + ".model.json"])
else:  # the GUI's analysis worker, in its own thread
    from hilbench.bench.gui.run_browser import AnalysisWorker
    failed = []
    worker = AnalysisWorker("identify", path, {})
    worker.failed.connect(failed.append)
    worker.start()
    worker.wait()
    rc = 1 if failed else 0
with open(out, "w") as f:
    json.dump({"rc": rc, "seen": seen}, f)
"""


def _threads_in_fit(tmp_path, mode: str) -> list[dict]:
    _write_run(tmp_path / "a.h5", 1)
    script = tmp_path / "child.py"
    script.write_text(_CHILD)
    env = {k: v for k, v in os.environ.items() if k not in execution.ENVIRONMENT}
    done = subprocess.run([sys.executable, str(script), str(tmp_path / "a.h5"), str(tmp_path / "seen.json"), mode],
                          capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads((tmp_path / "seen.json").read_text())
    assert result["rc"] == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return result["seen"]


@pytest.mark.parametrize("mode", ["cli", "gui"])
def test_an_analysis_runs_with_one_blas_thread(tmp_path, mode):
    if mode == "gui":
        from hilbench.bench.gui.app import qt_problem

        if qt_problem():
            pytest.skip(f"GUI cannot run here: {qt_problem()}")
    seen = _threads_in_fit(tmp_path, mode)
    assert seen, "the fit did not run"
    for threads in seen:  # numpy's OpenBLAS and, as the fit ends, scipy's own: all at the policy's count
        assert set(threads.values()) == {execution.THREADS}, threads
    assert len(seen[-1]) >= 2, seen[-1]
