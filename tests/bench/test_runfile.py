"""Run file schema v1: round trip, units, events, statuses, layout readable by plain h5py, errors."""

from __future__ import annotations

import json
import os

import h5py
import numpy as np
import pytest

from hilbench.bench.acquisition.excitations import stepped_sine
from hilbench.bench.cli import main as bench_main
from hilbench.common import runfile as rf


def _block(start: int, n: int, fs: float = 1000.0) -> dict[str, np.ndarray]:
    k = np.arange(start, start + n)
    t = k / fs
    return {
        "sample_index": k,
        "t": t,
        "current_cmd": np.sin(t),
        "current": np.sin(t) + 1e-3,
        "torque": 0.05 * np.sin(t),
        "position": np.cos(t),
        "counts": k * 3,
    }


def _write(path, n_blocks=7, block=300, **kw):
    with rf.RunWriter(path, sample_rate=1000.0, **kw) as w:
        for i in range(n_blocks):
            w.append(_block(i * block, block))
    return w


def test_round_trip_and_metadata(tmp_path):
    path = tmp_path / "run.h5"
    proto = stepped_sine(1000.0, frequencies=[1.0, 2.0], amplitudes=[0.5])
    with rf.RunWriter(
        path,
        sample_rate=1000.0,
        device={"name": "sim", "serial": "0001"},
        config={"mode": "current"},
        calibration={"torque_constant": 0.05, "torque_constant_unit": "N*m/A"},
        protocol_name="stepped_sine",
        protocol_params=proto.protocol(),
        protocol_arrays={"step_windows": proto.windows},
        operator="ada",
        notes="first run",
    ) as w:
        for i in range(7):
            w.append(_block(i * 300, 300))
        w.add_event("pause", "operator pause")
        w.add_event("resume", t=1.5, sample_index=1500)
    expected = {k: np.concatenate([_block(i * 300, 300)[k] for i in range(7)]) for k in rf.DEVICE_CHANNELS}
    with rf.open_run(path) as run:
        assert run.status == "completed" and run.stored_status == "completed"
        assert run.n_samples == 2100 and run.axis == "rotary" and run.sample_rate == 1000.0
        for name in rf.DEVICE_CHANNELS:
            np.testing.assert_array_equal(run.channel(name), expected[name])  # lossless
        np.testing.assert_array_equal(run.t, expected["t"])
        assert run.channels == rf.DEVICE_CHANNELS  # recording order kept
        assert run.units == {
            "sample_index": "1",
            "t": "s",
            "current_cmd": "A",
            "current": "A",
            "torque": "N*m",
            "position": "rad",
            "counts": "counts",
        }
        assert run.device == {"name": "sim", "serial": "0001"}
        assert run.calibration["torque_constant"] == 0.05
        assert run.protocol_name == "stepped_sine" and run.protocol_params["params"]["frequencies"] == [
            1.0,
            2.0,
        ]
        np.testing.assert_array_equal(run.protocol_array("step_windows"), proto.windows)
        assert len(run.meta["uid"]) == 32 and int(run.meta["uid"], 16) >= 0
        assert run.meta["operator"] == "ada" and run.meta["notes"] == "first run"
        assert set(run.software) == {"hilbench", "python", "numpy", "h5py", "hdf5"}
        assert run.start_time < run.end_time and run.end_time.endswith("+00:00")
        ev = run.events
        assert list(ev["kind"]) == ["pause", "resume"]
        assert ev["sample_index"][0] == 2099 and ev["t"][0] == pytest.approx(2.099)
        assert ev["message"][0] == "operator pause" and ev["t"][1] == 1.5
        np.testing.assert_array_equal(run.channel("torque", 10, 20), expected["torque"][10:20])


def test_layout_is_plain_h5py(tmp_path):
    """analysis reads the file without bench: the documented paths, attributes and JSON datasets."""
    path = tmp_path / "run.h5"
    _write(path, n_blocks=2, device={"name": "x"}, protocol_name="chirp", protocol_params={"a": 0.1})
    with h5py.File(path, "r", libver="latest", swmr=True) as f:
        assert f.attrs["schema"] == "hilbench-run" and f.attrs["schema_version"] == 2
        assert f.attrs["status"] == "completed" and f.attrs["axis"] == "rotary"
        assert f["samples/torque"].attrs["unit"] == "N*m" and f["samples/t"].attrs["unit"] == "s"
        assert f["samples/t"].shape == (600,) and f["samples/t"].maxshape == (None,)
        assert f["samples/t"].chunks == (500,) and f["samples/t"].compression == "lzf"
        assert json.loads(f["device/identity"][()]) == {"name": "x"}
        assert json.loads(f["protocol/parameters"][()]) == {"a": 0.1}
        assert f["protocol"].attrs["name"] == "chirp"
        assert f["events"].dtype.names == ("sample_index", "t", "wall_time", "kind", "message")


def test_linear_axis_units_and_aliases(tmp_path):
    path = tmp_path / "lin.h5"
    with rf.RunWriter(
        path,
        sample_rate=1000.0,
        axis="linear",
        channels=("sample_index", "t", "torque", "position", "velocity"),
        custom_channels={"drive_voltage": "V"},
        compression="gzip",
    ) as w:
        k = np.arange(10)
        w.append(
            {
                "sample_index": k,
                "t": k / 1e3,
                "torque": k * 2.0,
                "position": k * 1e-3,
                "velocity": k * 1.0,
                "drive_voltage": k * 0.1,
            }
        )
    with rf.open_run(path) as run:
        assert run.axis == "linear"
        assert run.unit("torque") == "N" and run.unit("force") == "N"
        assert (
            run.unit("position") == "m" and run.unit("velocity") == "m/s" and run.unit("drive_voltage") == "V"
        )
        np.testing.assert_array_equal(run.channel("force"), np.arange(10) * 2.0)
        with pytest.raises(rf.RunFileError, match="no channel 'current'"):
            run.channel("current")


def test_flush_leaves_less_than_flush_interval_in_memory(tmp_path):
    """After every append, the samples not yet flushed span < flush_interval (0.5 s) of device time, and the
    file on disk (read by a second SWMR reader) already holds all flushed samples."""
    path = tmp_path / "run.h5"
    w = rf.RunWriter(path, sample_rate=1000.0)
    reader = None
    try:
        for i in range(20):
            w.append(_block(i * 123, 123))
            unflushed = w.n_samples - w.n_flushed
            assert 0 <= unflushed < 0.5 * 1000.0
            assert w.n_flushed % 500 == 0
            if reader is None and w.n_flushed:
                reader = rf.open_run(path)
                assert reader.status == "running" and reader.writer_alive
            if reader is not None:
                assert reader.refresh() == w.n_flushed
                np.testing.assert_array_equal(reader.t[-3:], np.arange(w.n_flushed - 3, w.n_flushed) / 1000.0)
    finally:
        w.finish()
        if reader is not None:
            reader.close()
    assert not os.path.exists(rf.lock_path(path))


def test_exception_aborts_with_error_event(tmp_path):
    path = tmp_path / "run.h5"
    with pytest.raises(RuntimeError, match="boom"):
        with rf.RunWriter(path, sample_rate=1000.0) as w:
            w.append(_block(0, 700))
            raise RuntimeError("boom")
    with rf.open_run(path) as run:
        assert run.status == "aborted" and run.n_samples == 700  # the partial chunk is written on finish
        assert run.events["kind"][-1] == "error" and "RuntimeError: boom" in run.events["message"][-1]


def test_keyboard_interrupt_and_abort(tmp_path):
    with pytest.raises(KeyboardInterrupt):
        with rf.RunWriter(tmp_path / "a.h5", sample_rate=100.0) as w:
            w.append(_block(0, 5))
            raise KeyboardInterrupt
    with rf.open_run(tmp_path / "a.h5") as run:
        assert run.status == "aborted" and run.events["kind"][-1] == "abort"
    w = rf.RunWriter(tmp_path / "b.h5", sample_rate=100.0)
    w.abort("limit switch")
    with pytest.raises(rf.RunFileError, match="already finished"):
        w.append(_block(0, 5))
    with rf.open_run(tmp_path / "b.h5") as run:
        assert run.status == "aborted" and run.events["message"][-1] == "limit switch" and run.n_samples == 0


def test_writer_rejects_bad_input(tmp_path):
    path = tmp_path / "run.h5"
    with pytest.raises(rf.RunFileError, match="unknown channel"):
        rf.RunWriter(path, sample_rate=1000.0, channels=("sample_index", "t", "speed"))
    with pytest.raises(rf.RunFileError, match="must include"):
        rf.RunWriter(path, sample_rate=1000.0, channels=("t", "torque"))
    with pytest.raises(rf.RunFileError, match="axis"):
        rf.RunWriter(path, sample_rate=1000.0, axis="planar")
    with pytest.raises(rf.RunFileError, match="sample_rate"):
        rf.RunWriter(path, sample_rate=0.0)
    with rf.RunWriter(path, sample_rate=1000.0) as w:
        with pytest.raises(rf.RunFileError, match="missing \\['counts'\\]"):
            w.append({k: v for k, v in _block(0, 3).items() if k != "counts"})
        bad = _block(0, 3)
        bad["torque"] = bad["torque"][:2]
        with pytest.raises(rf.RunFileError, match="same length|as long as"):
            w.append(bad)
        with pytest.raises(rf.RunFileError, match="event kind"):
            w.add_event("party")
        with pytest.raises(rf.RunFileError, match="another process is writing"):
            rf.RunWriter(tmp_path / "run.h5", sample_rate=1.0, overwrite=True)
    with pytest.raises(rf.RunFileError, match="file exists"):
        rf.RunWriter(path, sample_rate=1000.0)


def test_truncated_and_foreign_files_give_one_line_cli_error(tmp_path, capsys):
    path = tmp_path / "run.h5"
    _write(path, n_blocks=10)
    data = path.read_bytes()
    truncated = tmp_path / "truncated.h5"
    truncated.write_bytes(data[: len(data) // 2])
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5\n")
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = 1
    for bad, pattern in (
        (truncated, "truncated"),
        (text, "not an HDF5 file"),
        (foreign, "not a hilbench run"),
    ):
        assert bench_main(["show", str(bad)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err and pattern in err, err
        with pytest.raises(rf.RunFileError):
            rf.open_run(bad)


def test_show_prints_summary_and_json(tmp_path, capsys):
    path = tmp_path / "run.h5"
    _write(path, n_blocks=2, protocol_name="chirp")
    out_json = tmp_path / "s.json"
    assert bench_main(["show", str(path), "--json", str(out_json)]) == 0
    out = capsys.readouterr().out
    assert "status     completed" in out and "torque" in out and "N*m" in out and "600 at 1000 Hz" in out
    summary = json.loads(out_json.read_text())
    assert summary["n_samples"] == 600 and summary["status"] == "completed"
    torque = next(c for c in summary["channels"] if c["name"] == "torque")
    assert torque["unit"] == "N*m" and torque["max"] == pytest.approx(0.05 * np.sin(0.599))


def test_lookup3_known_vectors_and_hdf5_superblock(tmp_path):
    """Oracle 1: Bob Jenkins' published lookup3 test values. Oracle 2: the checksum HDF5 itself wrote into a
    v3 superblock."""
    assert rf.lookup3(b"") == 0xDEADBEEF
    assert rf.lookup3(b"Four score and seven years ago") == 0x17770551
    assert rf.lookup3(b"Four score and seven years ago", 1) == 0xCD628161
    path = tmp_path / "run.h5"
    _write(path, n_blocks=1)
    head = path.read_bytes()[:48]
    assert head[8] == 3 and head[9] == 8  # superblock v3, 8-byte offsets
    assert rf.lookup3(head[:44]) == int.from_bytes(head[44:48], "little")
    assert rf.clear_write_flags(path) is False  # a cleanly closed file has no flags set


def test_event_message_is_cut_at_256_bytes_on_a_character_boundary(tmp_path):
    path = tmp_path / "run.h5"
    with rf.RunWriter(path, sample_rate=10.0) as w:
        w.add_event("fault", "é" * 200)  # 400 UTF-8 bytes
    with rf.open_run(path) as run:
        message = run.events["message"][0]
        assert message == "é" * 128 and len(message.encode()) == 256
        assert run.events["sample_index"][0] == -1 and np.isnan(run.events["t"][0])


def test_open_run_with_repair_leaves_a_finished_file_alone(tmp_path):
    path = tmp_path / "run.h5"
    _write(path, n_blocks=1)
    before = path.read_bytes()
    with rf.open_run(path, repair=True) as run:
        assert run.status == "completed"
    assert path.read_bytes() == before
