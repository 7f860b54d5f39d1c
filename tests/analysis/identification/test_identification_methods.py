"""Output-error refinement, the paper's baseline, the model file and the plots."""

import json

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.identify import RunArrays, identify
from hilbench.analysis.identification.output_error import refine_output_error, simulation_error
from hilbench.analysis.identification.paper_baseline import fit_paper
from hilbench.analysis.models.friction_model import FrictionModel
from hilbench.analysis.models.model_file import model_document, read_family, read_model, write_model
from hilbench.firmware_sim.engine.plant import PlantParams, simulate
from tests.analysis.identification.test_identification import random_enveloped


def _one_element_run(n=3000, fs=1000.0, seed=0):
    # one Jenkins element (k 400, Delta 1e-3) on J = 0.002 with b = 0.01
    p = PlantParams(inertia=0.002, ms_stiffness=(400.0,), ms_slip=(0.4,), viscous=0.01)
    u = random_enveloped(n, fs, seed, 1.0, period=1.0)
    out = simulate(p, u, 1 / fs)
    return p, RunArrays(np.arange(n) / fs, u, out.theta)


def test_output_error_refinement_recovers_a_perturbed_model():
    p, run = _one_element_run()
    truth = FrictionModel("rotary", 0.002, [400.0], [1e-3], viscous=0.01)
    start = FrictionModel("rotary", 0.0021, [360.0], [1.1e-3], viscous=0.012)
    refined, info = refine_output_error(start, run.position, run.torque, run.fs, max_nfev=60)
    assert info["position_nrmse_after"] < 0.1 * info["position_nrmse_before"]
    # noise-free data of the same engine: parameters back within 1 %
    assert refined.inertia == pytest.approx(truth.inertia, rel=0.01)
    assert refined.ms_stiffness[0] == pytest.approx(400.0, rel=0.01)
    assert refined.ms_delta[0] == pytest.approx(1e-3, rel=0.01)
    assert np.isfinite(refined.std_errors["inertia"])


def test_paper_baseline_finds_a_single_element():
    _, run = _one_element_run(n=1500)
    model, info = fit_paper(
        run.position, run.torque, run.fs, n_elements=1, maxiter=60, popsize=12, nm_maxfev=2000, seed=1
    )
    assert info["nm_cost"] <= info["de_cost"]
    # small budget: a 5 % tolerance on J and on the slip force W = k*Delta (0.4 N*m)
    assert model.inertia == pytest.approx(0.002, rel=0.05)
    assert model.ms_slip[0] == pytest.approx(0.4, rel=0.05)
    nrmse, _ = simulation_error(model, run.position, run.torque, run.fs)
    assert nrmse < 0.05


def test_model_file_round_trip_and_plots(tmp_path):
    _, run = _one_element_run(n=4000)
    _, val = _one_element_run(n=4000, seed=1)
    res = identify(run, validate=val)
    doc = model_document(
        res.model,
        method=res.method,
        settings=res.settings,
        figures=res.figures,
        data={"train": "synthetic", "validation": "synthetic seed 1"},
    )
    path = tmp_path / "model.json"
    write_model(path, doc)
    raw = json.loads(path.read_text())
    assert raw["schema"] == "hilbench.friction-model/2" and raw["family"] == "maxwell_slip"
    for key in (
        "train_torque_nrmse",
        "train_position_nrmse",
        "validation_torque_nrmse",
        "validation_position_nrmse",
    ):
        assert 0 <= raw["figures"][key] < 1
    model, _ = read_model(path)
    np.testing.assert_allclose(model.ms_stiffness, res.model.ms_stiffness)
    assert model.inertia == res.model.inertia
    assert raw["parameters"]["units"]["inertia"] == "kg*m^2"
    fam, _ = read_family(path)  # the reader of every family reads identify's file too, uncertainties included
    assert fam.family == "maxwell_slip" and fam.parameters["inertia"] == res.model.inertia
    assert fam.uncertainty("inertia") == pytest.approx(res.model.std_errors["inertia"])
    assert fam.plant.inertia == pytest.approx(res.model.inertia)
    v1 = tmp_path / "v1.json"  # a version-1 file (before the family key) is still read
    v1.write_text(json.dumps({k: v for k, v in raw.items() if k != "family"} | {"schema": "hilbench.friction-model/1"}))
    np.testing.assert_allclose(read_model(v1)[0].ms_stiffness, res.model.ms_stiffness)

    from hilbench.analysis.identification.plots import write_plots

    files = write_plots(res, tmp_path / "plots")
    assert {f.name for f in files} == {
        "virgin_curve.png",
        "train_fit.png",
        "train_residuals.png",
        "validation_fit.png",
        "validation_residuals.png",
        "train_hysteresis.png",
        "validation_hysteresis.png",
    }
    assert all(f.stat().st_size > 1000 for f in files)


def test_read_model_rejects_other_json(tmp_path):
    path = tmp_path / "x.json"
    path.write_text('{"schema": "other"}')
    with pytest.raises(AnalysisError, match="not a hilbench friction model"):
        read_model(path)
