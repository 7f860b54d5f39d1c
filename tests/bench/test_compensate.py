"""hilbench compensate: refusals before anything moves, clipping counts, the predicted matrix report."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from hilbench.bench import cli
from hilbench.common.runfile import RunWriter
from hilbench.firmware_sim.engine.friction_models import dc_motor
from tests.figure_checks import recording_figures

SHORT = ["--sample-rate", "1000", "--amplitudes", "1e-3", "1e-2", "--cycles", "1", "--rest", "0.1",
         "--amplitude", "0.01", "--frequency", "1", "--targets", "0.01", "0", "--move-time", "0.2"]


def _model(tmp_path, axis="rotary", train_file=None, **units):
    p = dc_motor(8)
    k = np.asarray(p.ms_stiffness)
    doc = {"schema": "hilbench.friction-model/1", "data": {"train": {"file": str(train_file or "")}},
           "parameters": {"axis": axis, "units": {"inertia": "kg*m^2", "ms_stiffness": "N*m/rad", **units},
                          "inertia": p.inertia, "ms_stiffness": k.tolist(),
                          "ms_delta": (np.asarray(p.ms_slip) / k).tolist(), "viscous": p.viscous, "coulomb": 0.0,
                          "offset": 0.0, "spring": 0.0, "std_errors": {}}}
    path = tmp_path / f"model-{axis}.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.fixture
def no_device(monkeypatch):
    """Fails the test if anything opens a device (so nothing can have been streamed)."""
    opened = []

    def refuse(*args, **kwargs):
        opened.append(args)
        raise AssertionError("a device was opened")

    monkeypatch.setattr("hilbench.bench.acquisition.runner.Bench.open", refuse)
    return opened


def _refused(capsys, argv) -> str:
    code = cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, (code, err)
    return err[0]


def test_a_linear_model_is_refused_before_anything_moves(tmp_path, capsys, no_device):
    line = _refused(capsys, ["compensate", str(_model(tmp_path, axis="linear")), "-o", str(tmp_path / "r.h5")])
    assert "linear axis" in line and "rotary" in line
    assert not no_device and not (tmp_path / "r.h5").exists()


def test_a_model_in_other_units_is_refused(tmp_path, capsys, no_device):
    line = _refused(capsys, ["compensate", str(_model(tmp_path, ms_delta="m")), "--matrix", "-o",
                             str(tmp_path / "out")])
    assert "ms_delta is in m, not rad" in line and not no_device


def test_a_model_identified_under_another_calibration_is_refused(tmp_path, capsys, no_device):
    run = tmp_path / "train.h5"
    with RunWriter(run, sample_rate=1000.0, calibration={"torque_constant": 0.2, "counts_per_rev": 1 << 20,
                                                          "ratio": 1.0}) as w:
        w.finish("completed")
    model = _model(tmp_path, train_file=run)
    line = _refused(capsys, ["compensate", str(model), "--torque-constant", "0.1", "-o", str(tmp_path / "r.h5")])
    assert "torque_constant 0.2 N*m/A" in line and "0.1 N*m/A" in line and not no_device
    line = _refused(capsys, ["compensate", str(model), "--ratio", "3", "-o", str(tmp_path / "r.h5")])
    assert "ratio" in line and not no_device


@pytest.mark.parametrize("extra, match", [
    (["--feedforward", "lugre"], "offers feed-forward none, coulomb, maxwell_slip; not lugre"),
    (["--reference", "triangle", "--corner", "5"], "corner"),
    (["--window", "0"], "--window"),
    (["--matrix"], "needs -o/--output"),
])
def test_bad_options_are_one_line(tmp_path, capsys, no_device, extra, match):
    assert match in _refused(capsys, ["compensate", str(_model(tmp_path)), *extra])
    assert not no_device


SINGLE = ["--sample-rate", "1000", "--amplitudes", "1e-3", "1e-2", "--frequency", "1", "--cycles", "1", "--rest",
          "0.1", "--current-limit", "10"]


def test_a_single_run_is_compared_with_its_baseline_on_the_device(tmp_path, capsys):
    """One `compensate` run also plays the reference without feed-forward beside it and writes a figure and a
    summary; the summary's figures are recomputed here from the two run files (reference - position)."""
    from hilbench.analysis.record import load_record

    model = _model(tmp_path)
    run = tmp_path / "run.h5"
    argv = ["compensate", str(model), "-o", str(run), "--device", "sim://?pacing=lockstep", *SINGLE]
    figures: dict = {}
    with recording_figures(figures) as seen:
        assert cli.main(argv) == 0
    out = capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model-rotary.json", "run-baseline.h5",
                                                          "run-tracking.json", "run-tracking.png", "run.h5"]
    assert seen == {"run-tracking.png": []}, seen  # units on every axis, no overlap, legend off the data
    title = figures["run-tracking.png"].get_suptitle()
    assert "run.h5" in title and "maxwell_slip" in title and "none" in title
    doc = json.loads((tmp_path / "run-tracking.json").read_text())
    runs = {r["feedforward"]: r for r in doc["runs"]}
    assert set(runs) == {"maxwell_slip", "none"} and runs["none"]["run_file"] == str(tmp_path / "run-baseline.h5")
    for name, r in runs.items():  # the oracle: the rms of q_ref - q straight from the run file
        rf = load_record(r["run_file"], need_torque=False, channels=("position_cmd",))
        e = rf.channel("position_cmd") - rf.position
        assert r["rms_error_rad"] == pytest.approx(float(np.sqrt(np.mean(e * e))), rel=1e-12), name
        assert r["max_error_rad"] == pytest.approx(float(np.max(np.abs(e))), rel=1e-12), name
    x = runs["maxwell_slip"]["reduction_vs_none"]
    assert x["rms_error_x"] == pytest.approx(runs["none"]["rms_error_rad"] / runs["maxwell_slip"]["rms_error_rad"])
    # measured on sim:// in lockstep (16-element truth, this 8-element model): rms 6.1x, glitch 5.7x lower
    assert x["rms_error_x"] > 4 and x["glitch_mean_x"] > 4, x
    summary = out.strip().splitlines()[-1]
    assert summary.startswith("sine / maxwell_slip against none: rms error ") and "x smaller)" in summary
    # a second run without --overwrite: one line, exit 2, nothing replaced; also when only the figure is left
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert "run.h5 exists; use --overwrite" in _refused(capsys, argv)
    for name in ("run.h5", "run-baseline.h5", "run-tracking.json"):
        (tmp_path / name).unlink()
    assert "run-tracking.png exists; use --overwrite" in _refused(capsys, argv)
    assert (tmp_path / "run-tracking.png").read_bytes() == before["run-tracking.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model-rotary.json", "run-tracking.png"]


def test_a_single_prediction_has_its_baseline_and_no_baseline_skips_it(tmp_path, capsys, no_device):
    model = _model(tmp_path)
    argv = ["compensate", str(model), "--predict", "-o", str(tmp_path / "p.h5"), *SINGLE]
    with recording_figures() as seen:
        assert cli.main(argv) == 0
    assert seen == {"p-tracking.png": []}, seen
    assert not (tmp_path / "p.h5").exists() and not (tmp_path / "p-baseline.h5").exists()  # --predict: no run file
    doc = json.loads((tmp_path / "p-tracking.json").read_text())
    assert [r["feedforward"] for r in doc["runs"]] == ["maxwell_slip", "none"]
    assert doc["runs"][0]["reduction_vs_none"]["rms_error_x"] > 1
    assert "p-tracking.png exists; use --overwrite" in _refused(capsys, argv)
    assert cli.main([*argv, "--overwrite", "--no-baseline"]) == 0
    doc = json.loads((tmp_path / "p-tracking.json").read_text())
    assert [r["feedforward"] for r in doc["runs"]] == ["maxwell_slip"] and "reduction_vs_none" not in doc["runs"][0]
    assert capsys.readouterr().out.strip().endswith("(no baseline)") and not no_device


def test_predicted_matrix_counts_clipped_feedforward(tmp_path, capsys, no_device):
    out = tmp_path / "matrix"
    model = _model(tmp_path)
    # 0.5 A limit: the feed-forward of the 0.76 N*m break-away at 0.2 N*m/A (3.8 A) is clipped
    with recording_figures() as seen:  # every axis labelled with a unit, no empty legend
        code = cli.main(["compensate", str(model), "--matrix", "--predict", "-o", str(out), "--current-limit",
                         "0.5", *SHORT])
    assert code == 0
    assert seen and not any(seen.values()), seen
    doc = json.loads((out / "compensation.json").read_text())
    runs = {(r["reference"], r["feedforward"]): r for r in doc["runs"]}
    assert set(runs) == {(ref, ff) for ref in ("sine", "triangle", "point_to_point")
                         for ff in ("none", "coulomb", "maxwell_slip")}
    assert all(r["feedforward_clipped"] == 0 for (_, ff), r in runs.items() if ff == "none")
    clipped = runs[("sine", "maxwell_slip")]["feedforward_clipped"]
    assert clipped > 0
    table = (out / "compensation.md").read_text()
    assert "| sine | maxwell_slip |" in table and f"| {clipped} |" in table
    assert {p.name for p in out.glob("*.png")} == {"compensation_sine.png", "compensation_triangle.png",
                                                    "compensation_point_to_point.png"}
    assert not no_device


def test_a_compensate_campaign_plays_the_matrix_on_the_device_and_writes_its_report(tmp_path):
    """[[compensate]] in a campaign: every case runs in position mode on sim://, the run file keeps the load-side
    reference and the feed-forward current, and the report follows. The stored feed-forward is checked against
    an independent closed form (exact stop operators of tests/truth, J*q'' and b*q' of the reference)."""
    from hilbench.analysis.compensation.references import slow_sine
    from hilbench.analysis.record import load_record
    from hilbench.bench.acquisition.campaign import load_campaign, run_campaign
    from tests.truth.generator import stop_operator_forces

    model = _model(tmp_path)
    (tmp_path / "c.toml").write_text(f"""
[defaults]
device = "sim://?pacing=lockstep"
current_limit = "10 A"

[[compensate]]
name = "m"
model = "{model.name}"
references = ["sine"]
feedforwards = ["none", "maxwell_slip"]
amplitudes = ["1e-3 rad", "1e-2 rad"]
frequency = "1 Hz"
cycles = 1
rest = "0.1 s"
sample_rate = 1000
window = "0.02 s"
tolerance = "2e-4 rad"
""")
    campaign = load_campaign(tmp_path / "c.toml")
    assert [r.key for r in campaign.runs] == ["m.sine.none-1", "m.sine.maxwell_slip-1"]
    entries = run_campaign(campaign, tmp_path / "out")
    assert all(e["status"] == "completed" for e in entries.values())
    ref = slow_sine(1000.0, amplitudes=(1e-3, 1e-2), frequency=1.0, cycles=1, rest=0.1)
    rf = load_record(tmp_path / "out" / "m.sine.maxwell_slip-1.h5", need_torque=False,
                     channels=("position_cmd", "current_ff"))
    assert np.allclose(rf.channel("position_cmd"), ref.position, atol=1e-9)
    p = dc_motor(8)
    k = np.asarray(p.ms_stiffness)
    torque = p.inertia * ref.acceleration + stop_operator_forces(k, np.asarray(p.ms_slip), ref.position) \
        + p.viscous * ref.velocity
    assert np.allclose(rf.channel("current_ff"), torque / 0.2, atol=1e-5)  # float32 on the wire
    doc = json.loads((tmp_path / "out" / "m" / "compensation.json").read_text())
    assert (doc["settings"]["window_s"], doc["settings"]["tolerance_rad"]) == (0.02, 2e-4)  # the step's own
    glitch = {r["feedforward"]: r["glitch_mean_rad"] for r in doc["runs"]}
    # measured on sim:// (16-element truth, this 8-element model of the same virgin curve): about 30x
    assert glitch["none"] > 3 * glitch["maxwell_slip"]
    assert (tmp_path / "out" / "m" / "compensation_sine.png").exists()
    # `hilbench analyse` gives each compensated run its compensation row (the run's protocol picks the step), with
    # the report's figures: the glitch ones too, scored with the step's window (0.02 s) that the run records
    import pyarrow.parquet as pq

    assert cli.main(["-q", "analyse", str(tmp_path / "out"), "--steps", "identify,compensation", "--serial",
                     "-o", str(tmp_path / "rows"), "--quiet"]) == 0
    rows = {r["key"]: r for r in pq.read_table(tmp_path / "rows" / "results.parquet").to_pylist()}
    assert {r["step"] for r in rows.values()} == {"compensation"}
    for r in doc["runs"]:
        row = rows[f"m.sine.{r['feedforward']}-1"]
        assert row["status"] == "ok", row["error"]
        for column in ("rms_error_rad", "max_error_rad", "effort_rms_a", "glitch_mean_rad", "glitch_max_rad"):
            assert row[column] == pytest.approx(r[column], rel=1e-9), (r["feedforward"], column)


def test_a_compensate_step_with_a_bad_key_names_its_line(tmp_path):
    from hilbench.bench.acquisition.campaign import CampaignError, load_campaign

    model = _model(tmp_path)
    (tmp_path / "c.toml").write_text(f'[[compensate]]\nmodel = "{model.name}"\nbogus = 1\n')
    with pytest.raises(CampaignError, match=r"c.toml:3: compensate 1: unknown key 'bogus'"):
        load_campaign(tmp_path / "c.toml")
    (tmp_path / "c.toml").write_text(f'[[compensate]]\nmodel = "{model.name}"\nwindow = "-0.005 s"\n')
    with pytest.raises(CampaignError, match=r"c.toml:3: compensate 1: window must be > 0 s"):
        load_campaign(tmp_path / "c.toml")
    (tmp_path / "c.toml").write_text('[[compensate]]\nmodel = "missing.json"\n')
    with pytest.raises(CampaignError, match=r"c.toml:2: compensate 1: cannot read model"):
        load_campaign(tmp_path / "c.toml")


# ---- issue 30: hostile model files and outputs (items 7, 8, 12, 13) ----

def _doc(tmp_path, name="m.json", **changes):
    """_model's document with ``changes`` applied to its parameters (None deletes a key), written as ``name``."""
    doc = json.loads(_model(tmp_path).read_text())
    for key, value in changes.items():
        if key in ("family", "schema", "plant"):
            doc[key] = value
        else:
            doc["parameters"][key] = value
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def test_the_training_run_of_the_model_is_never_an_output(tmp_path, capsys, no_device):
    # item 7: `compensate MODEL.json -o id.h5 --overwrite` replaced id.h5, the run compensate itself reads
    run = tmp_path / "id.h5"
    with RunWriter(run, sample_rate=1000.0, calibration={"torque_constant": 0.2, "ratio": 1.0}) as w:
        w.finish("completed")
    before = run.read_bytes()
    model = _model(tmp_path, train_file=run)
    line = _refused(capsys, ["compensate", str(model), "-o", str(run), "--overwrite"])
    assert "is an input of this command" in line
    # the matrix's run files are outputs too: a training run at the place of one of them is refused
    (tmp_path / "mx").mkdir()
    inside = tmp_path / "mx" / "sine-maxwell_slip.h5"
    run.rename(inside)
    model = _model(tmp_path, train_file=inside)
    line = _refused(capsys, ["compensate", str(model), "--matrix", "-o", str(tmp_path / "mx"), "--overwrite", *SHORT])
    assert "sine-maxwell_slip.h5 is an input of this command" in line
    assert inside.read_bytes() == before and not no_device


def _comparison(tmp_path, row_name):
    from hilbench.firmware_sim.engine.friction_models import dc_motor

    units = {"inertia": "kg*m^2", "ms_stiffness": "N*m/rad"}
    plant = dc_motor(8).replace(torque_constant=1.0).to_dict()
    rows = [{"model": "maxwell_slip", "fit": {"units": units}, "plant": plant},
            {"model": row_name, "fit": {"units": units}, "plant": plant}]
    path = tmp_path / "compare.json"
    path.write_text(json.dumps({"schema": "hilbench.compare/1", "axis": "rotary", "rows": rows}))
    return path


def test_a_planted_row_name_never_writes_outside_the_output_folder(tmp_path, capsys, no_device):
    # item 8: a row named "../../../../precious" made `--matrix -o deep/a/mx4 --overwrite` replace deep/precious.h5
    deep = tmp_path / "deep"
    (deep / "a").mkdir(parents=True)
    precious = deep / "precious.h5"
    precious.write_bytes(b"precious")
    model = _comparison(tmp_path, "../../../../precious")
    line = _refused(capsys, ["compensate", str(model), "--matrix", "-o", str(deep / "a" / "mx4"), "--overwrite",
                             *SHORT])
    assert "rows[1].model must be a plain identifier" in line and "'../../../../precious'" in line
    assert precious.read_bytes() == b"precious" and sorted(p.name for p in deep.rglob("*")) == ["a", "precious.h5"]
    # a plain name is accepted: the same file with the row renamed predicts (no device)
    model = _comparison(tmp_path, "lugre_twin")
    assert cli.main(["compensate", str(model), "--matrix", "--predict", "-o", str(tmp_path / "p"), "-q",
                     "--feedforwards", "none,lugre_twin", "--references", "triangle", *SHORT]) == 0
    assert {r["feedforward"] for r in json.loads((tmp_path / "p" / "compensation.json").read_text())["runs"]} == {
        "none", "lugre_twin"}
    assert not no_device


@pytest.mark.parametrize("changes, match", [
    ({"inertia": [0.002]}, "parameters.inertia must be a number, got [0.002]"),             # was TypeError
    ({"inertia": "0.002"}, "parameters.inertia must be a number, got '0.002'"),             # was taken as 0.002
    ({"inertia": True}, "parameters.inertia must be a number, got True"),                   # was taken as 1.0
    ({"inertia": 1e300}, "parameters.inertia must be finite and within +-1e+12"),           # was taken
    ({"inertia": -1e-3}, "parameters.inertia must be > 0"),
    ({"ms_stiffness": [-1.0, 2.0], "ms_delta": [1e-4, 2e-4]}, "ms_stiffness[0] must be >= 0, got -1.0"),  # dropped
    ({"ms_stiffness": [1.0, 2.0], "ms_delta": [1e-4, -2e-4]}, "ms_delta[1] must be >= 0, got -0.0002"),   # dropped
    ({"ms_stiffness": [1.0] * 13, "ms_delta": [1e-4] * 12}, "13 stiffnesses (ms_stiffness) but 12 slip"),  # truncated
    ({"ms_stiffness": [1.0] * 1025, "ms_delta": [1e-4] * 1025}, "has 1025 values, above the limit of 1024"),
    ({"viscous": "0"}, "parameters.viscous must be a number, got '0'"),
    ({"coulomb": -0.1}, "parameters.coulomb must be >= 0"),
    ({"std_errors": {"inertia": "x"}}, "std_errors.inertia must be a number"),
    ({"inertia": None}, "parameters.inertia must be a number, got None"),
    ({"family": "unicorn"}, "family must be one of coulomb_viscous"),                       # was StopIteration
    ({"family": "lugre", "plant": {"inertia": "1e-4"}}, "plant.inertia must be a number, got '1e-4'"),
    ({"family": "lugre", "plant": [1]}, "plant must be an object"),
    ({"family": "lugre", "plant": {"inertia": 1e-4, "ms_stiffness": [1.0, 2.0], "ms_slip": [1e-3]}},
     "2 values in ms_stiffness but 1 in ms_slip"),
])
def test_a_malformed_model_is_one_line_before_anything_moves(tmp_path, capsys, no_device, changes, match):
    # items 12 and 13: no value is silently changed; a malformed one is one line and exit 2
    model = _doc(tmp_path, **changes)
    for extra in ([], ["--matrix", "--predict", "-o", str(tmp_path / "p")]):
        line = _refused(capsys, ["compensate", str(model), *extra, *SHORT])
        assert match in line, line
    assert not no_device and not (tmp_path / "p").exists()


def test_deeply_nested_or_huge_model_files_are_one_line(tmp_path, capsys, no_device):
    import time

    nested = tmp_path / "nested.json"
    nested.write_text("[" * 100_000 + "]" * 100_000)  # was RecursionError
    assert "nested too deep" in _refused(capsys, ["compensate", str(nested)])
    huge = tmp_path / "huge.json"
    with open(huge, "wb") as fh:  # 74 MB (sparse): refused from its size, before it is read (was 1.4 GB, 10.8 s)
        fh.truncate(74_000_000)
    t0 = time.perf_counter()
    line = _refused(capsys, ["compensate", str(huge)])
    assert "74000000 bytes, above the 8388608 bytes" in line and time.perf_counter() - t0 < 2.0
    assert not no_device


def test_a_family_file_predicts_on_its_own_plant(tmp_path, capsys, no_device):
    # --predict took the Maxwell-slip plant with next(...): a family file without one ended in StopIteration
    from hilbench.firmware_sim.engine.friction_models import dc_motor

    plant = dc_motor(8).replace(torque_constant=1.0).to_dict()
    model = _doc(tmp_path, family="maxwell_slip", plant=plant, schema="hilbench.friction-model/2")
    doc = json.loads(model.read_text())
    doc["family"] = "gms"  # a family file of hilbench compare: its plant is what --predict simulates
    doc["parameters"]["units"] = {"inertia": "kg*m^2"}
    model.write_text(json.dumps(doc))
    assert cli.main(["compensate", str(model), "--matrix", "--predict", "-o", str(tmp_path / "p"), "-q",
                     "--references", "triangle", *SHORT]) == 0
    runs = json.loads((tmp_path / "p" / "compensation.json").read_text())["runs"]
    assert [r["feedforward"] for r in runs] == ["none", "gms"] and not no_device


def test_a_report_plot_that_is_the_model_is_refused(tmp_path, capsys, no_device):
    # an output is never an input: also the reversal plots of the report
    out = tmp_path / "mx"
    out.mkdir()
    model = _model(tmp_path)
    plot = out / "compensation_triangle.png"
    os.link(model, plot)  # the model under the plot's name (a hard link: the same file)
    before = model.read_bytes()
    line = _refused(capsys, ["compensate", str(model), "--matrix", "--predict", "-o", str(out), "--overwrite",
                             "--references", "triangle", *SHORT])
    assert "compensation_triangle.png is an input of this command" in line
    assert model.read_bytes() == before and sorted(p.name for p in out.iterdir()) == ["compensation_triangle.png"]


@pytest.mark.parametrize("name", ["..", "../up", "a.b", "a/b", "-x", 3])
def test_a_compensate_step_name_is_a_plain_name(tmp_path, name):
    # the step's name is its report folder OUT/<name>/: ".." wrote the report beside OUT, "a.b" split its runs
    from hilbench.bench.acquisition.campaign import CampaignError, load_campaign

    model = _model(tmp_path)
    (tmp_path / "c.toml").write_text(f'[[compensate]]\nname = {json.dumps(name)}\nmodel = "{model.name}"\n')
    with pytest.raises(CampaignError, match=r"c.toml:2: compensate 1: name .* must use only letters"):
        load_campaign(tmp_path / "c.toml")


def test_a_geared_run_tracks_the_load_reference_and_reports_its_setpoint_to_the_live_view(tmp_path):
    """With ratio 2 the load follows q_ref (the protocol multiplied its setpoints by the ratio and the runner did
    again: the load moved 2*q_ref, against a feed-forward computed for q_ref). Bench.run's progress blocks carry
    the setpoint at the load, which the GUI's live view draws against the measured position."""
    from hilbench.analysis.record import load_record
    from hilbench.bench.acquisition.compensation import CompensatedReference
    from hilbench.bench.acquisition.runner import Bench, DeviceSettings

    protocol = CompensatedReference(reference="point_to_point", targets=(0.01, 0.0), move_time=0.2, rest=0.1,
                                    sample_rate=1000)
    blocks = []
    with Bench.open("sim://?pacing=lockstep", DeviceSettings(ratio=2.0)) as bench:
        result = bench.run(protocol, tmp_path / "p.h5", progress=blocks.append)
    assert result.status == "completed"
    ref = protocol.reference_path.position
    rf = load_record(tmp_path / "p.h5", need_torque=False, channels=("position_cmd",))
    assert np.max(np.abs(rf.channel("position_cmd") - ref)) < 1e-9  # float32 on the wire
    # the load reaches the 10 mrad target (measured 10.00 mrad; 20.00 mrad before the fix), within 2 %
    assert abs(np.max(rf.position) - 0.01) < 2e-4, np.max(rf.position)
    sent = np.concatenate([b.position_cmd for b in blocks])
    assert sent.shape == ref.shape and np.max(np.abs(sent - ref)) < 1e-9
