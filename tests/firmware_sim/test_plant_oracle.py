"""C plant against the pure-Python oracle; determinism and block splitting."""

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hilbench.firmware_sim.engine._plant import ffi, lib
from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import Cogging, Plant, PlantOutput, PlantParams, simulate, stop_operator
from tests.firmware_sim.reference import ReferenceRng, reference_simulate, reference_stop_operator

pos = st.floats(min_value=1e-3, max_value=10.0)


@st.composite
def plants(draw):
    n = draw(st.integers(0, 6))
    k = draw(st.lists(st.floats(1.0, 200.0), min_size=n, max_size=n))
    w = draw(st.lists(st.floats(0.01, 1.0), min_size=n, max_size=n))
    coulomb = draw(st.sampled_from([0.0, 0.05, 0.3]))
    static = draw(st.sampled_from([None, coulomb + 0.1])) if coulomb else None
    cog = draw(st.lists(st.builds(Cogging, st.integers(1, 12), st.floats(0, 0.05), st.floats(-3, 3)),
                        max_size=2))
    table = draw(st.sampled_from([None, ((0.0, 0.1, 1.0), (0.0, 0.2, 0.5))]))
    return PlantParams(
        inertia=draw(st.floats(0.05, 2.0)),
        spring=draw(st.sampled_from([0.0, 5.0])),
        ms_stiffness=tuple(k), ms_slip=tuple(w),
        viscous=draw(st.floats(0, 0.5)), viscous_neg=draw(st.sampled_from([None, 0.2])),
        coulomb=coulomb, coulomb_neg=draw(st.sampled_from([None, coulomb * 1.5])),
        static=static, stribeck_velocity=0.2 if static is not None else 0.0,
        cogging=tuple(cog),
        delay_samples=draw(st.integers(0, 4)),
        current_lag=draw(st.sampled_from([0.0, 3e-3])),
        torque_constant=draw(st.floats(0.05, 2.0)),
        torque_constant_error=draw(st.floats(-0.2, 0.2)),
        torque_offset=draw(st.floats(-0.1, 0.1)), torque_drift=draw(st.floats(-0.1, 0.1)),
        counts_per_rev=draw(st.sampled_from([0, 1000, 65536])),
        noise_current=draw(st.sampled_from([0.0, 0.01])),
        noise_position=draw(st.sampled_from([0.0, 1e-4])),
        seed=draw(st.integers(0, 2**64 - 1)),
        velocity_kp=0.5, velocity_ki=5.0, current_limit=draw(st.sampled_from([np.inf, 2.0])),
        damping_table=table,
    )


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(p=plants(), seed=st.integers(0, 2**32 - 1), mode=st.sampled_from(["current", "velocity"]),
       substeps=st.integers(1, 3))
def test_c_plant_matches_python_oracle(p, seed, mode, substeps):
    # Same operations in the same order (plant.c is built with -ffp-contract=off); tolerance 1e-12
    # relative to each signal's scale.
    rng = np.random.default_rng(seed)
    u = rng.uniform(-3, 3, 300)
    a = simulate(p, u, 1e-3, substeps=substeps, mode=mode)
    b = reference_simulate(p, u, 1e-3, substeps=substeps, mode=mode)
    for name, va in a.as_dict().items():
        vb = getattr(b, name)
        scale = max(1.0, float(np.max(np.abs(vb))))
        assert np.max(np.abs(va - vb)) <= 1e-12 * scale, name


@settings(max_examples=40, deadline=None)
@given(x=st.lists(st.floats(-5, 5), min_size=1, max_size=200),
       deltas=st.lists(st.floats(1e-3, 3.0), min_size=1, max_size=8))
def test_stop_operator_matches_oracle(x, deltas):
    np.testing.assert_array_equal(stop_operator(np.array(x), np.array(deltas)),
                                  reference_stop_operator(np.array(x), np.array(deltas)))


def test_generator_matches_oracle_and_is_normal():
    state = ffi.new("hb_state *")
    params = ffi.new("hb_params *")
    lib.hb_state_init(state, params, 0.0, 0.0, 12345)
    out = np.empty(200_000)
    lib.hb_normals(state, ffi.cast("double *", ffi.from_buffer(out)), out.size)
    ref = ReferenceRng(12345)
    np.testing.assert_array_equal(out[:1000], [ref.normal() for _ in range(1000)])
    # moments of N(0,1) within 5 standard errors
    n = out.size
    assert abs(out.mean()) < 5 / np.sqrt(n)
    assert abs(out.var() - 1) < 5 * np.sqrt(2 / n)
    assert abs(np.mean(out**3)) < 5 * np.sqrt(15 / n)


def _noisy_motor():
    return dc_motor().replace(counts_per_rev=40_000, noise_current=0.02, noise_position=2e-5, seed=7,
                              delay_samples=3, current_lag=1e-4, cogging=(Cogging(7, 0.01, 0.2),),
                              velocity_kp=0.05, velocity_ki=1.0, current_limit=8.0)


def test_block_split_is_bit_identical_to_one_call():
    p = _noisy_motor()
    u = np.random.default_rng(3).uniform(-6, 6, 20_001)
    whole = simulate(p, u, 1e-4)
    plant = Plant(p, 1e-4)
    cuts = [0, 1, 2, 500, 7777, 13_000, 20_001]
    parts = [plant.run(u[a:b]) for a, b in zip(cuts, cuts[1:], strict=False)]
    joined = PlantOutput.concatenate(parts)
    for name, v in whole.as_dict().items():
        np.testing.assert_array_equal(v, getattr(joined, name), err_msg=name)


def test_state_round_trip_and_velocity_mode_split():
    p = _noisy_motor()
    u = np.random.default_rng(4).uniform(-20, 20, 4000)
    whole = simulate(p, u, 1e-4, mode="velocity")
    a = Plant(p, 1e-4, mode="velocity")
    first = a.run(u[:1234])
    saved = a.get_state()
    b = Plant(p, 1e-4, mode="velocity")
    b.set_state(saved)
    second = b.run(u[1234:])
    joined = PlantOutput.concatenate([first, second])
    for name, v in whole.as_dict().items():
        np.testing.assert_array_equal(v, getattr(joined, name), err_msg=name)


def test_seeded_run_is_repeatable_and_seed_matters():
    p = _noisy_motor()
    u = np.random.default_rng(5).uniform(-6, 6, 5000)
    a, b = simulate(p, u, 1e-4), simulate(p, u, 1e-4)
    for name, v in a.as_dict().items():
        np.testing.assert_array_equal(v, getattr(b, name))
    c = simulate(p.replace(seed=8), u, 1e-4)
    assert not np.array_equal(a.current_meas, c.current_meas)


def _realistic_input(n, dt, seed=0):
    from scipy.signal import butter, sosfiltfilt

    t = np.arange(n) * dt
    noise = sosfiltfilt(butter(4, 40.0, fs=1 / dt, output="sos"), np.random.default_rng(seed).uniform(-1, 1, n))
    env = np.sin(2 * np.pi * t / 2.0) + np.sin(6 * np.pi * t / 2.0) / 3
    u = noise * env
    return 15.0 * u / np.max(np.abs(u))


def test_closed_form_linear_stretch_agrees_with_the_oracle_on_a_long_run():
    # A plain motor (no Coulomb, cogging or tables) takes the closed-form RK4 step between saturations
    # (docs/plant.md). 20 000 samples of the identification input, presliding and sliding: rounding differs
    # from the oracle's stage-by-stage arithmetic, so 1e-11 of each signal's scale over the whole run.
    p = dc_motor().replace(noise_current=0.01, counts_per_rev=2**20, seed=3)
    u = _realistic_input(20_000, 1e-4)
    a, b = simulate(p, u, 1e-4), reference_simulate(p, u, 1e-4)
    assert np.ptp(a.theta) > 0.05  # it slides, not only presliding
    for name in ("theta", "omega", "friction", "torque"):
        va, vb = getattr(a, name), getattr(b, name)
        assert np.max(np.abs(va - vb)) <= 1e-11 * np.max(np.abs(vb)), name


def test_closed_form_linear_stretch_is_bit_identical_when_split():
    p = dc_motor().replace(noise_current=0.01, counts_per_rev=2**20, seed=3)
    u = _realistic_input(30_000, 1e-4, seed=1)
    whole = simulate(p, u, 1e-4)
    plant = Plant(p, 1e-4)
    cuts = [0, 1, 999, 12_345, 30_000]
    joined = PlantOutput.concatenate([plant.run(u[a:b]) for a, b in zip(cuts, cuts[1:], strict=False)])
    for name, v in whole.as_dict().items():
        np.testing.assert_array_equal(v, getattr(joined, name), err_msg=name)
