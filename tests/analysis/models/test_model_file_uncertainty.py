"""Per-family parameter uncertainties in the model file (schema hilbench.friction-model/2, docs/model-file.md):
written by ``family_document``, read back by ``read_family``, and checked against a Monte-Carlo over noise seeds.

The truth is a Coulomb+viscous plant with a load offset (C engine, noise-free motion); each seed adds white
position noise (0.1 mrad rms) to the measured path, the family is identified (linear start, output-error
refinement), its model file written and read back. Over 12 seeds the sample standard deviation of an estimate
has a relative uncertainty of about 1/sqrt(2*11) = 21 %, so the tolerance on (mean standard error) / (Monte-Carlo
standard deviation) is [0.6, 1.7] (about +-2.5 of those 21 %). Measured: F_c 0.95, b 0.92, c0 0.69. J's standard
error is not in the check: it is 0.44 of the Monte-Carlo spread (the segmented simulation restarts from a
noisy measured state, which the autocorrelation inflation does not capture; docs/model-file.md)."""

from __future__ import annotations

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.models.families import RunData, fit_family
from hilbench.analysis.models.model_file import SCHEMA, family_document, read_family, read_model, write_model
from hilbench.firmware_sim.engine.plant import PlantParams, simulate
from tests.analysis.identification.test_identification import random_enveloped

FS = 1000.0
N = 4000
SEEDS = range(12)
NOISE = 1e-4  # rad rms on the measured position
TRUTH = PlantParams(inertia=0.01, coulomb=0.3, viscous=0.05, torque_offset=-0.05)


@pytest.fixture(scope="module")
def read_back(tmp_path_factory):
    d = tmp_path_factory.mktemp("mc")
    u = random_enveloped(N, FS, 1, 2.0, period=2.0)
    theta = simulate(TRUTH, u, 1 / FS, substeps=4).theta
    models = []
    for s in SEEDS:
        x = theta + NOISE * np.random.default_rng(s).standard_normal(N)
        run = RunData.from_arrays(f"seed{s}", "rotary", FS, x, u, "hold_next")
        fit = fit_family("coulomb_viscous", run, timing="hold_next", position=x, torque=u)
        path = d / f"seed{s}.json"
        write_model(path, family_document(fit, method="compare", settings={}, figures={}, data={"seed": s}))
        models.append(read_family(path)[0])
    return d, models


@pytest.mark.parametrize("name, true", [("coulomb", 0.3), ("viscous", 0.05), ("offset", 0.05)])
def test_standard_errors_match_a_monte_carlo_over_noise_seeds(read_back, name, true):
    _, models = read_back
    est = np.array([m.parameters[name] for m in models])
    se = np.array([m.uncertainty(name) for m in models], float)
    assert np.all(se > 0)
    ratio = float(np.mean(se) / np.std(est, ddof=1))
    assert 0.6 <= ratio <= 1.7, f"{name}: mean standard error / Monte-Carlo std = {ratio:.2f}"
    assert abs(np.mean(est) - true) < 3 * np.std(est, ddof=1) / np.sqrt(len(est)) + 1e-4 * true  # unbiased


def test_the_family_file_reads_back_with_units_plant_and_schema(read_back):
    d, models = read_back
    m = models[0]
    assert m.family == "coulomb_viscous" and m.axis == "rotary"
    assert m.units["coulomb"] == "N*m" and m.units["viscous"] == "N*m*s/rad"
    assert m.plant.coulomb == pytest.approx(m.parameters["coulomb"])
    assert m.plant.torque_offset == pytest.approx(-m.parameters["offset"])
    assert (d / "seed0.json").read_text().count(SCHEMA) == 1
    with pytest.raises(AnalysisError, match="read_family"):
        read_model(d / "seed0.json")  # not a Maxwell-slip model
