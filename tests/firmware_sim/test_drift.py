"""Drift laws of the simulated device (firmware_sim.engine.drift) against their closed forms."""

import math

import numpy as np
import pytest

from hilbench.firmware_sim.engine.drift import Drift, DriftState, drifted_params, heat, rest, simulate_drifting
from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import PlantParameterError, PlantParams, simulate


def test_constant_current_heats_as_the_first_order_step_response():
    # T(t) = T_amb + R_th*R_w*i^2*(1 - exp(-t/tau)): the zero-order-hold recursion is exact for a held current
    d = Drift(winding_resistance=1.5, thermal_resistance=2.0, thermal_time_constant=30.0)
    state = DriftState(temperature=20.0, ambient=20.0)
    dt, i = 1e-3, 3.0
    temps = heat(d, state, np.full(60_000, i), dt)
    t = np.arange(60_000) * dt
    expected = 20.0 + 2.0 * 1.5 * i**2 * (1 - np.exp(-t / 30.0))
    np.testing.assert_allclose(temps, expected, rtol=0, atol=1e-9)
    assert state.temperature == pytest.approx(20.0 + 27.0 * (1 - math.exp(-2.0)), abs=1e-9)


def test_cooling_at_rest_is_exponential():
    d = Drift(thermal_time_constant=100.0)
    state = DriftState(temperature=60.0, ambient=20.0)
    rest(d, state, 100.0)
    assert state.temperature == pytest.approx(20.0 + 40.0 / math.e, rel=1e-12)


def test_level_and_viscous_laws_scale_the_plant():
    d = Drift(level_temperature_coefficient=-0.004, viscous_temperature_coefficient=0.02, wear_rate=1e-3,
              wear_step=0.1, wear_step_distance=50.0)
    base = dc_motor()
    state = DriftState(temperature=33.0, ambient=23.0, distance=60.0)
    p = drifted_params(base, d, state)
    level = (1 - 0.004 * 10.0) * (1 + 1e-3 * 60.0 + 0.1)
    assert p.breakaway == pytest.approx(level * base.breakaway, rel=1e-12)
    assert p.viscous == pytest.approx(base.viscous * math.exp(-0.2), rel=1e-12)
    np.testing.assert_allclose(p.ms_delta, base.ms_delta, rtol=1e-12)  # slip displacements kept
    before_step = drifted_params(base, d, DriftState(33.0, 23.0, distance=49.9))
    assert before_step.breakaway == pytest.approx((1 - 0.04) * (1 + 0.0499) * base.breakaway, rel=1e-12)


def test_wear_step_changes_the_steady_velocity_as_coulomb_viscous_balance_says():
    # constant torque on a Coulomb + viscous mass: omega_ss = (tau - L*Fc)/b; after the step L = 1 + step
    fc, b, tau = 0.2, 0.01, 0.5
    p = PlantParams(inertia=1e-3, coulomb=fc, viscous=b)
    d = Drift(wear_step=0.5, wear_step_distance=30.0, thermal_resistance=1e-9)  # no heating
    state = DriftState(23.0, 23.0)
    fs = 1000.0
    out, temps = simulate_drifting(p, np.full(4000, tau), 1 / fs, d, state, block=0.01)
    assert out.omega[900] == pytest.approx((tau - fc) / b, rel=1e-3)  # before the step: 30 rad/s, 1 s
    assert state.distance > 30.0
    assert out.omega[-1] == pytest.approx((tau - 1.5 * fc) / b, rel=1e-3)
    np.testing.assert_allclose(temps, 23.0, atol=1e-6)


def test_no_drift_is_the_plain_plant_bit_for_bit():
    p = dc_motor().replace(noise_current=0.01, seed=4)
    u = 6.0 * np.sin(np.linspace(0, 20, 3000))
    plain = simulate(p, u, 1e-3)
    drifted, _ = simulate_drifting(p, u, 1e-3, Drift(), DriftState(23.0, 23.0))
    np.testing.assert_array_equal(plain.position_meas, drifted.position_meas)
    np.testing.assert_array_equal(plain.current_meas, drifted.current_meas)


def test_bad_drift_constants_are_refused():
    with pytest.raises(PlantParameterError, match="thermal_time_constant"):
        Drift(thermal_time_constant=0.0)
    with pytest.raises(PlantParameterError, match="wear_rate"):
        Drift(wear_rate=-1.0)
