"""Skeleton fits: the paper's forms and the monotone alternative, against closed forms (science.md §3)."""

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.skeleton.skeleton_fit import (
    fit_monotone,
    fit_paper_damping,
    fit_paper_restoring,
    fit_skeleton_monotone,
    paper_damping_force,
    paper_restoring_force,
)

H, D = 1.64, 0.656
RNG = np.random.default_rng(7)


def test_paper_damping_form_recovers_its_parameters():
    # Data from the form itself (a = 1.5 N, b = 3 s/m, dead-zone v0 = 0.05 m/s) with 0.5 % noise: the fit
    # returns each coefficient within 3 %.
    v = np.geomspace(0.005, 3.0, 400)
    y = paper_damping_force(v, 1.5, 3.0, 0.05) * (1 + 0.005 * RNG.standard_normal(v.size))
    fit = fit_paper_damping(v, y)
    assert fit.params["a"] == pytest.approx(1.5, rel=3e-2)
    assert fit.params["b"] == pytest.approx(3.0, rel=3e-2)
    assert fit.params["v0"] == pytest.approx(0.05, rel=3e-2)
    assert np.all(fit(v[v < 0.05]) == 0.0)
    np.testing.assert_allclose(fit(-v), -fit(v))            # odd


def test_paper_restoring_form_fits_the_rolling_friction_closed_form():
    # F_k(A) = k_eq(A)*A = 2h*sqrt(d)*A/(d+A)^(3/2) rises to a peak at A = 2d and decays; the paper's
    # exponential + 1/Gamma form must follow it within 3 % of its peak over 0.01..5 m.
    a = np.geomspace(0.01, 5.0, 300)
    f = 2 * H * np.sqrt(D) * a / (D + a) ** 1.5
    fit = fit_paper_restoring(a, f)
    assert np.max(np.abs(fit(a) - f)) < 0.03 * f.max()
    assert fit.rms < 0.02 * f.max()
    np.testing.assert_allclose(paper_restoring_force(-a, **fit.params), -fit(a))


def test_monotone_fit_of_equivalent_stiffness():
    # Noisy (2 %) samples of k_eq(A) = 2h*sqrt(d)/(d+A)^(3/2): the form-free fit is non-increasing on a dense
    # grid and within 2 % of the closed form inside the sampled range.
    a = np.geomspace(0.005, 4.0, 5000)
    k = 2 * H * np.sqrt(D) / (D + a) ** 1.5
    fit = fit_monotone(a, k * (1 + 0.02 * RNG.standard_normal(a.size)), increasing=False, n_knots=30)
    grid = np.geomspace(0.006, 3.5, 2000)
    out = fit(grid)
    assert np.all(np.diff(out) <= 1e-12)
    ref = 2 * H * np.sqrt(D) / (D + grid) ** 1.5
    assert np.max(np.abs(out / ref - 1)) < 0.02


def test_monotone_skeleton_tables():
    # Damping force 4hA^2/(pi*(d+A)^2) against V = A*omega (omega fixed, 7 rad/s) is increasing; the tables
    # start at 0 and the restoring force equals k_eq(A)*A within 2 %.
    a = np.geomspace(0.005, 4.0, 3000)
    k = 2 * H * np.sqrt(D) / (D + a) ** 1.5
    v = 7.0 * a
    fd = 4 * H * a**2 / (np.pi * (D + a) ** 2)
    model = fit_skeleton_monotone(a, k, v, fd, n_knots=40)
    (xg, fk), (vg, fdg) = model.tables(3.0, 20.0, n=100)
    assert xg[0] == 0 and fk[0] == 0 and vg[0] == 0 and fdg[0] == 0
    assert np.all(np.diff(fdg) >= -1e-12)
    inner = (xg > 0.01) & (xg < 3.0)
    ref = 2 * H * np.sqrt(D) * xg[inner] / (D + xg[inner]) ** 1.5
    assert np.max(np.abs(fk[inner] / ref - 1)) < 0.02


def test_fit_errors():
    with pytest.raises(AnalysisError, match="at least 8"):
        fit_monotone([1.0, 2.0], [1.0, 2.0], increasing=True)
    with pytest.raises(AnalysisError, match="length"):
        fit_paper_damping(np.ones(10), np.ones(9))
    with pytest.raises(AnalysisError, match="nowhere positive"):
        fit_paper_damping(np.linspace(0.1, 1, 20), -np.ones(20))
