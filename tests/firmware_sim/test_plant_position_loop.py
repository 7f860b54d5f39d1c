"""The C plant's position loop (``Plant.run_position``, a drive's PID closed at every sample) against closed forms:
steady states on a linear spring, the torque command it reduces to, and its encoder PLL on a ramp."""

import math

import numpy as np
import pytest

from hilbench.firmware_sim.engine.plant import Plant, PlantParameterError, PlantParams

J, B, K, KT = 0.002, 0.05, 200.0, 0.2   # kg*m^2, N*m*s/rad, N*m/rad (a spring), N*m/A
DT = 1e-4


def _spring(counts_per_rev: int = 0) -> Plant:
    params = PlantParams(inertia=J, viscous=B, spring=K, torque_constant=KT, current_limit=20.0,
                         counts_per_rev=counts_per_rev)
    return Plant(params, DT, 4)


@pytest.mark.parametrize(("ki", "ilimit", "limit"), [(0.0, 0.0, math.inf), (2e4, 10.0, math.inf),
                                                      (2e4, 0.1, math.inf), (0.0, 0.0, 0.3)])
def test_steady_state_on_a_spring_is_the_closed_form(ki, ilimit, limit):
    # At rest: kp*(r - x) + I = K*x. PD: x = kp*r/(kp + K); PID with the integral unbounded: x = r; integral
    # clipped at ilimit: x = (kp*r + ilimit)/(kp + K); torque limit L below what is needed: x = L/K. Ideal encoder,
    # 2 s (the slowest mode ~ 0.3 s), tolerance 1e-6 of r.
    kp, kd, r = 50.0, 1.0, 0.01
    plant = _spring()
    out = plant.run_position(np.full(20_000, r), kp, kd, torque_limit=limit, ki=ki, ilimit=ilimit)
    if limit < kp * r:
        want = limit / K
    elif ki == 0.0:
        want = kp * r / (kp + K)
    elif ilimit >= K * r:
        want = r
    else:
        want = (kp * r + ilimit) / (kp + K)
    assert out.theta[-1] == pytest.approx(want, abs=1e-6 * r)
    assert out.current_cmd[-1] * KT == pytest.approx(K * want, abs=1e-6 * K * r)


def test_no_loop_is_the_torque_command_bit_for_bit():
    # NaN target, kp = kd = 0: torque = feed-forward, as the current command u = ff/kt (the moteus torque mode)
    u = np.sin(np.linspace(0, 20, 3000))
    run = _spring(1 << 16).run(u)
    b = _spring(1 << 16)  # sample by sample, the feed-forward changing between calls
    thetas = np.concatenate([b.run_position(np.full(1, np.nan), 0.0, 0.0, feedforward=x * KT).theta for x in u])
    np.testing.assert_array_equal(thetas, run.theta)


def test_the_pll_follows_a_ramp_without_lag():
    # A type-2 loop: on a constant velocity its estimate converges to the slope with no steady error, where a
    # backward difference of counts of 1/2^20 rev at 10 kHz dithers by 0.06 rad/s. The target is NaN, so only
    # the estimator and kd act: torque = kd*(velocity - v_est) on a free inertia with viscous B, steady state
    # omega = kd*velocity/(kd + B) when v_est is right on average. Tolerance 0.5 %.
    params = PlantParams(inertia=J, viscous=B, torque_constant=KT, current_limit=20.0, counts_per_rev=1 << 20)
    v = 2.0
    for pll in (200.0, 0.0):
        plant = Plant(params, DT, 1)
        out = plant.run_position(np.full(10_000, np.nan), 0.0, 0.5, velocity=v, pll_hz=pll)
        assert np.mean(out.omega[-2000:]) == pytest.approx(0.5 * v / (0.5 + B), rel=5e-3)
        ripple = np.std(np.diff(out.current_cmd[-2000:]))
        if pll:
            smooth = ripple
        else:
            assert ripple > 10 * smooth  # the backward difference's count dither, filtered out by the PLL


def test_bad_loop_arguments_are_refused():
    plant = _spring()
    with pytest.raises(PlantParameterError, match="kp"):
        plant.run_position(np.zeros(3), -1.0, 0.0)
    with pytest.raises(PlantParameterError, match="pll_hz"):
        plant.run_position(np.zeros(3), 1.0, 0.0, pll_hz=0.2 / DT)
    with pytest.raises(PlantParameterError, match="inf"):
        plant.run_position(np.array([0.0, np.inf]), 1.0, 0.0)
