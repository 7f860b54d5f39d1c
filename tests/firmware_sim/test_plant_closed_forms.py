"""The C plant against closed forms (docs/science.md §2-§3)."""

import numpy as np
import pytest
from scipy.linalg import expm

from hilbench.firmware_sim.engine.friction_models import (
    discretise_virgin_curve,
    geometric_breakpoints,
    maxwell_virgin_curve,
    virgin_curve,
)
from hilbench.firmware_sim.engine.plant import PlantParams, simulate, stop_operator
from tests.firmware_sim.loops import sine_loop

H, D = 1.64, 0.656


@pytest.mark.parametrize("amplitude", [0.1, 0.25, 0.26, 0.5, 1.0, 7.3])
def test_jenkins_element_matches_closed_form(amplitude):
    # One element k, W, Delta = W/k: A <= Delta -> k_eq = k, E = 0; else cos(t*) = 1 - 2 Delta/A,
    # k_eq = (k/pi)(t* - sin(2 t*)/2), E = 4 W (A - Delta).  Tolerance 1e-6 relative (trapezoidal
    # rule over 1e6 points per cycle; the force is piecewise linear so the error is O(n^-2) ~ 1e-11).
    k, w = 2.0, 0.5
    delta = w / k
    energy, keq = sine_loop(np.array([k]), np.array([w]), amplitude, n=1_000_000)
    if amplitude <= delta:
        assert keq == pytest.approx(k, rel=1e-6)
        assert abs(energy) < 1e-9
    else:
        ts = np.arccos(1 - 2 * delta / amplitude)
        assert keq == pytest.approx(k / np.pi * (ts - 0.5 * np.sin(2 * ts)), rel=1e-6)
        assert energy == pytest.approx(4 * w * (amplitude - delta), rel=1e-6)


def _closed_forms(a):
    return 4 * H * a**3 / (D + a) ** 2, 2 * H * np.sqrt(D) / (D + a) ** 1.5


def test_discretised_virgin_curve_converges_to_closed_forms():
    # E(A) = 4hA^3/(d+A)^2 and k_eq(A) = 2h sqrt(d)/(d+A)^1.5 for A in [0.05 d, 20 d]:
    # the error must fall with N and be < 1 % at N = 64 (issue #2).
    amplitudes = D * np.geomspace(0.05, 20, 9)
    worst = {}
    for n in (8, 16, 32, 64):
        k, w = discretise_virgin_curve(geometric_breakpoints(D, n), H, D)
        errors = []
        for a in amplitudes:
            energy, keq = sine_loop(k, w, a, n=40_000)
            e_ref, k_ref = _closed_forms(a)
            errors.append(max(abs(energy / e_ref - 1), abs(keq / k_ref - 1)))
        worst[n] = max(errors)
    ns = sorted(worst)
    assert all(worst[a] > worst[b] for a, b in zip(ns, ns[1:], strict=False)), worst
    assert worst[64] < 0.01, worst


def test_discretisation_is_exact_at_breakpoints():
    b = geometric_breakpoints(D, 16)
    k, w = discretise_virgin_curve(b, H, D)
    assert np.all(k > 0)
    assert np.sum(k) == pytest.approx(np.diff(virgin_curve([0, b[0]], H, D))[0] / b[0], rel=1e-12)
    np.testing.assert_allclose(maxwell_virgin_curve(b, k, w), virgin_curve(b, H, D), rtol=1e-12)
    mid = np.sqrt(b[1:] * b[:-1])
    # between breakpoints the curve is the chord (piecewise-linear interpolant)
    np.testing.assert_allclose(maxwell_virgin_curve(mid, k, w), np.interp(mid, b, virgin_curve(b, H, D)),
                               rtol=1e-12)


def test_wiping_out_and_masing():
    # Go to A, reverse to x1, do a minor loop x1 -> x2 -> x1, then continue to -A. Once the minor loop
    # closes, the force must be back on the outer branch: identical to the path without the minor loop.
    k, w = discretise_virgin_curve(geometric_breakpoints(D, 32), H, D)
    a, x1, x2 = 2.0, 0.5, 1.2
    up = np.linspace(0, a, 4001)
    down1 = np.linspace(a, x1, 3001)[1:]
    minor = np.concatenate([np.linspace(x1, x2, 2001)[1:], np.linspace(x2, x1, 2001)[1:]])
    down2 = np.linspace(x1, -a, 5001)[1:]
    with_loop = np.concatenate([up, down1, minor, down2])
    without = np.concatenate([up, down1, down2])
    f_with = stop_operator(with_loop, w / k) @ k
    f_without = stop_operator(without, w / k) @ k
    np.testing.assert_allclose(f_with[-down2.size:], f_without[-down2.size:], rtol=0, atol=1e-12)
    # Masing: the descending branch from (A, F_A) is F = F_A - 2 phi_N(|x - A|/2)
    f_a = f_without[up.size - 1]
    branch = f_a - 2 * maxwell_virgin_curve(np.abs(without[up.size:] - a) / 2, k, w)
    np.testing.assert_allclose(f_without[up.size:], branch, rtol=0, atol=1e-12)


def _msd_exact(m, c, kk, dt, x0, u):
    # Exact solution of m x'' + c x' + k x = u with u held over each sample (matrix exponential).
    a = np.array([[0, 1], [-kk / m, -c / m]])
    b = np.array([0, 1 / m])
    ad = expm(a * dt)
    bd = np.linalg.solve(a, (ad - np.eye(2)) @ b)
    x = np.empty((u.size, 2))
    s = np.array(x0, float)
    for i, ui in enumerate(u):
        x[i] = s
        s = ad @ s + bd * ui
    return x


def test_linear_msd_free_decay_matches_analytic():
    # m x'' + c x' + k x = 0 from x0: x = e^{-zeta wn t}(x0 cos wd t + x0 zeta wn / wd sin wd t).
    # Tolerance 1e-6 of the initial amplitude (RK4 at wn*h = 7e-3: error ~ 1e-10).
    m, c, kk, x0, dt = 1.0, 0.4, 50.0, 0.3, 1e-3
    p = PlantParams(inertia=m, spring=kk, viscous=c)
    out = simulate(p, np.zeros(20_000), dt, theta0=x0)
    t = np.arange(out.theta.size) * dt
    wn = np.sqrt(kk / m)
    zeta = c / (2 * np.sqrt(kk * m))
    wd = wn * np.sqrt(1 - zeta**2)
    x = np.exp(-zeta * wn * t) * (x0 * np.cos(wd * t) + x0 * zeta * wn / wd * np.sin(wd * t))
    assert np.max(np.abs(out.theta - x)) < 1e-6 * x0


def test_linear_msd_forced_steady_state_matches_analytic():
    # Forced by a sine held sample-by-sample (as a device does). The analytic reference is the exact
    # zero-order-hold solution (matrix exponential); compare the last 2 s, tolerance 1e-6 of amplitude.
    # zeta = 0.14, so the start-up transient has decayed by e^-30 at the end.
    m, c, kk, dt = 1.0, 2.0, 50.0, 1e-3
    t = np.arange(30_000) * dt
    u = 2.0 * np.sin(2 * np.pi * 1.25 * t)  # 800 samples per period
    out = simulate(PlantParams(inertia=m, spring=kk, viscous=c), u, dt)
    ref = _msd_exact(m, c, kk, dt, [0.0, 0.0], u)
    amp = np.max(np.abs(ref[-2000:, 0]))
    assert np.max(np.abs(out.theta - ref[:, 0])[-2000:]) < 1e-6 * amp
    assert np.max(np.abs(out.omega - ref[:, 1])[-2000:]) < 1e-6 * np.max(np.abs(ref[-2000:, 1]))
    # and the steady-state amplitude is the analytic FRF |1/(k - m W^2 + i c W)| of the held input,
    # whose fundamental is the sine scaled by sinc(f dt) and delayed dt/2 (ZOH), to 1e-6 relative
    w = 2 * np.pi * 1.25
    zoh = np.sinc(1.25 * dt)
    frf = 2.0 * zoh / abs(kk - m * w**2 + 1j * c * w)
    tail = out.theta[-8000:]  # 10 whole periods
    fund = 2 * abs(np.mean(tail * np.exp(-1j * w * t[-tail.size:])))
    assert fund == pytest.approx(frf, rel=1e-6)


def _coulomb_sine_oracle(g: float, periods: int) -> np.ndarray:
    """Mass m = 1 with Coulomb friction Fc = 1 under F = g*sin(2*pi*t) from rest (g > Fc at every velocity
    zero, so pure sliding after break-away): DOP853 (rtol 1e-13) between event-located velocity zeros.
    Returns the position at t = 0, 1, ..., periods."""
    from scipy.integrate import solve_ivp

    w = 2 * np.pi
    t, s, y = np.arcsin(1.0 / g) / w, 1.0, np.zeros(2)  # sticks until g*sin(wt) reaches Fc
    pieces = []
    while True:
        def zero_velocity(_t, yy):
            return yy[1]

        zero_velocity.terminal, zero_velocity.direction = True, -s
        sol = solve_ivp(lambda _t, yy, s=s: [yy[1], g * np.sin(w * _t) - s], (t, periods), y,
                        method="DOP853", rtol=1e-13, atol=1e-15, dense_output=True, events=zero_velocity)
        pieces.append((t, sol.t[-1], sol.sol))
        if sol.status != 1:
            break
        t, y = sol.t_events[0][0], np.array([sol.y_events[0][0][0], 0.0])
        s = np.sign(np.sin(w * t))
        assert abs(g * np.sin(w * t)) > 1.0  # no sticking after the start
    x = []
    for tk in range(periods + 1):
        x.append(0.0 if tk < pieces[0][0] else next(f(tk)[0] for a, b, f in pieces if a <= tk <= b))
    return np.array(x)


@pytest.mark.parametrize("samples_per_period, substeps", [(400, 8), (1600, 1), (1600, 2), (1600, 32)])
def test_coulomb_mass_under_a_sine_has_no_creep(samples_per_period, substeps):
    # From rest the mean-velocity offset of the start decays: the drift per period falls from 3.8e-6 of
    # G/(m*w^2) at period 10 to round-off by period 30 (oracle above). Projecting a whole sub-step in the new
    # direction at a reversal (before the reversal instant was located) kept a creep of up to 3.5e-3 per period.
    g, periods = 3.3, 30
    dt = 1.0 / samples_per_period
    t = np.arange(periods * samples_per_period + 1) * dt
    x = simulate(PlantParams(inertia=1.0, coulomb=1.0), g * np.sin(2 * np.pi * (t + dt / 2)), dt,
                 substeps=substeps).theta[::samples_per_period]
    unit = g / (2 * np.pi) ** 2
    ref = _coulomb_sine_oracle(g, periods)
    drift, drift_ref = np.diff(x) / unit, np.diff(ref) / unit
    assert drift[9] == pytest.approx(drift_ref[9], rel=0.02)  # the transient, 3.8e-6
    assert np.max(np.abs(drift[25:])) < 1e-9
    # positions: the held (mid-sample) force differs from the continuous sine by O(dt^2): 4e-5 at 400 samples
    np.testing.assert_allclose(x, ref, atol=1e-4 * unit)
