"""One compensated run against its baseline: reduction factors, the summary line and the figure, on errors whose
rms, maximum and glitch are known in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hilbench.analysis.compensation.metrics import tracking_metrics
from hilbench.analysis.compensation.references import slow_sine
from hilbench.analysis.compensation.report import CaseResult, reduction
from hilbench.analysis.compensation.run_report import run_figure, summary_line
from tests.figure_checks import figure_problems


def _case(ref, name: str, level: float) -> CaseResult:
    """A run whose error is ``level`` rad everywhere the reference moves, 0 at rest: rms level*sqrt(moving
    fraction), max level, every reversal glitch level."""
    error = np.where(ref.velocity != 0, level, 0.0)
    m = tracking_metrics(ref, ref.position - error, np.zeros(ref.n), window=0.02)
    return CaseResult(ref, name, m, error, 0, f"{name}.h5")


def test_reduction_summary_and_figure_of_a_run_against_its_baseline():
    ref = slow_sine(1000.0, amplitudes=(1e-3, 1e-2), frequency=1.0, cycles=1, rest=0.1)
    moving = float(np.mean(ref.velocity != 0))
    run, base = _case(ref, "maxwell_slip", 2e-5), _case(ref, "none", 1e-4)
    assert run.metrics.rms_error == pytest.approx(2e-5 * math.sqrt(moving), rel=1e-12)
    x = reduction(run, base)
    assert x == pytest.approx({"rms_error_x": 5.0, "max_error_x": 5.0, "glitch_mean_x": 5.0}, rel=1e-12)
    assert math.isnan(reduction(_case(ref, "exact", 0.0), base)["rms_error_x"])  # no error: no factor
    line = summary_line(run, base)
    assert line.startswith("sine / maxwell_slip against none: rms error ")
    assert line.count("5x smaller") == 3 and "max error 0.02 vs 0.1 mrad" in line and "over 3 reversals" in line
    assert "5x larger" in summary_line(base, run)  # a feed-forward that makes it worse says so
    assert summary_line(run, None).endswith("(no baseline)")
    fig = run_figure(run, base, "run.h5: sine reference, feed-forward maxwell_slip against none (baseline)")
    fig.canvas.draw()
    assert figure_problems(fig) == []
    top, zoom = fig.axes[:2]
    assert top.get_ylabel() == "tracking error q_ref - q (mrad)" and zoom.get_ylabel().endswith("(mrad)")
    assert len([ln for ln in top.lines if ln.get_linestyle() == ":"]) == 3  # one mark per reversal
    peak = max(np.max(np.abs(ln.get_ydata())) for ln in top.lines if ln.get_linestyle() == "-")
    assert peak == pytest.approx(0.1, rel=1e-12)  # 1e-4 rad drawn as 0.1 mrad
