"""The steps of ``hilbench analyse``: identify, compare and residual are each checked against their own command
(``hilbench identify``, ``compare``, ``residual``) run on the head the step fits, written as a run file, and against
the front door the command calls on the head and the held-out tail cut as the step cuts them (the tail is scored
from the friction state the head left, analysis.scoring: a tail written as a run file of its own starts relaxed
and reads another figure); and against the plant: the C plant's friction is a Maxwell-slip model, so that family
must score best and the residual loop must find nothing missing."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from hilbench.bench.campaign_analysis.engine import analyse
from hilbench.bench.campaign_analysis.steps import StepSettings, steps_for
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, simulate_runs, write_campaign
from hilbench.bench.cli import main
from hilbench.common.runfile import RunWriter

pytestmark = pytest.mark.device_free

quiet = {"progress": False, "say": lambda _line: None}
SETTINGS = StepSettings(compare_families=("coulomb_viscous", "maxwell_slip"))


def _head_and_tail(spec: SyntheticCampaign, folder: Path, fraction: float) -> tuple[Path, Path]:
    """The first run of ``spec`` cut as the steps cut it (round(n*(1-fraction))), as two run files."""
    run = next(iter(simulate_runs(spec)))
    n = run.channels["t"].size
    cut = int(round(n * (1 - fraction)))
    paths = []
    for name, rows in (("head", slice(0, cut)), ("tail", slice(cut, n))):
        channels = {k: np.asarray(v)[rows] for k, v in run.channels.items()}
        m = channels["t"].size
        channels["sample_index"], channels["t"] = np.arange(m), np.arange(m) / spec.sample_rate
        path = folder / f"{name}.h5"
        with RunWriter(path, sample_rate=spec.sample_rate, channels=list(channels), protocol_name="identification",
                       protocol_params=run.params, device={"model": "synthetic", "serial": "C-plant"}) as w:
            w.append(channels)
        paths.append(path)
    return paths[0], paths[1]


def _split(spec: SyntheticCampaign, folder: Path, fraction: float):
    """The first run of ``spec`` as one run file, loaded and cut as the steps cut it (analysis.record_split)."""
    from hilbench.analysis.record import load_record
    from hilbench.analysis.record_split import split

    run = next(iter(simulate_runs(spec)))
    path = folder / "whole.h5"
    with RunWriter(path, sample_rate=spec.sample_rate, channels=list(run.channels), protocol_name="identification",
                   protocol_params=run.params, device={"model": "synthetic", "serial": "C-plant"}) as w:
        w.append(dict(run.channels))
    return split(load_record(path), fraction)


def _one_row(spec: SyntheticCampaign, tmp_path: Path, step: str) -> dict:
    folder = tmp_path / "c"
    write_campaign(folder, spec)
    s = analyse([folder], tmp_path / "r", (step,), SETTINGS, serial=True, **quiet)
    rows = pq.read_table(s.table).to_pylist()
    assert len(rows) == spec.runs and all(r["step"] == step for r in rows)
    return rows[0]


def test_each_step_runs_on_the_protocols_that_support_it():
    wanted = ("identify", "compare", "residual", "presliding")
    assert steps_for("identification", wanted) == list(wanted[:3])
    assert steps_for("chirp", wanted) == list(wanted[:3])
    assert steps_for("stepped_sine", wanted) == [] and steps_for("presliding", wanted) == ["presliding"]


def test_identify_step_is_hilbench_identify_on_the_head_and_tail(tmp_path):
    spec = SyntheticCampaign(runs=1, duration=1.5, seed=31)
    row = _one_row(spec, tmp_path, "identify")
    assert row["status"] == "ok", row["error"]
    head, tail = _head_and_tail(spec, tmp_path, SETTINGS.validation_fraction)
    assert main(["-q", "identify", str(head), "--validate", str(tail), "--thresholds", str(SETTINGS.thresholds),
                 "--json", str(tmp_path / "m.json")]) == 0
    doc = json.loads((tmp_path / "m.json").read_text())
    for name in ("inertia", "viscous"):
        assert row[name] == pytest.approx(doc["parameters"][name], rel=1e-9), name
    assert row["train_torque_nrmse"] == pytest.approx(doc["figures"]["train_torque_nrmse"], rel=1e-9)
    from hilbench.analysis.identification import analyse as identify
    from hilbench.analysis.identification.maxwell_fit import LipSettings

    h, t = _split(spec, tmp_path, SETTINGS.validation_fraction)
    api = identify(h, LipSettings(n_thresholds=SETTINGS.thresholds), validation=t).figures
    for name in ("train_torque_nrmse", "validation_torque_nrmse", "validation_position_nrmse_segmented"):
        assert row[name] == pytest.approx(api[name], rel=1e-9), name
    # the plant's friction is Maxwell-slip and the model is fitted on 70 % of the run: the tail reads a few %
    assert row["validation_torque_nrmse"] < 0.1


def test_compare_step_is_hilbench_compare_on_the_head_and_tail(tmp_path):
    spec = SyntheticCampaign(runs=1, duration=1.5, seed=31)
    row = _one_row(spec, tmp_path, "compare")
    assert row["status"] == "ok", row["error"]
    head, tail = _head_and_tail(spec, tmp_path, SETTINGS.validation_fraction)
    assert main(["-q", "compare", str(head), "--validate", str(tail), "--families", "coulomb_viscous,maxwell_slip",
                 "-o", str(tmp_path / "cmp")]) == 0
    doc = {r["model"]: r for r in json.loads((tmp_path / "cmp" / "compare.json").read_text())["rows"]}
    # the plant's friction is Maxwell-slip: that family wins, by far, over Coulomb + viscous
    assert row["model"] == "maxwell_slip"
    assert doc["maxwell_slip"]["validation"]["torque_nrmse"] < 0.5 * doc["coulomb_viscous"]["validation"][
        "torque_nrmse"]
    # the step's row is compare's front door on the head and the tail, its maxwell_slip row fitting the identify
    # step's terms (32 thresholds): the figures agree to rounding
    from hilbench.analysis.identification.maxwell_fit import LipSettings
    from hilbench.analysis.models.compare import CompareSettings
    from hilbench.analysis.models.compare import analyse as compare

    h, t = _split(spec, tmp_path, SETTINGS.validation_fraction)
    best = {r.name: r for r in compare(h, t, CompareSettings(families=SETTINGS.compare_families, lip=LipSettings(
        n_thresholds=SETTINGS.thresholds))).rows}["maxwell_slip"]
    assert row["validation_torque_nrmse"] == pytest.approx(best.validation["torque_nrmse"], rel=1e-9)
    assert row["train_torque_nrmse"] == pytest.approx(best.train["torque_nrmse"], rel=1e-9)
    assert row["validation_position_nrmse_segmented"] == pytest.approx(
        best.validation["position_nrmse_segmented"], rel=1e-9)


def test_residual_step_is_hilbench_residual_on_the_head_and_tail(tmp_path):
    spec = SyntheticCampaign(runs=1, duration=8.0, seed=5)  # the loop needs more moving rows than 1.5 s give
    row = _one_row(spec, tmp_path, "residual")
    assert row["status"] == "ok", row["error"]
    head, tail = _head_and_tail(spec, tmp_path, SETTINGS.validation_fraction)
    out = tmp_path / "residual.json"
    assert main(["-q", "residual", str(head), "--validate", str(tail), "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert row["verdict"] == doc["verdict"]
    from hilbench.analysis.residual import ResidualSettings
    from hilbench.analysis.residual import analyse as residual

    h, t = _split(spec, tmp_path, SETTINGS.validation_fraction)
    loop = residual(h, ResidualSettings(start=SETTINGS.residual_start), validation=[t]).loop
    assert row["validation_torque_nrmse"] == pytest.approx(loop.error_after["validation"]["torque_nrmse"], rel=1e-9)
    assert row["validation_torque_nrmse_start"] == pytest.approx(loop.error_before["validation"]["torque_nrmse"],
                                                                 rel=1e-9)
    # the plant is the dc_motor preset (inertia, 16 Maxwell-slip elements, viscous 0.004 N*m*s/rad, current
    # noise): the loop adds the viscous term the start lacks, and nothing else; the model fits to a few %
    assert row["model"] == "inertia,maxwell_slip,viscous" and row["validation_torque_nrmse"] < 0.05


def test_a_run_too_short_for_the_residual_loop_is_a_failed_row_with_the_reason(tmp_path):
    row = _one_row(SyntheticCampaign(runs=1, duration=1.5, seed=5), tmp_path, "residual")
    assert row["status"] == "failed" and "too few moving rows" in row["error"]


def test_presliding_step_is_hilbench_presliding_and_meets_the_truth(tmp_path):
    """A displacement-driven linear record (40 Maxwell-slip elements of tests/truth: break-away 40 N, largest
    element 0.1 mm; nested reversals, 20 mN noise), as tests/bench/test_presliding_command.py builds it, put in a
    campaign as a presliding run."""
    from tests.analysis.presliding.records import maxwell_force, smooth_path
    from tests.truth.generator import elements

    breakaway, largest = 40.0, 0.1e-3
    k, w = elements(breakaway, largest, 40)
    x = smooth_path(largest / 4, 40)
    f = maxwell_force(x, k, w) + 0.02 * np.random.default_rng(3).standard_normal(x.size)
    csv, folder = tmp_path / "tribo.csv", tmp_path / "c"
    np.savetxt(csv, np.column_stack([np.arange(x.size) * 1e-3, x * 1e6, f * 1e3]), delimiter=",",
               header="t,displacement,force", comments="", fmt="%.12g")
    folder.mkdir()
    assert main(["-q", "import", "csv", str(csv), "--linear", "--record", "displacement-driven", "--unit", "t=s",
                 "--unit", "displacement=um", "--unit", "force=mN", "-o", str(folder / "p1.h5")]) == 0
    (folder / "index.json").write_text(json.dumps({"runs": [
        {"key": "p1", "name": "p", "repeat": 1, "protocol": "presliding", "file": "p1.h5", "status": "completed"}]}))
    s = analyse([folder], tmp_path / "r", ("identify", "presliding"), replace(SETTINGS, presliding_replicates=6),
                serial=True, **quiet)
    rows = pq.read_table(s.table).to_pylist()
    assert [r["step"] for r in rows] == ["presliding"]  # identify does not apply to a presliding run
    row = rows[0]
    assert row["status"] == "ok", row["error"]
    assert main(["-q", "presliding", str(folder / "p1.h5"), "-o", str(tmp_path / "cmd"), "--replicates", "6"]) == 0
    doc = json.loads((tmp_path / "cmd" / "presliding.json").read_text())
    for name, column in (("breakaway", "presliding_breakaway"), ("initial_stiffness", "initial_stiffness"),
                         ("presliding_distance", "presliding_distance")):
        assert row[column] == pytest.approx(doc["quantities"][name]["value"], rel=1e-9)
        assert row[f"{column}_se"] == pytest.approx(doc["quantities"][name]["std_uncertainty"], rel=1e-9)
    assert row["validation_force_relative_error"] == pytest.approx(doc["validation"]["force_rms_error_relative"],
                                                                   rel=1e-9)
    # the truth: break-away 40 N to 2 %; its virgin curve 40*(1 - (1 - x/P)^2) reaches 90 % at P*(1 - sqrt(0.1))
    assert row["presliding_breakaway"] == pytest.approx(breakaway, rel=0.02)
    assert row["presliding_distance"] == pytest.approx(largest * (1 - np.sqrt(0.1)), rel=0.05)
    assert row["validation_force_relative_error"] < 0.01
