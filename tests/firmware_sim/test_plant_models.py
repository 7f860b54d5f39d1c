"""LuGre, generalized Maxwell-slip and the continuous hysteresis in the C plant: closed forms, the Maxwell-slip
limit of GMS, the bounded reversal stack, and the pure-Python oracle (docs/plant.md, "Friction models")."""

from itertools import pairwise

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import (
    GMS,
    Hysteresis,
    LuGre,
    Plant,
    PlantParameterError,
    PlantParams,
    simulate,
)
from tests.firmware_sim.reference import reference_friction_path, reference_simulate

LG = LuGre(sigma0=1e4, coulomb=0.3, sigma1=5.0, sigma2=0.01, static=0.5, stribeck_velocity=0.1, exponent=1.5)


def _g(v):
    return LG.coulomb + (LG.static - LG.coulomb) * np.exp(-np.abs(v / LG.stribeck_velocity) ** LG.exponent)


@pytest.mark.parametrize("v", [0.02, 0.1, -0.3, 2.0])
def test_lugre_steady_state_along_a_constant_velocity(v):
    # dz/dt = 0 at z = sgn(v)*g(v)/sigma0, so F = sgn(v)*g(v) + sigma2*v; tolerance 1e-6 relative
    t = np.arange(20_000) * 1e-4
    f = Plant(PlantParams(inertia=1e-3, lugre=LG), 1e-4).friction_path(v * t, np.full(t.size, v))
    expected = np.sign(v) * _g(v) + LG.sigma2 * v
    assert abs(f[-1] - expected) <= 1e-6 * abs(expected)


def test_lugre_below_breakaway_stays_in_presliding():
    # torque 0.35 < Fs: the bristles hold it, z -> torque/sigma0 with the velocity decaying to zero
    out = simulate(PlantParams(inertia=1e-3, lugre=LG), np.full(40_000, 0.35), 1e-4, substeps=4)
    assert abs(out.friction[-1] - 0.35) < 1e-6 * 0.35
    assert abs(out.omega[-1]) < 1e-9


@pytest.mark.parametrize("torque", [0.52, -0.8])
def test_lugre_steady_speed_under_constant_torque(torque):
    # A mass under constant torque above break-away settles where torque = sgn(w)*g(w) + sigma2*w (the plant's
    # friction output then equals the closed form at the measured speed); tolerance 1e-6 relative
    p = PlantParams(inertia=1e-3, lugre=LG)
    out = simulate(p, np.full(60_000, torque), 1e-4, substeps=4)
    w, f = out.omega[-1], out.friction[-1]
    assert abs(out.omega[-1] - out.omega[-2]) < 1e-9
    expected = np.sign(w) * _g(w) + LG.sigma2 * w
    assert abs(f - expected) <= 1e-6 * abs(expected)
    assert abs(torque - expected) <= 1e-6 * abs(torque)


def _gms_twin(ms: PlantParams) -> PlantParams:
    w = np.asarray(ms.ms_slip)
    gms = GMS(stiffness=ms.ms_stiffness, fractions=tuple(w / w.sum()), coulomb=float(w.sum()))
    return ms.replace(ms_stiffness=(), ms_slip=(), gms=gms)


@pytest.mark.parametrize("extra", [{}, {"coulomb": 0.05}, {"viscous_neg": 0.003, "spring": 2.0}])
def test_gms_without_sliding_dynamics_is_maxwell_slip(extra):
    # attraction C = inf and no Stribeck: each element is a Jenkins element with W_i = alpha_i*Fc, computed by
    # the GMS code (forces F_i) instead of the lazy Maxwell-slip stop operator (deflections); tolerance 1e-12
    # relative to each signal's range, over 10 000 samples of the identification input
    from benchmarks.bench_plant import excitation

    ms = dc_motor(16).replace(**extra)
    u = excitation(10_000, 1e-4)
    a, b = simulate(ms, u, 1e-4), simulate(_gms_twin(ms), u, 1e-4)
    for name in ("theta", "omega", "friction"):
        va, vb = getattr(a, name), getattr(b, name)
        assert np.max(np.abs(va - vb)) <= 1e-12 * np.max(np.abs(va)), name


def test_gms_sliding_relaxes_to_the_stribeck_curve():
    # At constant velocity every element slips at alpha_i*s(v) and F = s(v) + sigma2*v; after a velocity step
    # within sliding, F_i approaches alpha_i*s(v2) as exp(-C*t/(alpha_i*s)) (closed form, one element)
    gms = GMS(stiffness=(1e4,), fractions=(1.0,), coulomb=0.3, static=0.5, stribeck_velocity=0.1,
              attraction=20.0, viscous=0.01)
    dt = 1e-4
    v = np.r_[np.full(2000, 0.05), np.full(3000, 0.4)]
    x = np.cumsum(v) * dt
    f = Plant(PlantParams(inertia=1.0, gms=gms), dt).friction_path(x, v)

    def s(w):
        return 0.3 + 0.2 * np.exp(-((w / 0.1) ** 2))

    assert abs(f[1999] - (s(0.05) + 0.01 * 0.05)) < 1e-12
    t = np.arange(1, 3001) * dt  # sample 2000 ends the first interval at 0.4 rad/s
    expected = s(0.4) + (s(0.05) - s(0.4)) * np.exp(-20.0 * t / s(0.4)) + 0.01 * 0.4
    np.testing.assert_allclose(f[2000:], expected, rtol=1e-10)


H, D = 1.0, 0.01


def _phi(x):
    return H * (1 - (D / (D + np.abs(x))) ** 2) * np.sign(x)


@pytest.mark.parametrize("amplitude", [0.05 * D, 0.3 * D, D, 4 * D, 20 * D])
def test_continuous_hysteresis_energy_and_stiffness_closed_forms(amplitude):
    # x = A sin(theta): E(A) = 4hA^3/(d+A)^2 and k_eq(A) = 2h*sqrt(d)/(d+A)^1.5 with no discretisation error;
    # the force is exact at every sample, so the only error left is the quadrature (trapezoid for E,
    # 20 000 points per cycle: ~2e-8; rectangle rule on a periodic integrand for k_eq). Tolerance 1e-6.
    n = 20_000
    th = 2 * np.pi * np.arange(3 * n + 1) / n
    x, v = amplitude * np.sin(th), amplitude * np.cos(th)
    f = Plant(PlantParams(inertia=1.0, hysteresis=Hysteresis(H, D, 8)), 1e-3).friction_path(x, v)
    xs, fs, ts = x[2 * n:], f[2 * n:], th[2 * n:]
    energy = np.sum(0.5 * (fs[1:] + fs[:-1]) * np.diff(xs))
    k_eq = np.sum(fs[:-1] * np.sin(ts[:-1])) * (2 * np.pi / n) / (np.pi * amplitude)
    a = amplitude
    assert energy == pytest.approx(4 * H * a**3 / (D + a) ** 2, rel=1e-6)
    assert k_eq == pytest.approx(2 * H * np.sqrt(D) / (D + a) ** 1.5, rel=1e-6)


def test_continuous_hysteresis_masing_branches_and_wiping_out():
    # virgin to a, reversal to b, reversal to c (inner loop), back past b (inner loop wiped: back on the branch
    # from a), past -a (back on the virgin curve); every force against the formula, to 1e-12
    a, b, c = 3 * D, -1 * D, 1 * D
    seg = [np.linspace(0, a, 50), np.linspace(a, b, 80)[1:], np.linspace(b, c, 40)[1:],
           np.linspace(c, -5 * D, 120)[1:]]
    x = np.concatenate(seg)
    plant = Plant(PlantParams(inertia=1.0, hysteresis=Hysteresis(H, D, 8)), 1e-3)
    f = plant.friction_path(x, np.gradient(x))
    fa = _phi(a)
    fb = fa + 2 * _phi((b - a) / 2)
    fc = fb + 2 * _phi((c - b) / 2)
    expected = np.concatenate([
        _phi(seg[0]),
        fa + 2 * _phi((seg[1] - a) / 2),
        fb + 2 * _phi((seg[2] - b) / 2),
        np.where(seg[3] > b, fc + 2 * _phi((seg[3] - c) / 2),
                 np.where(seg[3] > -a, fa + 2 * _phi((seg[3] - a) / 2), _phi(seg[3]))),
    ])
    np.testing.assert_allclose(f, expected, rtol=0, atol=1e-12)
    assert plant.hysteresis_stack == {"depth": 0, "depth_max": 3, "dropped": 0}


def _random_reversals(n_rev: int, seed: int, amplitude: float) -> np.ndarray:
    """Reversal points whose excursions shrink by U(0.5, 1) per reversal (deep nesting), restarting at
    U(0.3, 1)*amplitude with probability 0.05; 20 samples per excursion."""
    rng = np.random.default_rng(seed)
    points, a, sign = [0.0], amplitude, 1.0
    for _ in range(n_rev):
        a = amplitude * rng.uniform(0.3, 1) if rng.uniform() < 0.05 else a * rng.uniform(0.5, 1.0)
        points.append(points[-1] + sign * a)
        sign = -sign
    return np.concatenate([np.linspace(p0, p1, 20, endpoint=False) for p0, p1 in pairwise(points)])


def test_bounded_stack_on_a_long_random_reversal_run():
    # 20 000 reversals (400 000 samples) of amplitude up to 100 d. The unbounded run (stack 1024) must never
    # drop a point; each bounded run holds at most its bound, drops its first reversal exactly at the sample where
    # the unbounded stack first exceeds the bound, and agrees with the unbounded run bit for bit before it.
    # Measured error against the unbounded stack (which reaches depth 118), max |dF|/h (rms |dF|/h):
    # stack 8: 2.2 (0.12); 16: 1.2 (0.015); 32: 7.9e-5 (2.5e-6) -- docs/plant.md.
    x = _random_reversals(20_000, 3, 100 * D)
    v = np.gradient(x)

    def run(stack, n=x.size):
        plant = Plant(PlantParams(inertia=1.0, hysteresis=Hysteresis(H, D, stack)), 1e-3)
        return plant.friction_path(x[:n], v[:n]), plant.hysteresis_stack

    ref, ref_stack = run(1024)
    assert ref_stack["dropped"] == 0 and ref_stack["depth_max"] < 1024
    errors = {}
    for bound in (8, 16, 32):
        f, stack = run(bound)
        assert stack["depth_max"] <= bound and stack["dropped"] > 0
        lo, hi = 1, x.size  # first prefix length whose unbounded run exceeds the bound
        while lo < hi:
            mid = (lo + hi) // 2
            lo, hi = (mid + 1, hi) if run(1024, mid)[1]["depth_max"] <= bound else (lo, mid)
        assert run(bound, lo - 1)[1]["dropped"] == 0 and run(bound, lo)[1]["dropped"] == 1
        np.testing.assert_array_equal(f[:lo], ref[:lo])
        errors[bound] = float(np.max(np.abs(f - ref))) / H
    assert errors[8] >= errors[16] >= errors[32]
    assert errors[32] < 1e-4


def _model_plants():
    lugre = st.builds(LuGre, sigma0=st.floats(10, 1e3), coulomb=st.floats(0.05, 0.5), sigma1=st.floats(0, 2),
                      sigma2=st.floats(0, 0.1), static=st.sampled_from([None, 0.7]),
                      stribeck_velocity=st.floats(0, 0.5), exponent=st.sampled_from([1.0, 2.0, 0.7, 2.5]))
    gms = st.integers(1, 4).flatmap(lambda n: st.builds(
        GMS, stiffness=st.lists(st.floats(10, 500), min_size=n, max_size=n).map(tuple),
        fractions=st.lists(st.floats(0.1, 1), min_size=n, max_size=n).map(tuple),
        coulomb=st.floats(0.05, 0.5), static=st.sampled_from([None, 0.7]), stribeck_velocity=st.floats(0, 0.5),
        exponent=st.sampled_from([1.0, 2.0, 0.7, 2.5]), attraction=st.sampled_from([np.inf, 5.0, 100.0]),
        viscous=st.floats(0, 0.1)))
    hysteresis = st.builds(Hysteresis, h=st.floats(0.05, 1), d=st.floats(1e-3, 0.1), stack=st.integers(3, 6))
    return st.builds(
        PlantParams, inertia=st.floats(0.05, 1.0), lugre=st.one_of(st.none(), lugre),
        gms=st.one_of(st.none(), gms), hysteresis=st.one_of(st.none(), hysteresis),
        coulomb=st.sampled_from([0.0, 0.1]), ms_stiffness=st.just((50.0,)), ms_slip=st.just((0.1,)))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(p=_model_plants(), seed=st.integers(0, 2**32 - 1), mode=st.sampled_from(["current", "velocity"]),
       substeps=st.integers(1, 3))
def test_models_match_python_oracle(p, seed, mode, substeps):
    # tolerance 1e-12 relative to each signal's scale, as for the rest of the plant
    p = p.replace(velocity_kp=0.5, velocity_ki=5.0)
    u = np.random.default_rng(seed).uniform(-2, 2, 300)
    a = simulate(p, u, 1e-3, substeps=substeps, mode=mode)
    b = reference_simulate(p, u, 1e-3, substeps=substeps, mode=mode)
    for name in ("theta", "omega", "friction", "torque"):
        va, vb = getattr(a, name), getattr(b, name)
        assert np.max(np.abs(va - vb)) <= 1e-12 * max(1.0, float(np.max(np.abs(vb)))), name


@settings(max_examples=30, deadline=None)
@given(p=_model_plants(), seed=st.integers(0, 2**32 - 1))
def test_friction_path_matches_python_oracle(p, seed):
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(0, 0.01, 400))
    v = np.gradient(x, 1e-3)
    a = Plant(p, 1e-3).friction_path(x, v)
    b = reference_friction_path(p, x, v, 1e-3)
    assert np.max(np.abs(a - b)) <= 1e-12 * max(1.0, float(np.max(np.abs(b))))


def test_models_round_trip_through_dict():
    p = PlantParams(inertia=1.0, lugre=LG, gms=GMS((1.0, 2.0), (0.5, 0.5), 0.3), hysteresis=Hysteresis(1, 0.1, 5))
    assert PlantParams.from_dict(p.to_dict()) == p


@pytest.mark.parametrize("change, match", [
    ({"lugre": LuGre(sigma0=0.0, coulomb=0.3)}, "lugre.sigma0"),
    ({"lugre": LuGre(sigma0=1.0, coulomb=-0.3)}, "lugre.coulomb"),
    ({"gms": GMS((1.0,), (0.5, 0.5), 0.3)}, "gms.stiffness"),
    ({"gms": GMS((1.0,), (1.0,), 0.3, attraction=0.0)}, "gms.attraction"),
    ({"hysteresis": Hysteresis(1.0, 0.1, 0)}, "hysteresis.stack"),
    ({"hysteresis": Hysteresis(1.0, 0.0)}, "hysteresis.d"),
    ({"hysteresis": Hysteresis(1.0, 1e-7)}, "unstable step"),
])
def test_bad_model_parameters_are_refused(change, match):
    with pytest.raises(PlantParameterError, match=match):
        Plant(PlantParams(inertia=1.0, **change), 1e-3)


def test_simulated_device_config_takes_the_models(tmp_path):
    # the simulated amplifier's TOML builds its plant with PlantParams.from_dict: nested tables select a model,
    # and a bad value is refused with one line naming it
    from hilbench.firmware_sim.devices.sim_config import SimConfigError, load_sim_config

    base = ('[device]\nmodel = "HB-SIM-1"\nserial = "S"\nbuffer_capacity = 8192\n'
            '[plant]\npreset = "none"\ninertia = 0.0022\nviscous = 0.004\n')
    good = tmp_path / "lugre.toml"
    good.write_text(base + "[plant.lugre]\nsigma0 = 3000.0\ncoulomb = 0.76\nsigma1 = 0.5\nstatic = 0.9\n"
                    "stribeck_velocity = 0.05\n[plant.hysteresis]\nh = 0.2\nd = 5e-4\nstack = 16\n")
    cfg = load_sim_config(good)
    assert cfg.plant.lugre == LuGre(sigma0=3000.0, coulomb=0.76, sigma1=0.5, static=0.9, stribeck_velocity=0.05)
    assert cfg.plant.hysteresis == Hysteresis(0.2, 5e-4, 16)
    bad = tmp_path / "bad.toml"
    bad.write_text(base + "[plant.gms]\nstiffness = [100.0]\nfractions = [1.0]\ncoulomb = -1.0\n")
    with pytest.raises(SimConfigError, match="gms.coulomb") as err:
        load_sim_config(bad)
    assert "\n" not in str(err.value)
