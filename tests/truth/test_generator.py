"""The independent truth generator against closed forms (it must be right before it can judge the loop)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize

from tests.truth.generator import (
    TWO_PI,
    Truth,
    displacement_driven,
    displacement_ode,
    elements,
    simulate_torque_driven,
    stop_operator_forces,
    stribeck_curve,
    virgin_curve,
)


def _step(level: float):
    return lambda t: np.full_like(np.asarray(t, float), level)


@pytest.mark.parametrize("family", ["maxwell", "gms", "dahl"])
def test_coulomb_viscous_steady_state(family):
    """Constant torque tau0 > Fc: the terminal speed is (tau0 - Fc)/b (time constant J/b = 0.055 s)."""
    tr = Truth(family=family, coulomb=0.6, viscous=0.04, torque_noise=0.0)
    rec = simulate_torque_driven(tr, 1, duration=1.0, torque=_step(1.0))
    v = np.diff(rec.position_true[-200:]) * rec.fs
    assert np.mean(v) == pytest.approx((1.0 - 0.6) / 0.04, rel=2e-3)


def test_lugre_steady_state_with_its_own_stribeck_curve():
    """LuGre at constant speed: F = g(v) + sigma2*v, here with a Stribeck exponent 1 (tau0 = 1 N*m)."""
    tr = Truth(family="lugre", coulomb=0.6, viscous=0.1, stribeck_excess=0.3, stribeck_velocity=2.0,
               stribeck_exponent=1.0, torque_noise=0.0)
    v_true = optimize.brentq(lambda v: stribeck_curve(tr, v) + tr.viscous * v - 1.0, 0.5, 20.0)
    rec = simulate_torque_driven(tr, 1, duration=1.0, torque=_step(1.0))
    v = np.diff(rec.position_true[-200:]) * rec.fs
    assert np.mean(v) == pytest.approx(v_true, rel=2e-3)
    assert stribeck_curve(tr, v_true) - 0.6 > 0.05  # the Stribeck part matters at this speed


def test_elements_lie_on_the_parabolic_virgin_curve():
    k, w = elements(1.0, 1e-3, 40)
    d = w / k
    x = np.linspace(0, 1.2e-3, 500)
    parabola = np.where(x < 1e-3, 1 - (1 - x / 1e-3) ** 2, 1.0)
    # piecewise-linear interpolation of the parabola between 40 breakpoints: error <= (p/40)^2... bound
    assert np.max(np.abs(virgin_curve(k, w, x) - parabola)) < 2e-3
    assert np.allclose(virgin_curve(k, w, d), 1 - (1 - d / 1e-3) ** 2, atol=1e-12)


def test_stop_operators_follow_the_virgin_curve_then_masing():
    """Monotonic loading from rest follows the virgin curve; the reversal branch is the virgin curve
    doubled in both axes (Masing's rule, exact for Maxwell-slip)."""
    k, w = elements(40.0, 0.1e-3, 40)
    up = np.linspace(0, 0.15e-3, 301)
    down = np.linspace(0.15e-3, -0.15e-3, 601)
    f = stop_operator_forces(k, w, np.concatenate([up, down[1:]]))
    assert np.allclose(f[:301], virgin_curve(k, w, up), rtol=0, atol=1e-9)
    f_top = f[300]
    branch = f_top - 2 * virgin_curve(k, w, (0.15e-3 - down[1:]) / 2)
    assert np.allclose(f[301:], branch, rtol=0, atol=1e-9)


def test_dahl_and_lugre_displacement_closed_forms():
    """Monotonic displacement at constant speed from rest: Dahl F = Fc(1 - exp(-sigma0 x/Fc)); LuGre
    z = (g/sigma0)(1 - exp(-sigma0 x/g)), F = sigma0 z + sigma1 v (1 - sigma0 z/g) + b v."""
    fs, v = 1000.0, 2e-3
    x = np.arange(1000) / fs * v
    for family in ("dahl", "lugre"):
        tr = Truth(family=family, coulomb=30.0, viscous=100.0, presliding=0.1e-3, inertia=1.0)
        f = displacement_ode(tr, x, fs)
        s0 = 2 * 30.0 / 0.1e-3
        g = stribeck_curve(tr, v)
        if family == "dahl":
            ref = g * (1 - np.exp(-s0 * x / g)) + tr.viscous * v
        else:
            s1 = 2 * np.sqrt(s0 * tr.inertia) * 0.3
            z = g / s0 * (1 - np.exp(-s0 * x / g))
            ref = s0 * z + s1 * v * (1 - s0 * z / g) + tr.viscous * v
        assert np.max(np.abs(f[1:] - ref[1:])) < 1e-4 * np.max(np.abs(ref)), family


def test_quantisation_and_noise_at_the_stated_levels():
    tr = Truth(family="dahl")
    rec = simulate_torque_driven(tr, 4, duration=2.0)
    step = TWO_PI / tr.counts_per_rev
    assert np.allclose(rec.position / step, np.round(rec.position / step), atol=1e-6)
    assert np.max(np.abs(rec.position - rec.position_true)) <= step / 2 + 1e-12
    noise = rec.torque - rec.torque_true
    expected = np.sqrt(tr.torque_noise**2 + tr.torque_lsb**2 / 12)
    assert np.std(noise) == pytest.approx(expected, rel=0.05)


def test_displacement_record_starts_on_the_virgin_curve():
    rec, k, w = displacement_driven(3, duration=20.0, reversals=20)
    assert rec.kind == "displacement-driven"
    first = slice(0, rec.t.size // 20)
    ref = virgin_curve(k, w, rec.position_true[first])
    assert np.max(np.abs(rec.torque_true[first] - ref)) < 1e-6 * 40
    assert np.ptp(rec.position_true) == pytest.approx(0.24e-3, rel=0.1)
