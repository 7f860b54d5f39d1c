"""Campaigns: validation before anything moves, and kill-then-resume with no duplicate or missing run."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from hilbench.bench.acquisition.campaign import CampaignError, load_campaign
from hilbench.common.runfile import open_run

GOOD = """
[defaults]
device = "sim://?pacing=lockstep"
sample_rate = 10000
current_limit = "8 A"

[[run]]
name = "id"
protocol = "identification"
repeats = 2
amplitude = "4 A"
duration = "{duration} s"

[[run]]
name = "ss"
protocol = "stepped_sine"
frequencies = [10.0, 20.0]
amplitudes = ["1 A"]
settle_periods = 2
measure_periods = 4
"""


def _write(tmp_path, text, name="c.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("old", "new", "line", "reason"),
    [
        ('amplitude = "4 A"', 'amplitude = "4 N*m"', 11, "unit 'N*m' is wrong, expected 'A'"),
        ('amplitude = "4 A"', "amplitde = 4", 11, "unknown key 'amplitde'"),
        ('amplitude = "4 A"', "amplitude = 4000", 11, "outside"),
        ("repeats = 2", "repeats = 0", 10, "repeats must be"),
        ('protocol = "stepped_sine"', 'protocol = "sweep"', 16, "protocol must be one of"),
        ('current_limit = "8 A"', 'current_limit = "8 V"', 5, "unit 'V' is wrong"),
    ],
)
def test_bad_campaign_is_refused_with_file_line_and_reason(tmp_path, old, new, line, reason):
    path = _write(tmp_path, GOOD.format(duration=1).replace(old, new))
    with pytest.raises(CampaignError) as info:
        load_campaign(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}:{line}:"), msg
    assert reason in msg


def test_bad_campaign_from_the_cli_is_one_line_and_exit_2(tmp_path):
    path = _write(tmp_path, GOOD.format(duration=1).replace("repeats = 2", "repeats = 2\nfoo = 1"))
    cp = subprocess.run([sys.executable, "-m", "hilbench.bench.cli", "campaign", str(path)], capture_output=True,
                        text=True, timeout=60)
    assert cp.returncode == 2
    assert len(cp.stderr.strip().splitlines()) == 1 and "unknown key 'foo'" in cp.stderr
    assert not (tmp_path / "c").exists()  # nothing moved


@pytest.mark.usefixtures("starts_devices")  # a real-time simulator is killed mid-run: the serial part
def test_killed_campaign_resumes_to_every_run_completed_once(tmp_path):
    # real-time pacing so the kill lands inside the second run
    path = _write(tmp_path, GOOD.format(duration=2).replace("?pacing=lockstep", ""))
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "hilbench.bench.cli", "campaign", str(path), "-o", str(out),
                             "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        index = out / "index.json"
        if index.exists() and len(json.loads(index.read_text())["runs"]) == 1 and (out / "id-2.h5").exists():
            break
        time.sleep(0.05)
    else:
        proc.kill()
        pytest.fail("first run did not complete")
    time.sleep(0.5)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    with open_run(out / "id-2.h5") as run:
        assert run.status == "crashed"
    # (no --quiet: it is the global -q, which prints nothing but errors, and these lines are the result)
    cp = subprocess.run([sys.executable, "-m", "hilbench.bench.cli", "campaign", str(path), "-o", str(out), "--resume"],
                        capture_output=True, text=True, timeout=120)
    assert cp.returncode == 0, cp.stderr
    assert "id-1: skipped" in cp.stdout
    runs = json.loads((out / "index.json").read_text())["runs"]
    assert [r["key"] for r in runs] == ["id-1", "id-2", "ss-1"]
    assert all(r["status"] == "completed" for r in runs)
    for r in runs:
        with open_run(out / r["file"]) as run:
            assert run.status == "completed" and run.uid == r["uid"]
    assert (out / "id-2.failed-1.h5").exists()  # the crashed attempt is kept, not listed


# ---- issue 30 item 6: --resume never mixes plans; each repeat its own seed ----

STEP = """
[defaults]
device = "sim://?pacing=lockstep"
current_limit = "10 A"

[[compensate]]
name = "m"
model = "model.json"
references = ["point_to_point"]
feedforwards = ["none", "maxwell_slip"]
targets = {targets}
move_time = "0.2 s"
rest = "0.1 s"
sample_rate = 1000
"""


def test_resume_redoes_a_run_of_another_plan_and_the_report_combines_one_plan(tmp_path):
    # stop a [[compensate]] campaign after one case, edit its targets, resume: the report scored the old run
    # against the new reference ("reduction 5.49e+04")
    from hilbench.analysis.compensation.references import point_to_point
    from hilbench.analysis.record import load_record
    from hilbench.bench.acquisition.campaign import run_campaign
    from tests.bench.test_compensate import _model

    model = _model(tmp_path)
    model.rename(tmp_path / "model.json")
    path = _write(tmp_path, STEP.format(targets='["0.01 rad", "0 rad"]'))
    out = tmp_path / "out"
    states: list[tuple[str, str]] = []

    def stop_after_one(ev):
        states.append((ev.key, ev.state))
        if ev.state == "completed":
            raise KeyboardInterrupt("stopped after one case")

    with pytest.raises(KeyboardInterrupt):
        run_campaign(load_campaign(path), out, progress=stop_after_one)
    assert [k for k, s in states if s == "completed"] == ["m.point_to_point.none-1"]
    first = json.loads((out / "index.json").read_text())["runs"][0]["uid"]
    path.write_text(STEP.format(targets='["0.03 rad", "0 rad"]'))  # the plan changes
    states.clear()
    entries = run_campaign(load_campaign(path), out, resume=True, progress=lambda ev: states.append((ev.key, ev.state)))
    said = [(k, s) for k, s in states if s != "running"]
    assert said == [("m.point_to_point.none-1", "plan changed (parameters targets): redone"),
                    ("m.point_to_point.none-1", "completed"), ("m.point_to_point.maxwell_slip-1", "completed")]
    assert (out / "m.point_to_point.none-1.replanned-1.h5").exists()
    new = point_to_point(1000.0, targets=(0.03, 0.0), move_time=0.2, rest=0.1)
    for entry in entries.values():
        assert entry["status"] == "completed" and entry["parameters"]["targets"] == [0.03, 0.0]
        rf = load_record(out / entry["file"], need_torque=False, channels=("position_cmd",))
        np.testing.assert_allclose(rf.channel("position_cmd"), new.position, atol=1e-9)  # the new reference
    with open_run(out / "m.point_to_point.none-1.h5") as run:
        assert run.uid == entries["m.point_to_point.none-1"]["uid"] != first
    report = json.loads((out / "m" / "compensation.json").read_text())
    assert {r["feedforward"] for r in report["runs"]} == {"none", "maxwell_slip"}
    # nothing changed: every run is kept
    states.clear()
    run_campaign(load_campaign(path), out, resume=True, progress=lambda ev: states.append((ev.key, ev.state)))
    assert [s for _, s in states] == ["skipped", "skipped"]
    # the model file's content changes at the same path: the runs with its feed-forward are redone
    doc = json.loads((tmp_path / "model.json").read_text())
    doc["parameters"]["viscous"] *= 2
    (tmp_path / "model.json").write_text(json.dumps(doc))
    states.clear()
    run_campaign(load_campaign(path), out, resume=True, progress=lambda ev: states.append((ev.key, ev.state)))
    said = [s for _, s in states if s != "running"]
    assert said == ["plan changed (model file content): redone", "completed"] * 2


def test_each_repeat_plays_its_own_seed_stored_in_its_run_file(tmp_path):
    # all repeats of a campaign played seed 0: the identical input
    from hilbench.bench.acquisition.campaign import repeat_seed, run_campaign

    text = GOOD.format(duration=0.2).replace("repeats = 2", "repeats = 3\nseed = 7")
    campaign = load_campaign(_write(tmp_path, text))
    ids = [r for r in campaign.runs if r.name == "id"]
    expected = [7] + [int(np.random.SeedSequence([7, r]).generate_state(1, np.uint32)[0]) for r in (2, 3)]
    assert [r.protocol.seed for r in ids] == expected == [repeat_seed(7, r) for r in (1, 2, 3)]
    assert len(set(expected)) == 3
    inputs = [r.protocol.setpoints(8.0) for r in ids]
    assert not np.array_equal(inputs[0], inputs[1]) and not np.array_equal(inputs[1], inputs[2])
    campaign.runs = ids  # play the identification repeats only
    run_campaign(campaign, tmp_path / "out")
    for r, seed in zip(ids, expected, strict=True):
        with open_run(tmp_path / "out" / f"{r.key}.h5") as run:
            assert run.protocol_params["seed"] == seed
    # a campaign without a seed: repeat 1 plays seed 0, as before
    assert load_campaign(_write(tmp_path, GOOD.format(duration=1), "d.toml")).runs[0].protocol.seed == 0


def test_an_older_index_entry_without_a_model_hash_is_compared_on_parameters_and_settings(tmp_path):
    from hilbench.bench.acquisition.campaign_plan import plan_changes, run_plan

    planned = load_campaign(_write(tmp_path, GOOD.format(duration=1))).runs[1]  # id-2: its own seed now
    plan = run_plan(planned, {})
    assert plan["model_sha256"] is None and plan["parameters"]["seed"] == planned.protocol.seed != 0
    old = {"protocol": plan["protocol"], "parameters": {**plan["parameters"], "seed": 0},
           "settings": plan["settings"]}  # written before each repeat had its seed: repeat 2 played seed 0
    assert plan_changes(old, plan) == ["parameters seed"]
    old["parameters"]["seed"] = planned.protocol.seed
    assert plan_changes(old, plan) == []
    old["settings"] = {**plan["settings"], "current_limit": 4.0}
    assert plan_changes(old, plan) == ["settings current_limit"]


@pytest.mark.parametrize(("text", "reason"), [
    ("a = " + "[" * 100_000 + "]" * 100_000, "nested too deep"),  # was RecursionError
    ("name = \"\\xff\"".encode("latin-1").decode("latin-1") + "\udcff", "not valid TOML"),
    ("# " + "x" * (5 << 20), "longer than 4194304 bytes"),
])
def test_a_hostile_campaign_file_is_one_line(tmp_path, text, reason):
    path = tmp_path / "c.toml"
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    cp = subprocess.run([sys.executable, "-m", "hilbench.bench.cli", "campaign", str(path), "--check"],
                        capture_output=True, text=True, timeout=60)
    assert cp.returncode == 2 and len(cp.stderr.strip().splitlines()) == 1 and reason in cp.stderr, cp.stderr


def test_a_resume_with_fewer_repeats_marks_the_unplanned_runs_and_the_index_has_a_uid(tmp_path):
    # lowering repeats 3 -> 1 kept runs 2 and 3 in the index as planned ("3/1 runs completed") and analyse used them
    from hilbench.bench.acquisition.campaign import run_campaign

    text = GOOD.format(duration=0.2).split("[[run]]\nname = \"ss\"")[0].replace("repeats = 2", "repeats = 3")
    out = tmp_path / "out"
    run_campaign(load_campaign(_write(tmp_path, text)), out)
    first = json.loads((out / "index.json").read_text())
    assert len(first["runs"]) == 3 and len(first["uid"]) == 32  # a uid from the campaign's creation
    smaller = load_campaign(_write(tmp_path, text.replace("repeats = 3", "repeats = 1"), "d.toml"))
    entries = run_campaign(smaller, out, resume=True)
    doc = json.loads((out / "index.json").read_text())
    assert doc["uid"] == first["uid"]
    assert {e["key"]: e.get("planned", True) for e in doc["runs"]} == {"id-1": True, "id-2": False, "id-3": False}
    assert len(entries) == 3
    run_campaign(load_campaign(_write(tmp_path, text, "e.toml")), out, resume=True)  # planned again: unmarked
    assert all("planned" not in e for e in json.loads((out / "index.json").read_text())["runs"])
