"""examples/residual_emps.py runs in a clone: on the vendored EMPS files, without HILBENCH_REAL_DATA."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "examples" / "residual_emps.py"


def test_residual_emps_example_runs_on_the_vendored_data(tmp_path):
    # Why: "In a user's clone the EMPS reproduction silently skips, and examples/residual_emps.py fails"
    env = {k: v for k, v in os.environ.items() if k != "HILBENCH_REAL_DATA"} | {"MPLBACKEND": "Agg"}
    res = subprocess.run([sys.executable, str(SCRIPT), str(tmp_path / "out")], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    # the published IDIM-LS relative errors are 4.0834 % and 5.9824 % (Janot et al. 2019); the example
    # reproduces them on the vendored files (measured 4.05 % and 5.95 %)
    m = re.search(r"IDIM-LS reproduced here: ([\d.]+) % / ([\d.]+) %", res.stdout)
    assert m, res.stdout
    assert abs(float(m[1]) - 4.0834) < 0.1 and abs(float(m[2]) - 5.9824) < 0.1
    report = json.loads((tmp_path / "out" / "emps.json").read_text())
    # the reference model (M, Fc, Fv, offset) on the validation file: within the published 6 % (measured 4.45 %)
    assert 0 < report["error_before"]["validation"]["torque_rel_pct"] < 6.0
    assert "HSM150: skipped (set HILBENCH_REAL_DATA" in res.stdout
