"""The calibrated limits (analysis.drift.calibration) against closed forms and an independent oracle."""

import numpy as np
import pytest
from scipy import stats

from hilbench.analysis.drift.calibration import calibrate, split_gain, standardise


def _intercept(n: int) -> np.ndarray:
    return np.ones((n, 1))


def test_scores_of_an_intercept_fit_are_the_textbook_residuals():
    rng = np.random.default_rng(0)
    n, nb = 12, 7
    y = rng.normal(3.0, 0.2, n)
    base = np.arange(n) < nb
    z, fitted, s = standardise(y, _intercept(n), base)
    m, sd = y[:nb].mean(), y[:nb].std(ddof=1)
    np.testing.assert_allclose(fitted[0], m, rtol=1e-12)
    assert s[0] == pytest.approx(sd, rel=1e-12)
    np.testing.assert_allclose(z[0, :nb], (y[:nb] - m) / (sd * np.sqrt(1 - 1 / nb)), rtol=1e-10)
    np.testing.assert_allclose(z[0, nb:], (y[nb:] - m) / (sd * np.sqrt(1 + 1 / nb)), rtol=1e-10)


def test_a_later_run_s_score_follows_student_t_with_the_baseline_s_degrees_of_freedom():
    # the prediction error of a new observation over its estimated standard error is t with n_b - p dof (with a
    # covariate: p = 2), whatever the slope's range; a Kolmogorov-Smirnov test against scipy's t at 1 %
    rng = np.random.default_rng(1)
    n, nb = 9, 8
    x = np.linspace(-1, 1, nb).tolist() + [2.5]  # the later run lies beyond the baseline's covariate range
    design = np.column_stack([np.ones(n), x])
    base = np.arange(n) < nb
    z, _, _ = standardise(rng.standard_normal((20000, n)), design, base)
    assert stats.kstest(z[:, -1], stats.t(nb - 2).cdf).pvalue > 0.01
    assert stats.kstest(z[:, -1], stats.norm.cdf).pvalue < 1e-6  # not the normal law a known sigma would give


def test_the_ewma_limit_of_one_later_run_is_the_t_quantile():
    # one run after a baseline of 30: the EWMA's first value over its sd is |z|, so L is the two-sided t quantile
    n, nb, alpha = 31, 30, 0.05
    lim = calibrate(_intercept(n), np.arange(n) < nb, alpha=alpha, alpha_outlier=0.01, lam=0.2, k=0.5, clip=3.0,
                    min_size=5, draws=40000)
    assert lim.ewma == pytest.approx(stats.t(nb - 1).ppf(1 - alpha / 2), rel=0.02)


def test_split_gain_is_the_first_gain_of_ruptures_binary_segmentation():
    import ruptures

    rng = np.random.default_rng(2)
    for n, min_size in ((20, 3), (57, 5)):
        z = rng.standard_normal(n)
        _, gain = ruptures.Binseg(model="l2", min_size=min_size, jump=1).fit(z.reshape(-1, 1)).single_bkp(0, n)
        assert split_gain(z[None, :], min_size)[0] == pytest.approx(gain, rel=1e-9)


def test_limits_are_reproducible_and_refuse_a_bad_rate():
    args = dict(alpha=0.01, alpha_outlier=0.01, lam=0.2, k=0.5, clip=3.0, min_size=5, draws=500)
    base = np.arange(40) < 20
    assert calibrate(_intercept(40), base, **args) == calibrate(_intercept(40), base, **args)
    from hilbench.analysis.errors import AnalysisError

    with pytest.raises(AnalysisError, match="false-alarm"):
        calibrate(_intercept(40), base, **{**args, "alpha": 0.0})
