"""Building blocks of the residual loop against closed forms and independent oracles."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.residual import REGISTRY, prepare_run, residual_loop
from hilbench.analysis.residual.design import Setting, bounded_lstsq, fit_model, project_rest
from hilbench.analysis.residual.diagnostics import angle_periodogram, partial_f
from tests.analysis.residual.test_residual_loop import FS, simulated_run


def test_bounded_lstsq_matches_scipy_bvls():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(300, 8))
    y = a @ np.array([1.0, -2.0, 0.5, -0.3, 2.0, 0.0, -1.0, 0.7]) + 0.1 * rng.normal(size=300)
    lower = np.array([0, -np.inf, 0, 0, -np.inf, 0, 0, -np.inf])
    ours = bounded_lstsq(a, y, lower)
    ref = lsq_linear(a, y, bounds=(lower, np.inf), method="bvls", tol=1e-12).x
    # both solve the same strictly convex problem: agreement to solver precision
    np.testing.assert_allclose(ours, ref, atol=1e-8)
    assert ours[3] == 0 and ours[6] == 0  # the bound binds for the negative true values


def test_partial_f_closed_form():
    rng = np.random.default_rng(1)
    n = 20000
    x = rng.normal(size=n)
    e = 0.5 * x + rng.normal(size=n)
    f, p, effect = partial_f(e, x[:, None], None, float(n))
    # explained fraction = 0.25/(0.25 + 1) = 0.2 ; sampling sd ~ 0.006 -> 5 % relative tolerance
    assert effect == pytest.approx(0.2, rel=0.05)
    # F = (R^2/1)/((1 - R^2)/(n - 2)) for the intercept + one column model
    assert f == pytest.approx(effect / ((1 - effect) / (n - 2)), rel=1e-3)
    assert p < 1e-100
    _, p_null, eff_null = partial_f(rng.normal(size=n), x[:, None], None, float(n))
    assert p_null > 1e-3 and eff_null < 1e-3


def test_angle_periodogram_finds_an_order():
    theta = np.linspace(0, 12 * np.pi, 4000) + 0.3 * np.sin(np.linspace(0, 40, 4000))
    e = 0.7 * np.sin(7 * theta + 0.4)
    r2 = angle_periodogram(e, theta, np.arange(1.0, 31.0))
    assert r2[6] == pytest.approx(1.0, abs=1e-9)  # an exact sinusoid in the angle is fully explained
    assert np.max(np.delete(r2, 6)) < 0.05


def test_project_rest_closed_form():
    e = np.array([0.5, -0.5, 0.1, -2.0, 3.0])
    rest = np.array([True, True, True, True, False])
    np.testing.assert_allclose(project_rest(e, rest, 0.3), [0.2, -0.2, 0.0, -1.7, 3.0])


def test_prepare_run_rejects_bad_input():
    with pytest.raises(AnalysisError):
        prepare_run(np.zeros(100), np.zeros(99), 1000.0)
    with pytest.raises(AnalysisError):
        prepare_run(np.full(2000, np.nan), np.zeros(2000), 1000.0)


def test_unknown_start_term_is_a_clear_error():
    run = simulated_run(11)
    with pytest.raises(AnalysisError, match="unknown model term"):
        residual_loop(run, start=("inertia", "nonsense"))


def test_registry_has_the_issue_candidates():
    for name in ("viscous", "stribeck", "asymmetric_friction", "position_periodic", "position_dependent_friction",
                 "delay", "torque_gain", "offset_drift"):
        assert name in REGISTRY and REGISTRY[name].physics


@pytest.fixture(scope="module")
def synthetic_pdf_runs():
    """A friction level that varies with angle, A*sign(v)*sin(5*theta + phi), added to the torque record of a
    plain run: the recorded torque then balances J*theta'' + F_ms + that term exactly (the C plant has no
    such effect to inject). A = 0.06 N*m, phi = 0.5."""
    out = []
    for seed in (21, 1021):
        run = simulated_run(seed)
        extra = 0.06 * np.sign(run.velocity_fast) * np.sin(5 * run.position + 0.5)
        out.append(prepare_run(run.position, run.torque + extra, FS))
    return out


def test_position_dependent_friction_is_found_blind(synthetic_pdf_runs):
    result = residual_loop(synthetic_pdf_runs[0], synthetic_pdf_runs[1])
    assert result.names_added[0] == "position_dependent_friction"
    h = result.effect("position_dependent_friction")["parameters"]["harmonics"][0]
    assert h["order"] == 5
    assert h["amplitude"] == pytest.approx(0.06, rel=0.10)  # 10 %: the issue's bound
    assert h["phase"] == pytest.approx(0.5, abs=0.1)


def test_offset_drift_term_recovers_a_linear_load():
    """Offset + drift added to the torque record: the joint fit returns c0 and c1 (closed form)."""
    run = simulated_run(31)
    t = run.time
    rec = prepare_run(run.position, run.torque + 0.05 + 0.004 * t, FS)
    terms = [(REGISTRY[n], {}) for n in ("inertia", "maxwell_slip", "offset_drift")]
    fit = fit_model(terms, [rec], Setting(None, np.geomspace(6e-4, 0.2, 30)))
    params, unc = REGISTRY["offset_drift"].parameters(fit, {}, "rotary")
    # tolerance 0.01 N*m / 0.001 N*m/s: a few standard errors of the fit (unc) on a 15 s run
    assert params["offset"] == pytest.approx(0.05, abs=0.01)
    assert params["drift"] == pytest.approx(0.004, abs=0.001)
    assert unc["drift"] < 0.001


def test_block_average_keeps_a_held_torque_exact():
    # A torque held sample by sample at 10 kHz and constant over blocks of 5 is, after block_average, exactly
    # the held input at 2 kHz, and the position is the plant's at the block edges (hold_next: start of block).
    from hilbench.analysis.residual.rundata import block_average
    from hilbench.firmware_sim.engine.friction_models import dc_motor
    from hilbench.firmware_sim.engine.plant import simulate

    u2k = np.random.default_rng(0).uniform(-8, 8, 400)
    u10k = np.repeat(u2k, 5)
    fine = simulate(dc_motor(), u10k, 1e-4)
    coarse = simulate(dc_motor(), u2k, 5e-4, substeps=5)
    x, tau, fs = block_average(fine.position_meas, fine.torque, 10_000.0, 5, "hold_next")
    assert fs == 2000.0
    np.testing.assert_allclose(tau, coarse.torque, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(x, coarse.theta, rtol=0, atol=1e-9)  # same held input, RK4 on 5 sub-steps
