"""The run browser's analyses as plain functions (no window): the presliding analysis shows what
``hilbench presliding`` writes, and refuses a record it cannot analyse in one line."""

from __future__ import annotations

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.bench.gui.analyses import ANALYSES, availability, presliding, run_analysis, titles
from hilbench.common import runfile as rf
from tests.bench.presliding_runs import run_and_analyse


def test_the_presliding_analysis_shows_the_numbers_the_command_writes(tmp_path):
    """A short presliding run on the simulated bench (8 d/s, 2^16 counts/rev), analysed by the browser's function
    and by `hilbench presliding` with the same bootstrap: every quantity, the edge-pinned sum(k) and each reversal's
    extreme force agree to the digits shown; every number names its unit; the resolution lines are the warnings."""
    assert availability("presliding") == "" and ANALYSES["presliding"] is presliding and "presliding" in titles()
    h5, doc = run_and_analyse(tmp_path, 65536, "--rate", "8", "--settle", "0.05", replicates=8)
    result = run_analysis("presliding", h5, {"replicates": 8})
    shown = {q: (v, u) for q, v, u in result.numbers}
    assert all(u for _q, (_v, u) in shown.items())
    resolved = doc["resolution"]["resolved"]
    assert not resolved["initial_stiffness"]  # below one count: the NNLS sum(k) is a lower bound, and says so
    for name, q in doc["quantities"].items():
        value, unit = shown[f"{name.replace('_', ' ')} (NNLS, model-free)" + ("" if resolved[name] else
                                                                            ", NOT resolved")]
        assert value == f"{q['value']:.5g} +- {q['std_uncertainty']:.2g}" and unit == q["unit"]
    k0 = doc["edge_pinned"]["parametric_ramp"]["quantities"]["initial_stiffness"]
    value, unit = shown["initial stiffness sum(k) (edge points, p free)"]
    assert float(value.split(" +- ")[0]) == pytest.approx(k0["value"], rel=1e-4) and unit == "N*m/rad"
    for row in doc["reversals"]:
        x, force = (float(s) for s in shown[f"reversal {row['n']}: x, extreme force"][0].split(", "))
        assert x == pytest.approx(row["x"], rel=1e-4) and force == pytest.approx(row["force_extreme"], rel=1e-4)
    assert result.warnings == doc["resolution"]["lines"]
    assert [f.title for f in result.figures] == ["force against displacement", "virgin curve"]
    assert all("(rad)" in f.xlabel and "(N*m)" in f.ylabel for f in result.figures)


def test_a_torque_driven_run_is_refused_in_one_line(tmp_path):
    path = tmp_path / "id.h5"
    with rf.RunWriter(path, sample_rate=1000.0) as w:
        t = np.arange(300) / 1000.0
        w.append({"sample_index": np.arange(300), "t": t, "current_cmd": np.sin(t), "current": np.sin(t),
                  "torque": 0.05 * np.sin(t), "position": np.cos(t), "counts": np.arange(300)})
    with pytest.raises(AnalysisError) as err:  # the analysis's own refusal, as hilbench presliding gives it
        run_analysis("presliding", path)
    assert "torque-driven" in str(err.value) and "displacement-driven" in str(err.value)
    assert "\n" not in str(err.value)
