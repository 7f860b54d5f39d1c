"""Each injectable effect does what its definition says (docs/plant.md)."""

import numpy as np
import pytest

from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import Cogging, Plant, PlantParams, simulate

DT = 1e-4


def _u(n=4000, seed=0):
    return np.random.default_rng(seed).uniform(-5, 5, n)


def test_all_effects_are_off_by_default():
    p = PlantParams(inertia=1.0)
    assert (p.delay_samples, p.current_lag, p.torque_constant_error, p.torque_offset, p.torque_drift,
            p.counts_per_rev, p.noise_current, p.noise_position, len(p.cogging)) == (0, 0, 0, 0, 0, 0, 0, 0, 0)


def test_pure_delay_shifts_the_torque_by_whole_samples():
    base = simulate(dc_motor(), _u(), DT)
    late = simulate(dc_motor().replace(delay_samples=17), _u(), DT)
    np.testing.assert_array_equal(late.torque[17:], base.torque[:-17])
    np.testing.assert_array_equal(late.torque[:17], 0.0)
    np.testing.assert_array_equal(late.current_cmd, base.current_cmd)


def test_torque_constant_error_offset_and_drift():
    p = dc_motor().replace(torque_constant_error=0.1, torque_offset=0.02, torque_drift=0.5)
    u = _u()
    out = simulate(p, u, DT)
    t = np.arange(u.size) * DT
    np.testing.assert_allclose(out.torque, 0.2 * 1.1 * u + 0.02 + 0.5 * t, rtol=1e-12, atol=1e-13)


def test_current_lag_step_response_is_first_order():
    # step of the command: the sample-averaged current over [t_k, t_k+1) is exact for a first-order lag
    tau = 5e-4
    p = dc_motor().replace(current_lag=tau)
    out = simulate(p, np.full(50, 2.0), DT)
    k = np.arange(50)
    i_start = 2.0 * (1 - np.exp(-k * DT / tau))
    expected_avg = 2.0 - (2.0 - i_start) * tau / DT * (1 - np.exp(-DT / tau))
    np.testing.assert_allclose(out.torque, 0.2 * expected_avg, rtol=1e-12)
    np.testing.assert_allclose(out.current_meas, i_start, rtol=1e-12, atol=1e-15)


def test_encoder_quantisation():
    p = dc_motor().replace(counts_per_rev=4096)
    out = simulate(p, np.full(20_000, 5.0), DT)  # 1 N*m, above break-away: the rotor turns
    q = 2 * np.pi / 4096
    np.testing.assert_allclose(out.position_meas, out.counts * q, rtol=0, atol=1e-15)
    assert np.max(np.abs(out.position_meas - out.theta)) <= q / 2 + 1e-15
    assert np.any(out.counts != 0)


def test_measurement_noise_statistics_and_no_effect_on_mechanics():
    clean = simulate(dc_motor(), _u(50_000), DT)
    noisy = simulate(dc_motor().replace(noise_current=0.05, noise_position=1e-4, seed=3), _u(50_000), DT)
    np.testing.assert_array_equal(clean.theta, noisy.theta)  # noise is on measurements only
    e_i = noisy.current_meas - clean.current_meas
    e_p = noisy.position_meas - clean.position_meas
    n = e_i.size
    assert e_i.std() == pytest.approx(0.05, rel=5 * np.sqrt(0.5 / n))
    assert e_p.std() == pytest.approx(1e-4, rel=5 * np.sqrt(0.5 / n))
    assert abs(np.corrcoef(e_i, e_p)[0, 1]) < 5 / np.sqrt(n)


def test_cogging_equilibrium_and_stiffness():
    # J th'' = tau - A sin(n th): a constant torque T < A holds the rotor at th = asin(T/A)/n, and small
    # oscillations about it have w^2 = A n cos(n th*)/J.
    a, n_c, torque, J = 0.05, 6, 0.02, 1e-3
    p = PlantParams(inertia=J, viscous=0.002, cogging=(Cogging(n_c, a, 0.0),))
    out = simulate(p, np.full(200_000, torque), DT)
    th_star = np.arcsin(torque / a) / n_c
    assert out.theta[-1] == pytest.approx(th_star, rel=1e-6)
    p0 = p.replace(viscous=0.0)
    dev = 1e-4
    free = simulate(p0, np.full(20_000, torque), DT, theta0=th_star + dev).theta - th_star
    crossings = np.flatnonzero(np.diff(np.sign(free)) > 0)
    period = np.mean(np.diff(crossings)) * DT
    w = np.sqrt(a * n_c * np.cos(n_c * th_star) / J)
    assert period == pytest.approx(2 * np.pi / w, rel=2e-3)  # zero-crossing timing resolution


def test_coulomb_sticks_below_breakaway_and_slides_at_the_right_deceleration():
    J, fc = 0.01, 0.3
    p = PlantParams(inertia=J, coulomb=fc)
    stuck = simulate(p, np.full(1000, 0.29), 1e-3)
    assert np.all(stuck.theta == 0.0) and np.all(stuck.omega == 0.0)
    np.testing.assert_allclose(stuck.friction[1:], 0.29, rtol=1e-12)  # reaction equals the load
    slide = simulate(p, np.full(1000, 0.5), 1e-3)
    t = np.arange(1000) * 1e-3
    np.testing.assert_allclose(slide.omega, (0.5 - fc) / J * t, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(slide.theta, 0.5 * (0.5 - fc) / J * t**2, rtol=1e-9, atol=1e-12)
    # free run-out from 2 rad/s stops at t = J w0 / fc and stays stopped
    stop = simulate(p, np.zeros(2000), 1e-3, omega0=2.0)
    t = np.arange(2000) * 1e-3
    t_stop = J * 2.0 / fc
    assert np.all(stop.omega[t > t_stop + 1e-3] == 0.0)
    assert stop.theta[-1] == pytest.approx(J * 2.0**2 / (2 * fc), rel=1e-3)


def test_stribeck_breakaway_is_the_static_level():
    p = PlantParams(inertia=0.01, coulomb=0.3, static=0.5, stribeck_velocity=0.1)
    assert np.all(simulate(p, np.full(500, 0.49), 1e-3).omega == 0.0)
    assert simulate(p, np.full(500, 0.51), 1e-3).omega[-1] > 0.0


def test_asymmetric_viscous_and_coulomb_steady_speed():
    # steady speed v = (tau - Fc_dir)/b_dir in each direction
    p = PlantParams(inertia=0.01, viscous=0.02, viscous_neg=0.04, coulomb=0.1, coulomb_neg=0.2)
    fwd = simulate(p, np.full(20_000, 0.5), 1e-3)
    rev = simulate(p, np.full(20_000, -0.5), 1e-3)
    assert fwd.omega[-1] == pytest.approx((0.5 - 0.1) / 0.02, rel=1e-9)
    assert rev.omega[-1] == pytest.approx(-(0.5 - 0.2) / 0.04, rel=1e-9)


def test_velocity_mode_tracks_a_constant_command():
    # kp*kt = 0.1 N*m*s/rad, ki*kt = 4 N*m/rad: closed-loop wn = 43 rad/s, zeta = 0.55
    p = dc_motor().replace(velocity_kp=0.5, velocity_ki=20.0, current_limit=10.0, counts_per_rev=100_000)
    plant = Plant(p, DT, mode="velocity")
    out = plant.run(np.full(30_000, 5.0))
    assert np.mean(out.omega[-5000:]) == pytest.approx(5.0, rel=1e-3)
    assert np.max(np.abs(out.current_cmd)) <= 10.0


def test_current_limit_clamps_the_command():
    out = simulate(dc_motor().replace(current_limit=1.5), np.array([-9.0, 0.3, 9.0]), DT)
    np.testing.assert_array_equal(out.current_cmd, [-1.5, 0.3, 1.5])


def test_tabulated_curves_act_as_odd_spring_and_damper():
    # A linear table is a linear spring / damper: must equal spring=k, viscous=c to rounding.
    k, c = 40.0, 0.7
    x = np.linspace(0, 10, 11)
    tab = PlantParams(inertia=1.0, restoring_table=(x, k * x), damping_table=(x, c * x))
    lin = PlantParams(inertia=1.0, spring=k, viscous=c)
    u = np.sin(np.arange(5000) * 1e-3 * 7.0)
    a, b = simulate(tab, u, 1e-3), simulate(lin, u, 1e-3)
    np.testing.assert_allclose(a.theta, b.theta, rtol=1e-10, atol=1e-14)
