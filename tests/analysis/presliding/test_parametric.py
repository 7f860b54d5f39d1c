"""The parametric rolling-friction virgin curve h*(1-(d/(d+x))^2) fitted beside the NNLS: against its closed form
(quantised, noisy) and against the DC-motor preset's exact Maxwell-slip discretisation (tests/truth stop operators)."""

from __future__ import annotations

import numpy as np
import pytest

from hilbench.analysis.presliding.parametric import fit_rolling
from hilbench.analysis.presliding.reversals import find_reversals
from hilbench.firmware_sim.friction_models import DC_MOTOR_D
from tests.analysis.presliding.records import dc_elements, maxwell_force, smooth_path

FS = 1000.0  # Hz
H = 0.76  # N*m
NOISE = 4e-4  # N*m rms


def _closed_form(x: np.ndarray, r0: int) -> np.ndarray:
    """Virgin ramp h(1-(d/(d+x))^2) to the first reversal, then Masing's branch F_r + 2*phi((x - x_r)/2),
    written out independently of the module under test."""
    def phi(s):
        return H * (1 - (DC_MOTOR_D / (DC_MOTOR_D + np.abs(s))) ** 2) * np.sign(s)
    f = phi(x)
    f[r0:] = f[r0] + 2 * phi((x[r0:] - x[r0]) / 2)
    return f


def test_closed_form_virgin_curve_quantised_and_noisy_recovers_h_and_d():
    x = smooth_path(DC_MOTOR_D, 400, sequence=(4.0, -3.0))
    r0 = int(np.argmax(x))
    f = _closed_form(x, r0) + NOISE * np.random.default_rng(5).standard_normal(x.size)
    step = DC_MOTOR_D / 20  # position quantum: a twentieth of d
    xq = np.round(x / step) * step
    fit = fit_rolling(xq, f, FS, find_reversals(xq, 1.5 * step))
    assert fit.h == pytest.approx(H, rel=0.01)
    assert fit.d == pytest.approx(DC_MOTOR_D, rel=0.03)
    k0 = fit.quantities(0.9)["initial_stiffness"]
    assert k0 == pytest.approx(2 * H / DC_MOTOR_D, rel=0.03)
    assert 0 < fit.uncertainties(0.9)["initial_stiffness"] < 0.02 * k0


def test_on_the_exact_dc_discretisation_sum_k_matches_the_discretisation():
    """The truth is the discretisation's own sum(k) = 3019 N*m/rad (0.993 of 2h/d), not 2h/d."""
    k, w = dc_elements()
    x = smooth_path(DC_MOTOR_D, 400, sequence=(4.0, -3.0, 2.0, -1.0))
    f = maxwell_force(x, k, w) + NOISE * np.random.default_rng(6).standard_normal(x.size)
    fit = fit_rolling(x, f, FS, find_reversals(x, 1e-9))
    assert fit.quantities(0.9)["initial_stiffness"] == pytest.approx(k.sum(), rel=0.02)
    assert fit.h == pytest.approx(w.sum(), rel=0.01)


def test_points_without_velocity_fit_without_a_viscous_term():
    """viscous=False (the dwells of edges.py, at rest): the closed-form ramp at 12 exact points, 2 % offset,
    recovers h and d to 1e-6 and reports no viscous term."""
    from hilbench.analysis.presliding.parametric import rolling_virgin

    h, d = 0.76, 5e-4
    x = np.concatenate([[0.0], (np.arange(12) + 0.5) * 1e-4])
    fit = fit_rolling(x, 0.02 + rolling_virgin(x, h, d), 1.0, np.array([x.size - 1]), viscous=False)
    assert fit.h == pytest.approx(h, rel=1e-6) and fit.d == pytest.approx(d, rel=1e-6)
    assert fit.viscous == 0.0 and fit.offset == pytest.approx(0.02, abs=1e-9)
