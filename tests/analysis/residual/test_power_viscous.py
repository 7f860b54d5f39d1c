"""The sublinear viscous candidate ``power_viscous`` (issue 29: EMPS, a ball-screw axis, showed a residual concave in
speed against Coulomb + linear viscous friction). Oracle: a rigid body under a prescribed smooth motion, whose
driving torque is the closed form tau = J*a + F_c*sign(v) + b*v + c*sign(v)*|v|^n, so the law and its
parameters are known exactly; the loop starts from inertia + Coulomb + viscous (EMPS's start without the offset)."""

from __future__ import annotations

import numpy as np
import pytest

from hilbench.analysis.residual import LoopOptions, prepare_run, residual_loop
from hilbench.analysis.residual.candidates import POWER_EXPONENTS, REGISTRY

J, FC, B = 0.0022, 0.3, 0.004  # kg*m^2, N*m, N*m*s/rad
FS = 1000.0
NOISE = 0.004  # N*m rms, the truth generator's current-sensor noise
START = ("inertia", "coulomb", "viscous")


def _run(seed: int, c: float, n: float):
    """A multisine motion of about 5 rad/s peak (a few reversals per second) and its exact torque."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(10 * FS)) / FS
    f = rng.uniform(0.2, 2.0, 8)
    ph = rng.uniform(0, 2 * np.pi, 8)
    a = 1.2 / (1 + f)
    w = 2 * np.pi * f
    x = (a * np.sin(np.outer(t, w) + ph)).sum(1)
    v = (a * w * np.cos(np.outer(t, w) + ph)).sum(1)
    acc = -(a * w**2 * np.sin(np.outer(t, w) + ph)).sum(1)
    tau = J * acc + FC * np.sign(v) + B * v + c * np.sign(v) * np.abs(v) ** n + NOISE * rng.standard_normal(t.size)
    return prepare_run(x, tau, FS, name=f"power-{seed}", timing="instant")


def test_a_power_law_friction_is_found_with_its_exponent_and_coefficient():
    c, n = 0.1, 0.3  # N*m at 1 rad/s; the elastohydrodynamic exponent
    res = residual_loop(_run(1, c, n), _run(2, c, n), start=START, options=LoopOptions(sim_window=None))
    assert res.names_added == ["power_viscous"]
    p = res.effect("power_viscous")["parameters"]
    # measured: n = 0.29998, c = 0.1008, b = 0.00393 (tolerances for the noise and the filtered columns)
    assert p["exponent"] == pytest.approx(n, abs=0.02)
    assert p["power_coefficient"] == pytest.approx(c, rel=0.03)
    assert res.model_after["viscous"]["parameters"]["viscous"] == pytest.approx(B, abs=5e-4)
    assert res.error_after["validation"]["torque_rel_pct"] < 0.5 * res.error_before["validation"]["torque_rel_pct"]


def test_linear_viscous_friction_adds_no_power_law():
    res = residual_loop(_run(3, 0.0, 0.3), _run(4, 0.0, 0.3), start=START, options=LoopOptions(sim_window=None))
    assert "power_viscous" not in res.names_added


def test_the_term_cannot_mimic_a_stribeck_curve():
    """The coefficient is bounded at zero (velocity strengthening only), and every exponent is sublinear."""
    term = REGISTRY["power_viscous"]
    assert np.all(term.lower({"exponent": 0.3}, 1) == 0.0)
    assert all(0.0 < e < 1.0 for e in POWER_EXPONENTS)


def test_a_model_with_the_term_reports_no_simulation_error_rather_than_a_wrong_one():
    """The simulated plant has no power law: the simulated figures of the model after are None, with the reason."""
    res = residual_loop(_run(1, 0.1, 0.3), _run(2, 0.1, 0.3), start=START, options=LoopOptions(sim_window=1.0))
    assert res.names_added == ["power_viscous"]
    assert res.error_before["validation"]["position_nrmse"] is not None
    after = res.error_after["validation"]
    assert after["position_nrmse"] is None and "power_viscous" in after["simulation_note"]
