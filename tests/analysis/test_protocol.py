"""The analysis protocol (hilbench.analysis.protocol): one registry that every consumer iterates, and one figure
for one model on one input whichever consumer computes it.

- A toy analysis registered with one line is a campaign step (``hilbench analyse --steps toy``), a section of the
  campaign page and an analysis of the GUI's run browser, and its figure is the closed form sum |dx|.
- Consistency: identify, compare and the residual loop through every consumer they have (the Python API, the CLI's
  JSON, the GUI's result, the campaign's Parquet row) on the same runs (whole, and cut 70/30 into a head and a
  held-out tail: the CLI reads the two parts written as run files) at 2, 10 and 20 kHz and on a host-clocked
  drive run (a ``sample_times`` channel: resampled by the one loader) report the same figure to 1e-6 relative;
  afrf, skeleton and presliding likewise at the same rates and host-clocked, whole only (they take no validation
  run, so no 70/30 split applies).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from hilbench.analysis import protocol
from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.entry import IdentifySettings
from hilbench.analysis.identification.maxwell_fit import LipSettings
from hilbench.analysis.record import load_record
from hilbench.bench.campaign_analysis.steps import STEPS, StepSettings
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign
from hilbench.bench.cli import main
from hilbench.bench.gui.analyses import run_analysis
from hilbench.common.runfile import RunWriter
from tests.analysis.consistency import (
    CLOCK_IDS,
    CLOCKS,
    FRACTION,
    RTOL,
    THRESHOLDS,
    campaign_row,
    clocked,
    one_run_campaign,
    page_cell,
)

pytestmark = pytest.mark.device_free



@pytest.fixture
def toy():
    protocol.register("toy", "tests.analysis.toy_analysis")  # the one line a new analysis needs
    yield protocol.entry("toy")
    protocol.ANALYSES.pop("toy")
    protocol._LOADED.pop("toy", None)


def test_a_registered_toy_is_a_campaign_step_a_page_section_and_a_gui_analysis(toy, tmp_path):
    folder = tmp_path / "c"
    write_campaign(folder, SyntheticCampaign(runs=1, duration=0.5, sample_rate=2000.0, seed=3))
    run = folder / json.loads((folder / "index.json").read_text())["runs"][0]["file"]
    x = load_record(run).position
    expected = float(np.sum(np.abs(np.diff(x))))  # the closed form of the toy's figure
    assert "toy" in STEPS
    assert main(["-q", "analyse", str(folder), "--steps", "identify,toy", "--serial", "-o", str(tmp_path / "r"),
                 "--thresholds", str(THRESHOLDS), "--quiet"]) == 0
    rows = {r["step"]: r for r in pq.read_table(tmp_path / "r" / "results.parquet").to_pylist()}
    assert rows["toy"]["status"] == "ok" and rows["toy"]["sliding_distance"] == pytest.approx(expected, rel=1e-12)
    from hilbench.bench.campaign_analysis.page import step_sections

    page = "".join(step_sections(list(rows.values()), {}))
    assert "id='step-toy'" in page and "id='step-identify'" in page
    shown = run_analysis("toy", run)
    assert shown.title == "Toy (distance slid)" and shown.summary["sliding_distance"] == pytest.approx(expected)
    files, summary = toy.report(toy.analyse(toy.read([run], protocol.ReadOptions())), tmp_path / "out")
    assert [f.name for f in files] == ["toy.json"] and summary["sliding_distance"] == pytest.approx(expected)
    with pytest.raises(AnalysisError, match="unknown analysis 'nothing'"):
        protocol.entry("nothing")


def test_a_validation_run_must_go_with_its_training_run(tmp_path):
    """The one check: each analysis names what a validation run shares with the training run."""
    folder = tmp_path / "c"
    write_campaign(folder, SyntheticCampaign(runs=2, duration=0.5, sample_rate=2000.0, seed=4))
    files = sorted(folder.glob("*.h5"))
    ident = protocol.entry("identify")
    train = ident.read([files[0]], protocol.ReadOptions())
    other = ident.read([files[1]], protocol.ReadOptions(timing="hold_next"))
    with pytest.raises(AnalysisError, match="torque timing hold_next") as err:
        ident.analyse(train, IdentifySettings(LipSettings(n_thresholds=THRESHOLDS)), other)
    assert "\n" not in str(err.value)
    with pytest.raises(AnalysisError, match="scores its models on a validation run"):
        protocol.entry("compare").analyse(train)
    assert ident.matches == ("axis", "kind", "timing") and protocol.entry("afrf").matches is None


def _write_part(record, rows: slice, path: Path) -> Path:
    """Samples ``rows`` of a record as a run file of their own (as the campaign steps cut it)."""
    t = record.t[rows] - record.t[rows][0]
    with RunWriter(path, sample_rate=record.sample_rate, channels=("t", "sample_index", "position", "torque"),
                   protocol_name="identification") as w:
        w.append({"t": t, "sample_index": np.arange(t.size), "position": record.position[rows],
                  "torque": record.torque[rows]})
    return path


def _host_clocked(folder: Path) -> Path:
    """The synthetic campaign's run rewritten as a host-clocked drive writes it: its samples taken at jittered
    host times (``sample_times``: ``host_time``), so the loader resamples it onto the uniform grid."""
    entry = json.loads((folder / "index.json").read_text())["runs"][0]
    src = load_record(folder / entry["file"])
    n, fs = src.n_samples, src.sample_rate
    jitter = np.random.default_rng(7).uniform(-0.2, 0.2, n) / fs
    path = folder / "drive.h5"
    with RunWriter(path, sample_rate=fs, channels=("t", "sample_index", "position", "torque", "host_time"),
                   protocol_name="identification",
                   device={"protocol": "CiA 402 over CANopen", "sample_times": "host_time"}) as w:
        w.append({"t": src.t, "sample_index": np.arange(n), "position": src.position, "torque": src.torque,
                  "host_time": 50.0 + src.t + jitter})
        uid = w.uid
    index = {"runs": [{**entry, "file": "drive.h5", "key": "drive", "uid": uid}]}  # the index names its run
    (folder / "index.json").write_text(json.dumps(index))
    (folder / entry["file"]).unlink()
    return path


CASES = [(2000.0, False), (10000.0, False), (20000.0, False), (2000.0, True)]


@pytest.mark.parametrize(("rate", "host_clocked"), CASES, ids=["2kHz", "10kHz", "20kHz", "host-clocked"])
def test_every_consumer_reports_the_same_figure(rate, host_clocked, tmp_path, capsys):
    folder = tmp_path / "c"
    write_campaign(folder, SyntheticCampaign(runs=1, duration=1.0, sample_rate=rate, seed=11))
    run = _host_clocked(folder) if host_clocked else \
        folder / json.loads((folder / "index.json").read_text())["runs"][0]["file"]
    rec = load_record(run)
    assert any(n.startswith("resampled on host_time") for n in rec.notes) == host_clocked
    ident = protocol.entry("identify")
    settings = IdentifySettings(LipSettings(n_thresholds=THRESHOLDS))

    # whole run: the Python API, the CLI's model file, the GUI's result (its model file and summary), the row
    api = ident.analyse(ident.read([run], protocol.ReadOptions()), settings)
    figure = api.value.figures["train_torque_nrmse"]
    assert main(["-q", "identify", str(run), "--thresholds", str(THRESHOLDS), "--json", str(tmp_path / "m.json")]) == 0
    cli = json.loads((tmp_path / "m.json").read_text())
    gui = run_analysis("identify", run)
    row = campaign_row(folder, tmp_path / "whole", "identify", 0.0)
    gui_thresholds = gui.model_document["settings"]["n_thresholds"]
    for where, value in (("cli", cli["figures"]["train_torque_nrmse"]), ("campaign", row["train_torque_nrmse"])):
        assert value == pytest.approx(figure, rel=RTOL), where
    assert row["inertia"] == pytest.approx(api.value.model.inertia, rel=RTOL)
    gui_api = ident.analyse(ident.read([run], protocol.ReadOptions()),
                            IdentifySettings(LipSettings(n_thresholds=gui_thresholds)))
    assert gui.summary["train_torque_nrmse"] == pytest.approx(gui_api.value.figures["train_torque_nrmse"], rel=RTOL)
    shown = {q: v for q, v, _u in gui.numbers}
    assert float(shown["train torque NRMSE"]) == pytest.approx(100 * gui.summary["train_torque_nrmse"], rel=5e-3)

    # 70/30: the head fitted, the tail held out from the state the head left (analysis.scoring): the API, the
    # CLI's --hold-out and the campaign row; the head and tail written as run files of their own are two other
    # runs (the tail's file starts relaxed), read alike by the CLI and the API
    head, tail = protocol.held_out(ident.read([run], protocol.ReadOptions()), FRACTION)
    cut = head.record.n_samples
    parts = [_write_part(rec, slice(0, cut), tmp_path / "head.h5"), _write_part(rec, slice(cut, None),
                                                                                tmp_path / "tail.h5")]
    split = ident.analyse(head, settings, tail).value.figures["validation_torque_nrmse"]
    assert main(["-q", "identify", str(run), "--hold-out", str(FRACTION), "--thresholds", str(THRESHOLDS),
                 "--json", str(tmp_path / "h.json")]) == 0
    assert json.loads((tmp_path / "h.json").read_text())["figures"]["validation_torque_nrmse"] == pytest.approx(
        split, rel=RTOL)
    split_row = campaign_row(folder, tmp_path / "split", "identify", FRACTION)
    assert split_row["validation_torque_nrmse"] == pytest.approx(split, rel=RTOL)
    value, text = page_cell(split_row, "validation_torque_nrmse")  # the campaign page's cell: % shown, exact kept
    assert value == pytest.approx(split, rel=RTOL) and float(text) == pytest.approx(100 * split, rel=5e-4)
    files = ident.analyse(ident.read([parts[0]], protocol.ReadOptions()), settings,
                          ident.read([parts[1]], protocol.ReadOptions())).value.figures["validation_torque_nrmse"]
    assert main(["-q", "identify", str(parts[0]), "--validate", str(parts[1]), "--thresholds", str(THRESHOLDS),
                 "--json", str(tmp_path / "s.json")]) == 0
    assert json.loads((tmp_path / "s.json").read_text())["figures"]["validation_torque_nrmse"] == pytest.approx(
        files, rel=RTOL)

    # compare: validation only, so the 70/30 split; the row is the family with the lowest validation NRMSE
    cmp = protocol.entry("compare")
    from hilbench.analysis.models.compare import CompareSettings

    families = ("coulomb_viscous", "maxwell_slip")
    summary = cmp.report(cmp.analyse(head, CompareSettings(families=families), tail))[1]
    assert main(["-q", "compare", str(run), "--hold-out", str(FRACTION), "--families", ",".join(families),
                 "-o", str(tmp_path / "cmp")]) == 0
    doc = {r["model"]: r for r in json.loads((tmp_path / "cmp" / "compare.json").read_text())["rows"]}
    for family in families:
        assert doc[family]["validation"]["torque_nrmse"] == pytest.approx(
            summary[f"{family}.validation_torque_nrmse"], rel=RTOL), family
    # the campaign's compare step fits its maxwell_slip row with the identify step's terms (32 thresholds here),
    # so that row reads the identify row's figure: the API with the step's settings gives the row
    from hilbench.bench.campaign_analysis.steps import step_settings

    stepped = cmp.report(cmp.analyse(head, step_settings("compare", StepSettings(
        thresholds=THRESHOLDS, compare_families=families)), tail))[1]
    row = campaign_row(folder, tmp_path / "cmp-row", "compare", FRACTION)
    assert row["model"] == stepped["model"]
    assert row["validation_torque_nrmse"] == pytest.approx(stepped["validation_torque_nrmse"], rel=RTOL)
    assert stepped["maxwell_slip.validation_torque_nrmse"] == pytest.approx(split, rel=RTOL)  # identify's figure
    capsys.readouterr()


@pytest.fixture(scope="module", params=CASES, ids=["2kHz", "10kHz", "20kHz", "host-clocked"])
def residual_run(request, tmp_path_factory):
    """One short run per rate (1.5 s: the loop's blocked cross-validation needs a few blocks), and the host-clocked
    drive's rewrite of the 2 kHz one, shared by the residual tests of that case."""
    rate, host_clocked = request.param
    folder = tmp_path_factory.mktemp("residual") / "c"
    write_campaign(folder, SyntheticCampaign(runs=1, duration=1.5, sample_rate=rate, seed=12))
    run = _host_clocked(folder) if host_clocked else \
        folder / json.loads((folder / "index.json").read_text())["runs"][0]["file"]
    assert any(n.startswith("resampled on host_time") for n in load_record(run).notes) == host_clocked
    return folder, run


def test_the_residual_loop_reports_one_figure_everywhere(residual_run, tmp_path, capsys):
    """The residual loop at 2, 10 and 20 kHz and on a host-clocked drive's run: on the whole run (blocked
    cross-validation) the Python API, the CLI's JSON, the GUI's result and the campaign row (no held-out tail); cut
    70/30, the API, the CLI's --hold-out, the campaign row and the page's cell, start and final model alike."""
    folder, run = residual_run
    res = protocol.entry("residual")
    inputs = res.read([run], protocol.ReadOptions())
    whole = res.report(res.analyse(inputs))[1]
    assert main(["-q", "residual", str(run), "--json", str(tmp_path / "r.json")]) == 0
    cli = json.loads((tmp_path / "r.json").read_text())
    row = campaign_row(folder, tmp_path / "whole", "residual", 0.0)
    for key, part in (("validation_torque_nrmse_start", "error_before"), ("validation_torque_nrmse", "error_after")):
        value = whole[key]
        assert cli[part]["validation"]["torque_nrmse"] == pytest.approx(value, rel=RTOL), key
        assert row[key] == pytest.approx(value, rel=RTOL), key
    assert run_analysis("residual", run).summary["validation_torque_nrmse"] == pytest.approx(
        whole["validation_torque_nrmse"], rel=RTOL)
    head, tail = protocol.held_out(inputs, FRACTION)
    split = res.report(res.analyse(head, None, tail))[1]
    assert main(["-q", "residual", str(run), "--hold-out", str(FRACTION), "--json", str(tmp_path / "s.json")]) == 0
    cli = json.loads((tmp_path / "s.json").read_text())
    row = campaign_row(folder, tmp_path / "row", "residual", FRACTION)
    for key, part in (("validation_torque_nrmse_start", "error_before"), ("validation_torque_nrmse", "error_after")):
        value = split[key]
        assert cli[part]["validation"]["torque_nrmse"] == pytest.approx(value, rel=RTOL), key
        assert row[key] == pytest.approx(value, rel=RTOL), key
        assert page_cell(row, key)[0] == pytest.approx(value, rel=RTOL), key
    capsys.readouterr()


def _afrf_run(path: Path, fs: float, host: bool) -> None:
    """A stepped sine (1 and 3 Hz, 0.5 and 2 N m, 4 settle periods) on m x'' + c x' + k x = T (1, 10, 50) at
    ``fs``, written as a device-clocked device or a host-clocked drive writes it."""
    from hilbench.bench.acquisition.excitations import stepped_sine
    from hilbench.firmware_sim.engine.plant import PlantParams, simulate

    exc = stepped_sine(fs, frequencies=[1.0, 3.0], amplitudes=[0.5, 2.0], settle_periods=4, measure_periods=4)
    out = simulate(PlantParams(inertia=1.0, spring=50.0, viscous=10.0), exc.u, 1.0 / fs)
    k = np.arange(exc.u.size)
    channels, data, kw = clocked(("sample_index", "t", "current_cmd", "current", "torque", "position", "counts"),
                                 {"sample_index": k, "t": k / fs, "current_cmd": exc.u, "current": exc.u,
                                  "torque": out.torque, "position": out.theta, "counts": np.zeros(k.size, np.int64)},
                                 fs, host)
    with RunWriter(path, sample_rate=fs, channels=channels, protocol_name="stepped_sine",
                   protocol_params=exc.protocol(), protocol_arrays={"step_windows": exc.windows}, **kw) as w:
        w.append(data)


@pytest.mark.parametrize(("rate", "host_clocked"), CLOCKS, ids=CLOCK_IDS)
def test_the_afrf_reports_one_figure_everywhere(rate, host_clocked, tmp_path, capsys):
    """A stepped-sine run of a linear system at 2, 10 and 20 kHz and as a host-clocked drive records it: the
    first-harmonic compliance of the lowest amplitude (the campaign row's column) from the Python API, the CLI's
    JSON, the GUI's result and the Parquet row, to 1e-6; whole, and read one step window at a time under a small
    budget (the same bit for bit; a host-clocked run is read whole, resampled). No 70/30 split: the AFRF takes
    no validation run (it fits no model to score)."""
    folder = tmp_path / "c"
    folder.mkdir()
    run = folder / "afrf.h5"
    _afrf_run(run, rate, host_clocked)
    assert any(n.startswith("resampled on host_time") for n in load_record(run).notes) == host_clocked
    one_run_campaign(folder, "afrf.h5", "stepped_sine")
    afrf = protocol.entry("afrf")
    summary = afrf.report(afrf.analyse(afrf.read([run], protocol.ReadOptions())))[1]
    compliance = summary["afrf_compliance_low_amplitude"]
    # the closed form: |X1/T1| of m x'' + c x' + k x = T at the lowest frequency, within the sampling's 1e-3
    w = 2 * np.pi * 1.0
    assert compliance == pytest.approx(1 / abs(50.0 - w * w + 10j * w), rel=1e-3)
    assert main(["-q", "afrf", str(run), "--json", str(tmp_path / "a.json")]) == 0
    doc = json.loads((tmp_path / "a.json").read_text())
    i, j = int(np.argmin(doc["amplitudes"])), int(np.argmin(doc["frequencies"]))
    assert doc["magnitude"][i][j][0] / doc["drive_magnitude"][i][j] == pytest.approx(compliance, rel=RTOL)
    assert run_analysis("afrf", run).summary["afrf_compliance_low_amplitude"] == pytest.approx(compliance, rel=RTOL)
    row = campaign_row(folder, tmp_path / "row", "afrf", 0.0)
    assert row["afrf_compliance_low_amplitude"] == pytest.approx(compliance, rel=RTOL)
    from hilbench.analysis.afrf import array_cost

    # a host-clocked run is resampled onto the grid in one read, so it is read whole under any budget
    streamed = afrf.read([run], protocol.ReadOptions(memory=array_cost(load_record(run).n_samples) - 1))
    assert streamed.streamed != host_clocked
    assert afrf.report(afrf.analyse(streamed))[1]["afrf_compliance_low_amplitude"] == pytest.approx(compliance,
                                                                                                   rel=RTOL)
    capsys.readouterr()


def _chirp_run(path: Path, fs: float, host: bool) -> None:
    """G sin(pi a t^2) (G = 5 N, a = 0.05 Hz/s, 20 s) on the paper's system at ``fs``, the torque logged as a
    device logs it (hold_previous), written as a device-clocked device or a host-clocked drive writes it."""
    from hilbench.firmware_sim.engine.friction_models import paper_system
    from hilbench.firmware_sim.engine.plant import simulate

    params, g, a, duration = paper_system(), 5.0, 0.05, 20.0
    t = np.arange(int(duration * fs)) / fs
    out = simulate(params, g * np.sin(np.pi * a * t**2), 1 / fs, substeps=4)
    torque = np.insert(g * np.sin(np.pi * a * t[:-1] ** 2), 0, 0.0)
    channels, data, kw = clocked(("sample_index", "t", "torque", "position"),
                                 {"sample_index": np.arange(t.size), "t": t, "torque": torque, "position": out.theta},
                                 fs, host)
    with RunWriter(path, sample_rate=fs, channels=channels, calibration={"inertia": params.inertia},
                   protocol_name="chirp", protocol_params={"gain": g, "rate": a, "duration": duration}, **kw) as w:
        w.append(data)


@pytest.mark.parametrize(("rate", "host_clocked"), CLOCKS, ids=CLOCK_IDS)
def test_the_skeleton_reports_one_figure_everywhere(rate, host_clocked, tmp_path, capsys):
    """A chirp run of the paper's system at 2, 10 and 20 kHz and as a host-clocked drive records it: the composed
    amplitude range of the skeleton (the campaign row's columns) from the Python API, the CLI's JSON, the GUI's
    result, the Parquet row and the page's cell, to 1e-6; the mass is the run's declared inertia everywhere (no
    option). No 70/30 split: the skeleton takes no validation run (ForceVib reads one run's own cycles)."""
    folder = tmp_path / "c"
    folder.mkdir()
    run = folder / "chirp.h5"
    _chirp_run(run, rate, host_clocked)
    assert any(n.startswith("resampled on host_time") for n in load_record(run).notes) == host_clocked
    one_run_campaign(folder, "chirp.h5", "chirp")
    sk = protocol.entry("skeleton")
    summary = sk.report(sk.analyse(sk.read([run], protocol.ReadOptions())))[1]
    low, high = summary["skeleton_amplitude_min"], summary["skeleton_amplitude_max"]
    assert main(["-q", "skeleton", str(run), "--json", str(tmp_path / "s.json")]) == 0
    doc = json.loads((tmp_path / "s.json").read_text())
    assert (min(doc["amplitude"]), max(doc["amplitude"])) == (pytest.approx(low, rel=RTOL), pytest.approx(high,
                                                                                                        rel=RTOL))
    shown = run_analysis("skeleton", run)
    assert shown.summary["skeleton_amplitude_max"] == pytest.approx(high, rel=RTOL)
    row = campaign_row(folder, tmp_path / "row", "skeleton", 0.0)
    for column, value in (("skeleton_amplitude_min", low), ("skeleton_amplitude_max", high)):
        assert row[column] == pytest.approx(value, rel=RTOL), column
        assert page_cell(row, column)[0] == pytest.approx(value, rel=RTOL), column
    assert row["skeleton_stiffness_low_amplitude"] == pytest.approx(summary["skeleton_stiffness_low_amplitude"],
                                                                    rel=RTOL)
    capsys.readouterr()


def _presliding_run(path: Path, fs: float, host: bool) -> None:
    """A displacement-driven record of the DC motor's Maxwell-slip elements on a nested path (the same strokes in
    the same time at any ``fs``), read by an encoder of 2^16 counts/rev (the run's calibration), force noise 2 mN m;
    written as a device-clocked device or (``host``) a host-clocked drive writes it."""
    from hilbench.firmware_sim.engine.friction_models import DC_MOTOR_D
    from tests.analysis.presliding.records import dc_elements, maxwell_force, smooth_path

    cpr = 2**16
    x = smooth_path(DC_MOTOR_D, int(fs / 10))
    force = maxwell_force(x, *dc_elements()) + 2e-3 * np.random.default_rng(5).standard_normal(x.size)
    k = np.arange(x.size)
    counts = np.round(x * cpr / (2 * np.pi)) * (2 * np.pi / cpr)
    channels, data, kw = clocked(("sample_index", "t", "position", "torque"),
                                 {"sample_index": k, "t": k / fs, "position": counts, "torque": force}, fs, host)
    with RunWriter(path, sample_rate=fs, channels=channels, record="displacement-driven",
                   calibration={"counts_per_rev": cpr}, protocol_name="presliding", protocol_params={"inertia": 0.0},
                   **kw) as w:
        w.append(data)


@pytest.mark.parametrize(("rate", "host_clocked"), CLOCKS, ids=CLOCK_IDS)
def test_presliding_reports_one_figure_everywhere(rate, host_clocked, tmp_path, capsys):
    """A quantised displacement-driven record (``_presliding_run``) at 2, 10 and 20 kHz and as a host-clocked drive
    records it: the break-away force and initial stiffness from the Python API, the CLI's presliding.json, the
    GUI's result, the Parquet row and the page's cell, to 1e-6. The host-clocked record (resampled: a spline through
    the counts) takes its position step from the calibration, so its figures are the device-clocked record's within
    2 % (measured 0.5 % and 0.9 %; with the step of the resampled samples, 1e-6 counts, they were 32 % and 500 %
    off). No 70/30 split: presliding takes no validation run (its figures are read off one path)."""
    folder = tmp_path / "c"
    folder.mkdir()
    run = folder / "p.h5"
    _presliding_run(run, rate, host_clocked)
    assert any(n.startswith("resampled on host_time") for n in load_record(run).notes) == host_clocked
    one_run_campaign(folder, "p.h5", "presliding", key="p")
    ps = protocol.entry("presliding")
    summary = ps.report(ps.analyse(ps.read([run], protocol.ReadOptions())))[1]
    assert main(["-q", "presliding", str(run), "-o", str(tmp_path / "out")]) == 0
    doc = json.loads((tmp_path / "out" / "presliding.json").read_text())
    shown = run_analysis("presliding", run)
    row = campaign_row(folder, tmp_path / "row", "presliding", 0.0)
    for column, quantity in (("presliding_breakaway", "breakaway"), ("initial_stiffness", "initial_stiffness")):
        value = summary[column]
        assert doc["quantities"][quantity]["value"] == pytest.approx(value, rel=RTOL), column
        assert shown.summary[column] == pytest.approx(value, rel=RTOL), column
        assert row[column] == pytest.approx(value, rel=RTOL), column
        assert page_cell(row, column)[0] == pytest.approx(value, rel=RTOL), column
    if host_clocked:
        _presliding_run(tmp_path / "device.h5", rate, False)
        device = ps.report(ps.analyse(ps.read([tmp_path / "device.h5"], protocol.ReadOptions())))[1]
        for column in ("presliding_breakaway", "initial_stiffness"):
            assert summary[column] == pytest.approx(device[column], rel=0.02), column
    capsys.readouterr()


def test_the_gui_goes_through_the_entries_refusals_and_fallbacks(tmp_path):
    """The run browser once refused a skeleton without J where `hilbench skeleton` takes the run's declared inertia,
    and skipped presliding's check of the force channel; through the entries it does what the command does."""
    from hilbench.firmware_sim.engine.friction_models import paper_system
    from tests.analysis.skeleton.test_skeleton_stream import _write_chirp

    path = tmp_path / "chirp.h5"
    _write_chirp(path, paper_system(), 5.0, duration=20.0)
    shown = run_analysis("skeleton", path, {})  # no J typed: the run's calibration inertia, as the CLI
    assert main(["-q", "skeleton", str(path), "--json", str(tmp_path / "s.json")]) == 0
    doc = json.loads((tmp_path / "s.json").read_text())
    assert shown.summary["mass"] == doc["mass"] == paper_system().inertia
    assert shown.summary["skeleton_amplitude_max"] == pytest.approx(max(doc["amplitude"]), rel=RTOL)
    with pytest.raises(AnalysisError, match="a torque-driven record; presliding needs a displacement-driven one"):
        run_analysis("presliding", path)
