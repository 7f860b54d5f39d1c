"""The drive soak's file check finds lost and invented samples and short runs called completed (so its zeros
mean something)."""

import numpy as np

from benchmarks.bench_drive_soak import KT, RATED, check_drive_file
from hilbench.common.runfile import DEVICE_CHANNELS, RunWriter


def _write(path, index, cmd, setpoints):
    with RunWriter(path, sample_rate=1000.0, channels=DEVICE_CHANNELS,
                   protocol_arrays={"setpoints": setpoints}) as w:
        n = len(index)
        w.append({"sample_index": index, "t": index / 1000, "current_cmd": cmd, "current": cmd,
                  "torque": KT * cmd, "position": np.zeros(n), "counts": np.zeros(n, dtype=np.int64)})


def test_cia402_files_quantised_commands_gaps_and_short_runs(tmp_path):
    sp = np.linspace(-2, 2, 200)
    quantised = np.rint(sp * KT / RATED * 1000) * RATED / 1000 / KT
    good = tmp_path / "good.h5"
    _write(good, np.arange(200), quantised, sp)
    assert check_drive_file(good, "canopen", killed=False, drive_killed=False) == {
        "lost": 0, "invented": 0, "unreadable": 0, "samples": 200, "absent": 0, "short_completed": 0, "drive_ended": 0}
    raw = tmp_path / "raw.h5"  # the setpoints as they are: not what a per-mille drive was sent
    _write(raw, np.arange(200), sp, sp)
    assert check_drive_file(raw, "canopen", False, False)["invented"] == int(np.sum(sp != quantised)) > 100
    short = tmp_path / "short.h5"  # 150 of 200 samples, marked completed
    index = np.concatenate([np.arange(100), np.arange(110, 160)])  # and a gap of 10
    _write(short, index, quantised[index], sp)
    got = check_drive_file(short, "canopen", False, drive_killed=True)
    assert got["short_completed"] == 1 and got["lost"] == 50 + 50  # 50 indices moved, 50 missing at the end


def test_odrive_files_accept_only_targets_the_drive_was_sent(tmp_path):
    sp = np.linspace(-2, 2, 100)
    target = (sp * KT).astype(np.float32).astype(np.float64) / KT
    held = np.concatenate([[0.0, 0.0], target[:-2]])  # the drive's own clock: targets it had received, or 0
    ok = tmp_path / "ok.h5"
    _write(ok, np.arange(100), held, sp)
    assert check_drive_file(ok, "odrive", False, False)["invented"] == 0
    made_up = held.copy()
    made_up[50] = 0.123456
    bad = tmp_path / "bad.h5"
    _write(bad, np.arange(100), made_up, sp)
    assert check_drive_file(bad, "odrive", False, False)["invented"] == 1


def test_a_killed_host_must_leave_a_crashed_run_unless_it_had_finished(tmp_path):
    sp = np.linspace(-1, 1, 100)
    q = np.rint(sp * KT / RATED * 1000) * RATED / 1000 / KT
    done = tmp_path / "done.h5"  # the host finished the file, then was killed while closing the drive
    _write(done, np.arange(100), q, sp)
    assert check_drive_file(done, "canopen", killed=True, drive_killed=False)["unreadable"] == 0
    partial = tmp_path / "partial.h5"  # "completed" with 60 of 100 samples after a kill: not what happened
    _write(partial, np.arange(60), q[:60], sp)
    got = check_drive_file(partial, "canopen", killed=True, drive_killed=False)
    assert got["unreadable"] == 1 and got["short_completed"] == 1


def test_moteus_files_hold_the_float32_command_of_each_sample(tmp_path):
    sp = np.linspace(-2, 2, 100)
    sent = np.float32(sp * KT).astype(np.float64) / KT
    ok = tmp_path / "ok.h5"
    _write(ok, np.arange(100), sent, sp)
    assert check_drive_file(ok, "moteus", False, False)["invented"] == 0
    shifted = tmp_path / "shifted.h5"  # each sample holding the previous sample's command: invented
    _write(shifted, np.arange(100), np.concatenate([[0.0], sent[:-1]]), sp)
    assert check_drive_file(shifted, "moteus", False, False)["invented"] == 100
