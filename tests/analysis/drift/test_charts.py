"""EWMA, CUSUM and change points (analysis.drift.charts) against closed forms."""

import numpy as np
import pytest

from hilbench.analysis.drift.charts import change_points, cusum, ewma, signals
from hilbench.analysis.errors import AnalysisError


def test_ewma_of_a_step_and_its_limits_are_the_closed_forms():
    lam, d = 0.2, 1.5
    w, lim = ewma(np.full(40, d), lam, 3.0)
    i = np.arange(40)
    np.testing.assert_allclose(w, d * (1 - (1 - lam) ** (i + 1)), rtol=1e-13)
    np.testing.assert_allclose(lim, 3.0 * np.sqrt(lam / (2 - lam) * (1 - (1 - lam) ** (2 * (i + 1)))), rtol=1e-13)
    assert lim[0] == pytest.approx(3.0 * lam)  # first limit: L*lambda*sigma (one sample)
    assert lim[-1] == pytest.approx(3.0 * np.sqrt(lam / (2 - lam)), rel=1e-6)  # asymptote


def test_cusum_of_a_constant_shift_grows_linearly():
    hi, lo = cusum(np.full(10, 1.25), 0.5, 5.0)
    np.testing.assert_allclose(hi, 0.75 * np.arange(1, 11), rtol=1e-14)
    np.testing.assert_array_equal(lo, 0.0)
    hi, lo = cusum(np.array([-2.0, 0.0, 3.0]), 0.5, 5.0)
    np.testing.assert_allclose(lo, [1.5, 1.0, 0.0])
    np.testing.assert_allclose(hi, [0.0, 0.0, 2.5])


def test_signals_count_one_alarm_per_excursion():
    assert signals(np.array([False, True, True, False, True])) == [1, 4]
    assert signals(np.array([True, False])) == [0]
    assert signals(np.zeros(5, bool)) == []


def test_binary_segmentation_finds_a_mean_step_where_it_starts():
    rng = np.random.default_rng(3)
    z = rng.standard_normal(150)
    z[70:] += 3.0
    assert change_points(z, 3 * np.log(150)) == [70]
    assert change_points(rng.standard_normal(150), 3 * np.log(150)) == []
    assert change_points(z[:8], 1.0, min_size=5) == []  # too short for two segments


def test_bad_chart_constants_are_refused():
    with pytest.raises(AnalysisError, match="lambda"):
        ewma(np.zeros(3), 0.0, 3.0)
    with pytest.raises(AnalysisError, match="h > 0"):
        cusum(np.zeros(3), 0.5, 0.0)
