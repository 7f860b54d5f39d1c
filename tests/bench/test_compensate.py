"""hilbench compensate: refusals before anything moves, clipping counts, the predicted matrix report."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hilbench.analysis.runfile import RunWriter
from hilbench.bench import cli
from hilbench.firmware_sim.friction_models import dc_motor
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

    monkeypatch.setattr("hilbench.bench.runner.Bench.open", refuse)
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
    (["--predict", "-o", "x.h5"], "--predict writes no run file"),
])
def test_bad_options_are_one_line(tmp_path, capsys, no_device, extra, match):
    assert match in _refused(capsys, ["compensate", str(_model(tmp_path)), *extra])
    assert not no_device


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
    from hilbench.bench.campaign import load_campaign, run_campaign
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


def test_a_compensate_step_with_a_bad_key_names_its_line(tmp_path):
    from hilbench.bench.campaign import CampaignError, load_campaign

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
