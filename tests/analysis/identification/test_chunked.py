"""The NNLS fit over a record read chunk by chunk (analysis/identification/chunked.py, maxwell_fit.fit_lip_chunks)
against the same fit on the whole record, and against the whole-record regressors it replaces."""

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.chunked import array_chunks, blocks, default_margin, scan
from hilbench.analysis.identification.maxwell_fit import LipSettings, fit_lip, fit_lip_chunks, grid_from_scan
from hilbench.analysis.identification.regressors import (
    filtered_data,
    position_resolution,
    stop_columns,
    threshold_grid,
)
from tests.analysis.identification.test_identification import _dc_run

FS = 4000.0


@pytest.fixture(scope="module")
def run():
    return _dc_run(3, fs=FS, n=24_000)[1]


def test_blocks_match_the_whole_record_regressors(run):
    # every regressor column of the whole-record code (zero-phase filter of the entire record), against the
    # blocks of 700 samples with their 40-time-constant margins: equal to rounding (the margin leaves exp(-40)
    # of a start-up transient). Rounding: 1e-12 of each column's scale; the acceleration, a second difference
    # /T^2 of a position of some rad, carries eps*max|x|/T^2 = 2e-8 rad/s^2 of it, so 1e-9 of its scale
    x, tau = run.position, run.torque
    deltas = np.geomspace(1e-5, 1e-2, 7)
    whole = filtered_data(x, tau, FS, FS / 20, decimation=8, timing="hold_previous")
    stop = stop_columns(x, deltas, whole)
    got = list(blocks(array_chunks(x, tau, 333), FS, FS / 20, decimation=8, timing="hold_previous",
                      deltas=deltas, block=700))
    rows = np.concatenate([b.rows for b in got])
    np.testing.assert_array_equal(rows, whole.rows)
    for name in ("torque", "acceleration", "velocity", "position", "sign"):
        ref = getattr(whole, name)
        err = np.max(np.abs(np.concatenate([getattr(b, name) for b in got]) - ref))
        assert err <= (1e-9 if name == "acceleration" else 1e-12) * np.max(np.abs(ref)), name
    err = np.max(np.abs(np.vstack([b.stop for b in got]) - stop))
    assert err <= 1e-12 * np.max(np.abs(stop))


def test_chunking_of_the_source_does_not_change_a_bit(run):
    # blocks are cut on the global sample index, so how the source slices the record is invisible
    x, tau = run.position, run.torque
    s = LipSettings(timing="hold_previous")
    a = fit_lip_chunks(array_chunks(x, tau, 97), FS, settings=s, block=3000)
    b = fit_lip_chunks(array_chunks(x, tau, 10_000), FS, settings=s, block=3000)
    np.testing.assert_array_equal(a.model.ms_stiffness, b.model.ms_stiffness)
    np.testing.assert_array_equal(a.predicted, b.predicted)
    assert a.model.inertia == b.model.inertia


@pytest.mark.parametrize("settings", [LipSettings(timing="hold_previous"),
                                      LipSettings(timing="hold_previous", coulomb=True, offset=True),
                                      LipSettings(timing="hold_previous", fixed_inertia=0.0022)])
def test_streamed_with_tiny_chunks_equals_the_whole_record(run, settings):
    # streamed: chunks of 97 samples, blocks of 2 margins (672 samples); whole: one block holding the record.
    # Same elements; every parameter and standard error to 1e-7 relative, the prediction to 1e-9 of std(L tau)
    # (measured: 4e-11 and 1e-11; the rest is rounding through NNLS on the QR factor)
    x, tau = run.position, run.torque
    margin = default_margin(FS, FS / 20)
    whole = fit_lip(x, tau, FS, settings=settings, block=x.size)
    grid = whole.candidate_deltas
    tiny = fit_lip_chunks(array_chunks(x, tau, 97), FS, settings=settings, grid=grid, block=2 * margin,
                          calibrated=True)  # the standard errors of whole arrays (HAC, bootstrap)
    assert tiny.model.ms_stiffness.size == whole.model.ms_stiffness.size > 3
    np.testing.assert_allclose(tiny.model.ms_delta, whole.model.ms_delta, rtol=1e-7)
    np.testing.assert_allclose(tiny.model.ms_stiffness, whole.model.ms_stiffness, rtol=1e-7)
    for name in ("inertia", "viscous", "coulomb", "offset"):
        assert getattr(tiny.model, name) == pytest.approx(getattr(whole.model, name), rel=1e-7, abs=1e-12), name
    for name, se in whole.model.std_errors.items():
        np.testing.assert_allclose(tiny.model.std_errors[name], se, rtol=1e-6, err_msg=name)
    np.testing.assert_array_equal(tiny.rows, whole.rows)
    assert np.max(np.abs(tiny.predicted - whole.predicted)) <= 1e-9 * np.std(whole.measured)
    assert tiny.n_eff == pytest.approx(whole.n_eff, rel=1e-6)


@pytest.mark.parametrize("settings", [LipSettings(timing="hold_previous"),
                                      LipSettings(timing="hold_previous", coulomb=True, offset=True),
                                      LipSettings(timing="hold_previous", fixed_inertia=0.0022)])
def test_whole_arrays_filter_the_record_once_per_new_threshold_set(run, settings, monkeypatch):
    # fit_lip keeps its passes and picks the columns of a later threshold subset (pruned elements, the final
    # prediction, the bootstrap's grid; each setting here prunes) instead of filtering the record again: 2
    # passes (grid, merged) where it made 5, with the model, the prediction and the equation-error figure of
    # a fit that keeps nothing (the streamed path, every pass fresh) to 1e-9 relative (measured: bit for bit)
    from hilbench.analysis.identification import maxwell_fit

    x, tau = run.position, run.torque
    passes = []
    counted = maxwell_fit.blocks

    def counting(*args, **kwargs):
        passes.append(np.size(kwargs.get("deltas")))
        return counted(*args, **kwargs)

    monkeypatch.setattr(maxwell_fit, "blocks", counting)
    whole = fit_lip(x, tau, FS, settings=settings)
    assert len(passes) == 2, passes  # the 64 candidates, then the merged elements
    monkeypatch.setattr(maxwell_fit, "blocks", counted)
    fresh = fit_lip_chunks(array_chunks(x, tau), FS, settings=settings, grid=whole.candidate_deltas)
    assert whole.model.ms_delta.size == fresh.model.ms_delta.size > 2
    np.testing.assert_allclose(whole.model.ms_delta, fresh.model.ms_delta, rtol=1e-9)
    np.testing.assert_allclose(whole.model.ms_stiffness, fresh.model.ms_stiffness, rtol=1e-9)
    for name in ("inertia", "viscous", "coulomb", "offset"):
        assert getattr(whole.model, name) == pytest.approx(getattr(fresh.model, name), rel=1e-9, abs=1e-15), name
    np.testing.assert_array_equal(whole.rows, fresh.rows)
    np.testing.assert_allclose(whole.predicted, fresh.predicted, rtol=0, atol=1e-9 * np.std(fresh.measured))
    assert whole.torque_nrmse == pytest.approx(fresh.torque_nrmse, rel=1e-9)


def test_scan_gives_the_whole_record_grid(run):
    # a record of one noise block and at most 2x20000 points: the scan's resolution and thinned path are the
    # whole array's, so the grid is threshold_grid's to rounding
    x = run.position[:20_000]
    sc = scan(array_chunks(x, run.torque[:20_000], 1234))
    assert sc.n == x.size
    assert sc.resolution == pytest.approx(position_resolution(x), rel=1e-12)
    np.testing.assert_allclose(grid_from_scan(sc, 64), threshold_grid(x, 64), rtol=1e-12)


def test_a_streamed_fit_without_a_grid_scans_the_record(run):
    # the grid from the scan (median of block noise levels, power-of-2 thinning) against the whole array's:
    # the same fit to 1 % (measured: the grid differs by the thinning of the reversal travels only)
    x, tau = run.position, run.torque
    s = LipSettings(timing="hold_previous")
    whole = fit_lip(x, tau, FS, settings=s)
    streamed = fit_lip_chunks(array_chunks(x, tau, 5000), FS, settings=s)
    assert streamed.model.inertia == pytest.approx(whole.model.inertia, rel=0.01)
    assert streamed.model.breakaway == pytest.approx(whole.model.breakaway, rel=0.01)


def test_bad_chunks_are_refused_with_the_sample_index(run):
    x = run.position.copy()
    x[5003] = np.nan
    with pytest.raises(AnalysisError, match="position contains NaN or inf .first at sample 5003"):
        fit_lip_chunks(array_chunks(x, run.torque, 1000), FS)

    def uneven():
        yield run.position[:100], run.torque[:99]

    with pytest.raises(AnalysisError, match="lengths differ"):
        fit_lip_chunks(uneven, FS)


def test_streamed_identify_gives_the_figures_of_the_array_identify(run):
    # every figure of identify() on arrays, from chunk sources of 333 samples: the fit (same grid), the
    # equation error, the open-loop simulation (the plant run block by block from its own state: bit for bit)
    # and the segmented one (restart velocity from windows with a 40-time-constant margin). Validation on a
    # second run. All to 1e-9 relative (measured: 1e-13)
    from hilbench.analysis.identification.identify import RunArrays, identify, identify_chunks

    _, val = _dc_run(4, fs=FS, n=12_000)
    s = LipSettings(timing="hold_previous")
    whole = identify(RunArrays(np.arange(run.position.size) / FS, run.torque, run.position), settings=s,
                     validate=RunArrays(np.arange(val.position.size) / FS, val.torque, val.position),
                     segment=0.5)
    streamed = identify_chunks(array_chunks(run.position, run.torque, 333), FS, settings=s, segment=0.5,
                               validate=array_chunks(val.position, val.torque, 333))
    keys = [k for k in whole.figures if k.startswith(("train_", "validation_"))]
    assert len(keys) == 8
    for key in keys:
        assert streamed.figures[key] == pytest.approx(whole.figures[key], rel=1e-9), key
    assert streamed.model.inertia == pytest.approx(whole.model.inertia, rel=1e-9)


def test_streamed_simulations_match_the_array_ones_on_a_long_block_boundary(run):
    # blocks of 16384 samples and a 0.3 s segment (1200 samples, not a divisor of the block): the segmented
    # simulation's blocks are whole segments, so the figure is the array one's (to 1e-9; measured 1e-14)
    from hilbench.analysis.identification.output_error import (
        segmented_simulation_error,
        segmented_simulation_error_chunks,
        simulation_error,
        simulation_error_chunks,
    )

    model = fit_lip(run.position, run.torque, FS, settings=LipSettings(timing="hold_previous")).model
    src = array_chunks(run.position, run.torque, 5000)
    whole, _ = segmented_simulation_error(model, run.position, run.torque, FS, timing="hold_previous", segment=0.3)
    assert segmented_simulation_error_chunks(model, src, FS, timing="hold_previous",
                                             segment=0.3) == pytest.approx(whole, rel=1e-9)
    whole, _ = simulation_error(model, run.position, run.torque, FS, timing="hold_previous")
    assert simulation_error_chunks(model, src, FS, timing="hold_previous") == pytest.approx(whole, rel=1e-9)


def test_streamed_residual_autocorrelation_equals_the_whole_series():
    # n_eff of an AR(1) series (rho 0.9, mean 0.3) fed in blocks of 37, against effective_sample_count on the
    # whole series: equal to 1e-9 (the lagged sums are exact; the mean's terms use the first/last 200 values)
    from hilbench.analysis.identification.output_error import _Autocorrelation
    from hilbench.analysis.identification.regressors import effective_sample_count

    rng = np.random.default_rng(7)
    e = rng.standard_normal(5000)
    r = np.empty_like(e)
    r[0] = e[0]
    for i in range(1, r.size):
        r[i] = 0.9 * r[i - 1] + e[i]
    r += 0.3
    acc = _Autocorrelation()
    for i in range(0, r.size, 37):
        acc.add(r[i : i + 37])
    assert acc.n_eff() == pytest.approx(effective_sample_count(r), rel=1e-9)
    assert acc.n_eff() < 0.1 * r.size  # a strongly coloured series, so the check is not trivial


def test_streamed_output_error_refinement_recovers_a_perturbed_model():
    # as test_identification_methods' array refinement: one Jenkins element on noise-free data of the same
    # engine, from a start 5-12 % off; read in chunks of 250 samples. Parameters back within 1 % of the truth,
    # and within 3e-3 of the array refinement's optimum (measured: J 8e-5, b 9e-4, k 1e-4; both stop in the
    # same flat valley at NRMSE 7.9e-4, the restart-velocity floor); standard errors within 10 % of the array
    # version's (measured 1.5-3 %)
    from hilbench.analysis.identification.output_error import refine_output_error, refine_output_error_chunks
    from hilbench.analysis.models.friction_model import FrictionModel
    from tests.analysis.identification.test_identification_methods import _one_element_run

    _, r = _one_element_run()
    start = FrictionModel("rotary", 0.0021, [360.0], [1.1e-3], viscous=0.012)
    streamed, info = refine_output_error_chunks(start, array_chunks(r.position, r.torque, 250), r.fs)
    whole, _ = refine_output_error(start, r.position, r.torque, r.fs, max_nfev=60)
    assert info["position_nrmse_after"] < 0.1 * info["position_nrmse_before"]
    assert streamed.inertia == pytest.approx(0.002, rel=0.01)
    assert streamed.ms_stiffness[0] == pytest.approx(400.0, rel=0.01)
    assert streamed.ms_delta[0] == pytest.approx(1e-3, rel=0.01)
    assert streamed.viscous == pytest.approx(0.01, rel=0.01)
    for name in ("inertia", "viscous"):
        assert getattr(streamed, name) == pytest.approx(getattr(whole, name), rel=3e-3), name
        assert streamed.std_errors[name] == pytest.approx(whole.std_errors[name], rel=0.1), name
    np.testing.assert_allclose(streamed.ms_stiffness, whole.ms_stiffness, rtol=3e-3)


def test_streamed_identify_with_output_error_scores_the_refined_model():
    # method oe on chunk sources: the refined model's figures (its own equation error, not the NNLS fit's) and
    # the refinement's, against the streamed simulation of that model (the oracle of the test above)
    from hilbench.analysis.identification.identify import identify_chunks
    from hilbench.analysis.identification.maxwell_fit import predict_chunks
    from hilbench.analysis.identification.output_error import simulation_error_chunks
    from hilbench.common.metrics import nrmse
    from tests.analysis.identification.test_identification_methods import _one_element_run

    _, r = _one_element_run()
    src = array_chunks(r.position, r.torque, 400)
    res = identify_chunks(src, r.fs, method="oe", oe_max_iterations=5, settings=LipSettings(n_thresholds=16))
    assert res.method == "oe" and res.figures["passes"] > 0
    from hilbench.analysis.scoring import ScoreSettings, score_chunks

    # the figures are the one scoring function's of the refined model (analysis.scoring) ...
    scored = score_chunks(res.model.plant_params(), src, r.fs).figures
    for key in ("torque_nrmse", "position_nrmse", "position_nrmse_segmented"):
        assert res.figures[f"train_{key}"] == pytest.approx(scored[key], rel=1e-12), key
    # ... which along the raw path is the regression's prediction (predict_chunks) of that model, and simulates
    # as output_error does from the same start (the scorer's velocity is the whole run's low-passed one)
    meas, pred, _ = predict_chunks(res.model, src, r.fs, res.lip.cutoff, decimation=res.lip.decimation)
    raw = score_chunks(res.model.plant_params(), src, r.fs, settings=ScoreSettings(path_factor=None)).figures
    assert raw["torque_nrmse"] == pytest.approx(nrmse(meas, pred), rel=1e-12)
    assert raw["position_nrmse"] == pytest.approx(simulation_error_chunks(res.model, src, r.fs), rel=1e-2)
    # the refinement's own cost is not that figure: it simulates with twice the sub-steps (as the array
    # version, room for stiffer elements), and RK4 at 1 and 2 sub-steps differ here by 1e-3 of std(theta)
    assert res.figures["position_nrmse_after"] < 0.5 * res.figures["position_nrmse_before"]
    with pytest.raises(AnalysisError, match="method must be lip or oe"):
        identify_chunks(src, r.fs, method="paper")
