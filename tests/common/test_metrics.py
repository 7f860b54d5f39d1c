"""The error figures against closed forms (docs/metrics.md)."""

import math

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.common.metrics import (
    FAIR_TORQUE_PCT,
    GOOD_TORQUE_PCT,
    grade,
    label,
    nrmse,
    percent,
    relative_error,
)


def test_nrmse_of_an_offset_sine_is_the_offset_over_the_sine_rms():
    t = np.arange(10_000) / 10_000  # 10 whole periods: std(sin) = 1/sqrt(2) exactly on the grid
    y = np.sin(2 * np.pi * 10 * t)
    assert nrmse(y, y + 0.01) == pytest.approx(0.01 * math.sqrt(2), rel=1e-12)
    assert relative_error(y, np.full_like(y, 0.01)) == pytest.approx(0.01 * math.sqrt(2), rel=1e-12)


def test_a_constant_reference_is_refused_in_one_line_where_analyses_catch_their_own():
    with pytest.raises(AnalysisError, match="the reference signal is constant"):
        nrmse(np.ones(5), np.zeros(5))
    assert relative_error(np.zeros(3), np.ones(3)) is None


def test_percent_label_and_bands():
    assert percent(0.0215) == pytest.approx(2.15) and math.isnan(percent(None))
    assert label("validation") == "validation torque NRMSE"
    assert [grade(GOOD_TORQUE_PCT), grade(FAIR_TORQUE_PCT), grade(FAIR_TORQUE_PCT + 0.1)] == ["good", "fair", "poor"]
