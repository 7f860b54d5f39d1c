"""Friction identification: regressors, NNLS fit, DC-motor and paper-system checks, bad input."""

import numpy as np
import pytest
from scipy import signal

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.identify import RunArrays, identify
from hilbench.analysis.identification.maxwell_fit import LipSettings, fit_lip
from hilbench.analysis.identification.output_error import segmented_simulation_error, simulation_error
from hilbench.analysis.identification.regressors import (
    held_torque,
    reversal_travels,
    threshold_grid,
    torque_at_samples,
    triangle_average,
    zero_phase_lowpass,
)
from hilbench.analysis.models.friction_model import FrictionModel
from hilbench.analysis.reproductions.paper import maxwell_slip_closed_form
from hilbench.firmware_sim.engine.friction_models import PAPER_D, PAPER_H, dc_motor, paper_system
from hilbench.firmware_sim.engine.plant import simulate


def random_enveloped(n: int, fs: float, seed: int, amplitude: float, period: float = 4.0) -> np.ndarray:
    """Uniform noise low-passed at 40 Hz times the first three terms of a square wave (science.md §6)."""
    rng = np.random.default_rng(seed)
    r = signal.sosfilt(signal.butter(4, 40.0, fs=fs, output="sos"), rng.uniform(-1, 1, n))
    t = np.arange(n) / fs
    w = 2 * np.pi / period
    env = 4 / np.pi * (np.sin(w * t) + np.sin(3 * w * t) / 3 + np.sin(5 * w * t) / 5)
    return amplitude * env * r / np.max(np.abs(r))


# ---- regressors against closed forms / independent oracles -------------------------------------------


def test_torque_timing_conversions():
    tau = np.array([1.0, 2.0, 4.0, 8.0])
    np.testing.assert_array_equal(held_torque(tau, "hold_next"), tau)
    np.testing.assert_array_equal(held_torque(tau, "hold_previous"), [2, 4, 8, 8])
    np.testing.assert_array_equal(held_torque(tau, "instant"), [1.5, 3, 6, 8])
    np.testing.assert_array_equal(torque_at_samples(tau, "hold_next"), [1, 1.5, 3, 6])
    with pytest.raises(AnalysisError, match="timing"):
        held_torque(tau, "later")


def test_triangle_average_matches_its_response():
    # (x[k-1]+10x[k]+x[k+1])/12 on cos(wkT) is (10+2cos wT)/12 * cos(wkT), exactly
    k = np.arange(200)
    x = np.cos(0.3 * k)
    rows = np.arange(1, 199)
    np.testing.assert_allclose(triangle_average(x, rows), (10 + 2 * np.cos(0.3)) / 12 * x[rows], atol=1e-12)


def test_zero_phase_lowpass_matches_scipy_filtfilt_inside():
    # oracle: scipy's own sosfiltfilt with its default padding; away from the ends both agree
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.normal(size=4000))
    fs, fc = 1000.0, 50.0
    ours = zero_phase_lowpass(x, fs, fc)
    ref = signal.sosfiltfilt(signal.butter(4, fc, fs=fs, output="sos"), x)
    np.testing.assert_allclose(ours[500:-500], ref[500:-500], atol=1e-6 * np.ptp(x))


def test_reversal_travels_of_a_triangle_wave():
    x = np.concatenate([np.linspace(0, 2, 50), np.linspace(2, -1, 80), np.linspace(-1, 0.5, 40)])
    np.testing.assert_allclose(reversal_travels(x, 0.01), [2.0, 3.0, 1.5], atol=1e-12)


def test_threshold_grid_is_log_spaced_and_ranged_from_the_data():
    # slow enough that consecutive samples differ by 0 or one 1e-3 quantum
    x = np.round(np.concatenate([np.linspace(0, 2, 5000), np.linspace(2, -1, 8000)]) / 1e-3) * 1e-3
    g = threshold_grid(x, 10)
    assert g[0] == pytest.approx(2e-3, rel=1e-6)  # 2 x the 1e-3 quantum
    assert g[-1] == pytest.approx(1.5, rel=1e-6)  # half the largest travel (3)
    np.testing.assert_allclose(np.diff(np.log(g)), np.log(g[1] / g[0]))
    with pytest.raises(AnalysisError, match="hardly moves"):
        threshold_grid(np.zeros(100), 10)


# ---- fits against known systems -----------------------------------------------------------------------


def test_linear_system_recovered_exactly():
    # inertia + viscous only: the filtered equation is exact, so J and b come back to 1e-4
    fs = 1000.0
    p = dc_motor().replace(ms_stiffness=(), ms_slip=())
    u = random_enveloped(20_000, fs, 3, 6.0)
    out = simulate(p, u, 1 / fs, substeps=8)
    fit = fit_lip(out.theta, p.torque_constant * u, fs, settings=LipSettings(cutoff=50.0))
    assert fit.model.inertia == pytest.approx(p.inertia, rel=1e-4)
    assert fit.model.viscous == pytest.approx(p.viscous, rel=1e-3)
    assert fit.model.breakaway < 1e-3 * 0.76  # no friction invented


def _dc_run(seed: int, fs: float = 4000.0, n: int = 100_000, amplitude: float = 16.0):
    # amplitude 16 A (3.2 N*m, 4x the break-away) is the bench's default identification protocol
    p = dc_motor().replace(counts_per_rev=2**20, noise_current=0.02, seed=seed)
    out = simulate(p, random_enveloped(n, fs, seed, amplitude), 1 / fs)
    # torque from the measured current: sampled at t_k, it is the mean over [t_k-1, t_k)
    return p, RunArrays(np.arange(n) / fs, p.torque_constant * out.current_meas, out.position_meas)


@pytest.mark.parametrize("seed", [1, 5, 9])
def test_dc_motor_identified_and_validated(seed):
    # training: 100 s at 4 kHz; validation: 25 s of another seed
    p, train = _dc_run(seed, n=400_000)
    _, val = _dc_run(seed + 100)
    settings = LipSettings(timing="hold_previous")
    res = identify(train, validate=val, settings=settings)
    m = res.model
    truth = FrictionModel("rotary", p.inertia, np.array(p.ms_stiffness), p.ms_delta, viscous=p.viscous)
    # J within 1 % (issue target; measured 0.01 %) and b within 2 % (measured 0.35 %; virgin curve 0.1 % RMS)
    assert m.inertia == pytest.approx(p.inertia, rel=0.01)
    assert m.viscous == pytest.approx(p.viscous, rel=0.02)
    # virgin curve within 2 % RMS (issue target), pointwise relative, on a log grid over the excited
    # range: from 2 encoder counts (below that the quantised path cannot resolve a threshold) to half
    # the largest travel between reversals, capped where the true curve is flat (100*d).
    q = 2 * np.pi / 2**20
    hi = min(0.5 * reversal_travels(train.position, 4 * q).max(), 100 * 5e-4)
    x = np.geomspace(2 * q, hi, 200)
    rel = m.virgin_curve(x) / truth.virgin_curve(x) - 1
    assert np.sqrt(np.mean(rel**2)) < 0.02
    # Validation simulation error against the noise floor: the true model's error under the same
    # measured torque, in the same figure. The 1.2x is held on the segmented simulation (restarted
    # every second from the measured state; measured 1.00-1.09 over 7 seeds). The whole-record open-loop
    # figure is a random walk of the torque noise: for the true model it varies 7x between seeds, and a
    # fitted model beats it on some (measured ratio 0.97-1.53 over 7 seeds), so it gets a loose guard.
    floor_seg, _ = segmented_simulation_error(truth, val.position, val.torque, val.fs, timing="hold_previous")
    assert res.figures["validation_position_nrmse_segmented"] < 1.2 * floor_seg
    floor, _ = simulation_error(truth, val.position, val.torque, val.fs, timing="hold_previous")
    assert res.figures["validation_position_nrmse"] < 2.0 * floor
    assert res.figures["validation_torque_nrmse"] < 0.05


def test_segmented_simulation_restarts_from_the_measured_state(monkeypatch):
    # Oracle: noise-free, unquantised run of the true model. Restarting from the measured position, the
    # filtered velocity and the stop-operator deflections of the measured path reproduces the run closely
    # (only the velocity estimate is approximate: 1.2e-4 of std(x)); restarted with relaxed elements instead,
    # it is 30x worse (measured 3.9e-3). The stop operator is evaluated in chunks: a tiny chunk must not change it.
    import hilbench.analysis.identification.output_error as oe

    p = dc_motor()
    fs, n = 4000.0, 40_000
    out = simulate(p, random_enveloped(n, fs, 2, 16.0), 1 / fs)
    truth = FrictionModel("rotary", p.inertia, np.array(p.ms_stiffness), p.ms_delta, viscous=p.viscous)
    tau = p.torque_constant * out.current_meas
    e, sim = segmented_simulation_error(truth, out.theta, tau, fs, timing="hold_previous", segment=0.5)
    assert e < 2e-4
    monkeypatch.setattr(oe, "CHUNK_VALUES", 16 * 2000 + 7)
    e2, sim2 = segmented_simulation_error(truth, out.theta, tau, fs, timing="hold_previous", segment=0.5)
    np.testing.assert_array_equal(sim2, sim)
    from hilbench.firmware_sim.engine.plant import Plant

    monkeypatch.setattr(Plant, "set_deflections", lambda self, v: None)  # restart with relaxed elements
    e_relaxed, _ = segmented_simulation_error(truth, out.theta, tau, fs, timing="hold_previous", segment=0.5)
    assert e_relaxed > 10 * e
    with pytest.raises(AnalysisError, match="segment"):
        segmented_simulation_error(truth, out.theta, tau, fs, segment=0.0)


def _paper_chirp_fit(n_elements: int):
    fs = 1000.0
    t = np.arange(int(20 * fs)) / fs
    p = paper_system(n_elements)
    u = 20.0 * np.sin(0.1 * np.pi * t**2)
    out = simulate(p, u, 1 / fs, substeps=8)
    return p, out.theta, fit_lip(out.theta, u, fs, "linear", LipSettings(spring=True)).model


def test_paper_system_equivalent_curves_from_a_chirp():
    """science.md §3 closed forms: k_eq(A) = 2h sqrt(d)/(d+A)^1.5 and E(A) = 4hA^3/(d+A)^2, within 3 %.

    The closed forms are those of the continuous virgin curve. The paper's 16-element discretisation departs
    from them by up to 14 % in E (docs/plant.md), so the system identified here is the paper's with 64
    elements (within 0.6 %). The chirp G = 20 N, 0-2 Hz over 20 s cycles through half-travels of 0.2-3.4 m
    between reversals and loads the virgin curve from rest; the curves are checked from 0.06 m to a quarter
    of the travel (measured: k_eq 0.14 %, E 1.9 %; at 0.047 m, twice the smallest identified Delta, E is 3.6 %
    low).
    """
    p, theta, m = _paper_chirp_fit(64)
    assert m.inertia == pytest.approx(1.0, rel=1e-3)
    a = np.geomspace(0.06, 0.25 * np.ptp(theta), 40)
    assert 2 * m.ms_delta.min() < a[0]
    keq, energy = maxwell_slip_closed_form(m.plant_params(), a)  # science.md §3, per element
    # Elements that never slip are indistinguishable from the linear spring, so the identifiable
    # friction stiffness is k_eq + (K_identified - 50), with the known spring 50 N/m.
    keq_total = keq + (m.spring - 50.0)
    np.testing.assert_allclose(keq_total, 2 * PAPER_H * np.sqrt(PAPER_D) / (PAPER_D + a) ** 1.5, rtol=0.03)
    np.testing.assert_allclose(energy, 4 * PAPER_H * a**3 / (PAPER_D + a) ** 2, rtol=0.03)


def test_paper_16_element_system_recovered_from_a_chirp():
    # The paper's own 16 elements: against the closed form evaluated on the true elements (science.md §3 per
    # element), k_eq within 3 % and E within 3 % for A >= d/2 (below, the identified grid places its few
    # small thresholds differently from the true ones).
    p, theta, m = _paper_chirp_fit(16)
    a = np.geomspace(2 * m.ms_delta.min(), 0.25 * np.ptp(theta), 40)
    keq, energy = maxwell_slip_closed_form(m.plant_params(), a)  # science.md §3, per element
    k_true, e_true = maxwell_slip_closed_form(p, a)
    np.testing.assert_allclose(keq + (m.spring - 50.0), k_true, rtol=0.03)
    sel = a >= 0.5 * PAPER_D
    assert sel.sum() >= 5
    np.testing.assert_allclose(energy[sel], e_true[sel], rtol=0.03)


def test_threshold_refinement_stays_inside_the_candidate_range():
    # An unbounded refinement step once drove a threshold towards 0 (seed 1, 100 000 samples), and the element became so
    # stiff that the validation simulation asked for an absurd number of sub-steps (OverflowError in C).
    # Here: the bound holds and the refined model simulates.
    p, run = _dc_run(13, n=20_000)
    fit = fit_lip(run.position, run.torque, run.fs, settings=LipSettings(timing="hold_previous", refine=True))
    d = fit.model.ms_delta
    g = fit.candidate_deltas
    assert d.size > 0 and np.all(d >= g[0] * (1 - 1e-9)) and np.all(d <= g[-1] * (1 + 1e-9))
    err, _ = simulation_error(fit.model, run.position, run.torque, run.fs, timing="hold_previous")
    assert np.isfinite(err)


# ---- bad input ----------------------------------------------------------------------------------------


def _ok_run(n=4000, fs=1000.0):
    p = dc_motor()
    u = random_enveloped(n, fs, 0, 6.0)
    out = simulate(p, u, 1 / fs)
    return RunArrays(np.arange(n) / fs, p.torque_constant * u, out.theta)


def test_bad_input_gives_clear_errors():
    run = _ok_run()
    with pytest.raises(AnalysisError, match="no torque channel"):
        identify(RunArrays(run.t, None, run.position))
    bad = run.position.copy()
    bad[17] = np.nan
    with pytest.raises(AnalysisError, match="NaN or inf.*sample 17"):
        identify(RunArrays(run.t, run.torque, bad))
    with pytest.raises(AnalysisError, match="too short"):
        identify(RunArrays(run.t[:50], run.torque[:50], run.position[:50]))
    with pytest.raises(AnalysisError, match="never changes"):
        identify(RunArrays(run.t, run.torque, np.zeros_like(run.t)))
    jitter = run.t + 0.05 * (run.t[1] - run.t[0]) * np.sin(np.arange(run.t.size))
    with pytest.raises(AnalysisError, match="not uniformly spaced"):
        identify(RunArrays(jitter, run.torque, run.position))
    # time stored in float32 (as EMPS does) is uniform to ~1e-4 of the period: accepted, fs from the whole span
    t32 = (run.t + 20.0).astype(np.float32).astype(float)
    assert RunArrays(t32, run.torque, run.position).fs == pytest.approx(run.fs, rel=1e-6)
    identify(RunArrays(t32, run.torque, run.position))
    with pytest.raises(AnalysisError, match="axis"):
        identify(RunArrays(run.t, run.torque, run.position, axis="helical"))
    with pytest.raises(AnalysisError, match="method"):
        identify(run, method="magic")


def test_unexciting_run_names_the_unidentifiable_parameter():
    # a slow ramp with constant acceleration-free motion: J has nothing to stand on
    fs, n = 1000.0, 4000
    t = np.arange(n) / fs
    rng = np.random.default_rng(1)
    position = 0.5 * t + 1e-7 * rng.normal(size=n)
    torque = 0.76 + 0.004 * 0.5 + 1e-3 * rng.normal(size=n)
    with pytest.raises(AnalysisError, match="inertia J is unidentifiable"):
        identify(RunArrays(t, torque, position))


def test_absurdly_stiff_model_gives_a_clear_error():
    from hilbench.analysis.identification.output_error import stable_substeps

    m = FrictionModel("rotary", 1e-3, np.array([1e20]), np.array([1e-12]), viscous=0.0)
    with pytest.raises(AnalysisError, match="cannot be simulated.*sub-steps"):
        stable_substeps(m, 1e-3)


def test_path_deflections_in_chunks_equal_the_full_stop_operator(monkeypatch):
    import hilbench.analysis.identification.output_error as oe
    from hilbench.firmware_sim.engine.plant import stop_operator

    rng = np.random.default_rng(7)
    x = np.cumsum(rng.normal(scale=1e-3, size=5000))
    deltas = np.array([1e-4, 1e-3, 5e-3])
    idx = np.array([0, 1, 17, 999, 1000, 1001, 4999])
    monkeypatch.setattr(oe, "CHUNK_VALUES", 3 * 1000)  # chunks of 1000 samples
    np.testing.assert_array_equal(oe.path_deflections(x, deltas, idx), stop_operator(x, deltas)[idx])
