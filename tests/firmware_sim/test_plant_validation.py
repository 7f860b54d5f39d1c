"""Bad parameters raise one clear error before any C code runs."""

import math
import re

import numpy as np
import pytest

from hilbench.firmware_sim.engine.friction_models import dc_motor, paper_system
from hilbench.firmware_sim.engine.plant import (
    MAX_ELEMENTS,
    RK4_STABLE_RADIUS,
    Plant,
    PlantParameterError,
    PlantParams,
    simulate,
    stop_operator,
)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"ms_stiffness": (1.0, -2.0), "ms_slip": (0.1, 0.1)}, r"ms_stiffness\[1\]"),
        ({"ms_stiffness": (1.0, 2.0), "ms_slip": (0.1, 0.0)}, "slip force must be > 0"),
        ({"ms_stiffness": (1.0,), "ms_slip": (-0.1,)}, "slip force must be > 0"),
        ({"ms_stiffness": (1.0, 2.0), "ms_slip": (0.1,)}, "equal length"),
        ({"ms_stiffness": (float("nan"),), "ms_slip": (0.1,)}, "NaN"),
        ({"inertia": 0.0}, "inertia"),
        ({"inertia": float("nan")}, "inertia"),
        ({"viscous": -1.0}, "viscous"),
        ({"spring": -1.0}, "spring"),
        ({"coulomb": float("inf")}, "coulomb"),
        ({"coulomb": 0.1, "static": 0.05, "stribeck_velocity": 1.0}, "below Coulomb"),
        ({"coulomb": 0.1, "static": 0.2}, "stribeck_velocity"),
        ({"delay_samples": -1}, "delay_samples"),
        ({"delay_samples": 10**6}, "delay_samples"),
        ({"counts_per_rev": 2.5}, "counts_per_rev"),
        ({"torque_constant": 0.0}, "torque_constant"),
        ({"torque_constant_error": -1.0}, "torque_constant_error"),
        ({"current_limit": 0.0}, "current_limit"),
        ({"seed": -1}, "seed"),
        ({"restoring_table": ((0.0, 1.0, 0.5), (0.0, 1.0, 2.0))}, "restoring_table"),
        ({"damping_table": ((0.0, 1.0), (0.3, 1.0))}, "damping_table"),
    ],
)
def test_bad_parameter_is_refused_with_a_clear_message(changes, message):
    params = PlantParams(inertia=1.0).replace(**changes)
    with pytest.raises(PlantParameterError, match=message):
        Plant(params, 1e-3)


def test_too_many_elements():
    n = MAX_ELEMENTS + 1
    params = PlantParams(inertia=1.0, ms_stiffness=(1.0,) * n, ms_slip=(0.1,) * n)
    with pytest.raises(PlantParameterError, match="above the limit"):
        Plant(params, 1e-3)


def test_256_elements_are_allowed():
    out = simulate(dc_motor(256), np.full(100, 5.0), 1e-4)
    assert np.all(np.isfinite(out.theta))


def test_nan_input_is_refused():
    with pytest.raises(PlantParameterError, match="NaN or inf.*sample 3"):
        simulate(paper_system(), np.array([0, 1, 2, np.nan, 4.0]), 1e-3)
    with pytest.raises(PlantParameterError, match="NaN"):
        stop_operator(np.array([0.0, np.nan]), np.array([0.1]))


def test_unstable_step_is_refused_and_the_message_says_what_to_do():
    stiff = PlantParams(inertia=1e-4, ms_stiffness=(1e6,), ms_slip=(1.0,))
    with pytest.raises(PlantParameterError, match=r"unstable step.*substeps >= \d+") as info:
        Plant(stiff, 1e-3)
    need = int(re.search(r"substeps >= (\d+)", str(info.value)).group(1))
    assert need >= math.sqrt(1e6 / 1e-4) * 1e-3 / RK4_STABLE_RADIUS
    Plant(stiff, 1e-3, substeps=need)  # the advised value is accepted
    with pytest.raises(PlantParameterError):
        Plant(stiff, 1e-3, substeps=need - 1)


def test_rk4_region_contains_the_half_disc_used_by_the_check():
    # |R(z)| <= 1 for R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24 on the closed left half-disc |z| <= 2.5
    r = np.linspace(0, RK4_STABLE_RADIUS, 400)
    a = np.linspace(np.pi / 2, 3 * np.pi / 2, 800)
    z = (r[:, None] * np.exp(1j * a[None, :])).ravel()
    stab = np.abs(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24)
    assert stab.max() <= 1 + 1e-12
    # and the stiff plant really does blow up just outside the limit, so the check is needed
    lam = 100.0
    params = PlantParams(inertia=1.0, spring=lam**2)
    dt = 2.9 / lam  # beyond the imaginary-axis limit 2*sqrt(2) of RK4
    with pytest.raises(PlantParameterError):
        Plant(params, dt)


def test_wrong_mode_and_dt():
    with pytest.raises(PlantParameterError, match="mode"):
        Plant(paper_system(), 1e-3, mode="torque")
    with pytest.raises(PlantParameterError, match="dt"):
        Plant(paper_system(), 0.0)
    with pytest.raises(PlantParameterError, match="substeps"):
        Plant(paper_system(), 1e-3, substeps=0)


def test_params_dict_round_trip_and_unknown_key():
    p = dc_motor().replace(static=0.9, stribeck_velocity=0.3)
    assert PlantParams.from_dict(p.to_dict()).to_dict() == p.to_dict()
    with pytest.raises(PlantParameterError, match="unknown plant parameter"):
        PlantParams.from_dict({"inertia": 1.0, "mass": 2.0})


def test_set_deflections_continues_a_run_exactly():
    # Oracle: one plant run over n1 + n2 samples. A second plant started at the first one's (theta, omega,
    # deflections) after n1 samples must reproduce the remaining n2 samples (same arithmetic: 1e-12).
    p = dc_motor()
    dt, n1, n2 = 2.5e-4, 3000, 3000
    rng = np.random.default_rng(2)
    u = np.repeat(rng.uniform(-6, 6, (n1 + n2) // 100), 100)
    a = Plant(p, dt, 2)
    a.run(u[:n1])
    b = Plant(p, dt, 2, theta0=a.theta, omega0=a.omega)
    b.set_deflections(a.deflections)
    np.testing.assert_allclose(b.deflections, a.deflections, rtol=0, atol=1e-15)
    np.testing.assert_allclose(b.run(u[n1:]).theta, a.run(u[n1:]).theta, rtol=0, atol=1e-12)
    with pytest.raises(PlantParameterError, match="shape"):
        b.set_deflections(np.zeros(3))
    big = np.full(p.n_elements, 1.0)
    b.set_deflections(big)  # clipped to the slip displacements
    np.testing.assert_allclose(b.deflections, p.ms_delta, rtol=1e-15)


def test_stiffest_eigenvalue_is_the_quadratics_root_and_refuses_a_vanishing_inertia():
    """max |s| of J s^2 + B s + K = 0: the closed form for an overdamped and an underdamped case (1e-12), the same
    figure as numpy.roots([J, B, K]) bit for bit, and a model file's 1e-308 kg*m^2 is one PlantParameterError, not a
    LinAlgError from the eigenvalue solver (the compensate fuzz test found it)."""
    import math

    import numpy as np

    from hilbench.firmware_sim.engine.plant import PlantParameterError, PlantParams, stiffest_eigenvalue

    over = PlantParams(inertia=0.01, viscous=3.0, spring=20.0)  # roots (-3 +- sqrt(9 - 0.8)) / 0.02
    assert stiffest_eigenvalue(over) == pytest.approx((3.0 + math.sqrt(9.0 - 0.8)) / 0.02, rel=1e-12)
    under = PlantParams(inertia=0.01, viscous=0.02, spring=400.0)  # |s| = sqrt(K / J) for complex roots
    assert stiffest_eigenvalue(under) == pytest.approx(math.sqrt(400.0 / 0.01), rel=1e-12)
    for p in (over, under):
        assert stiffest_eigenvalue(p) == float(np.max(np.abs(np.roots([p.inertia, p.viscous, p.spring]))))
    with pytest.raises(PlantParameterError, match="inertia 1.11254e-308 is too small"):
        stiffest_eigenvalue(PlantParams(inertia=1.1125369292536007e-308, viscous=0.004, ms_stiffness=(399.5,),
                                        ms_slip=(1e-3,)))
