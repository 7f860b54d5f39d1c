"""SIGKILL a writer process mid-run: the file opens with bench, holds every sample up to its last flush,
and says 'crashed'; `hilbench show --repair` marks it so in the file and plain HDF5 opens it again."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import h5py
import numpy as np
import pytest

from hilbench.bench.cli import main as bench_main
from hilbench.common import runfile as rf

FS = 10_000.0

WRITER = textwrap.dedent(
    """
    import sys
    import numpy as np
    from hilbench.common.runfile import RunWriter

    fs = float(sys.argv[2])
    with RunWriter(sys.argv[1], sample_rate=fs, protocol_name="crash-test", operator="pytest") as w:
        w.add_event("info", "started")
        start, reported = 0, -1
        while True:
            k = np.arange(start, start + 250)
            w.append({
                "sample_index": k, "t": k / fs, "current_cmd": np.sin(1e-3 * k), "current": np.cos(1e-3 * k),
                "torque": 0.05 * np.sin(1e-3 * k), "position": 1e-4 * k, "counts": (7 * k) % 100_003,
            })
            start += 250
            if w.n_flushed != reported:
                reported = w.n_flushed
                print(reported, flush=True)
    """
)


def _expected(n: int) -> dict[str, np.ndarray]:
    k = np.arange(n)
    return {
        "sample_index": k,
        "t": k / FS,
        "current_cmd": np.sin(1e-3 * k),
        "current": np.cos(1e-3 * k),
        "torque": 0.05 * np.sin(1e-3 * k),
        "position": 1e-4 * k,
        "counts": (7 * k) % 100_003,
    }


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
@pytest.mark.parametrize("extra_delay", [0.0, 0.013])
def test_sigkill_mid_write_keeps_flushed_samples_and_says_crashed(tmp_path, capsys, extra_delay):
    path = tmp_path / "run.h5"
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(path), str(FS)],
        stdout=subprocess.PIPE,
        text=True,
        cwd=os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
    )
    try:
        flushed = 0
        deadline = time.monotonic() + 60
        while flushed < 100_000:  # 10 s of device time, 20 flushes of 0.5 s
            line = proc.stdout.readline()
            assert line, "writer exited early"
            flushed = int(line)
            assert time.monotonic() < deadline
        # a live reader sees a running file while the writer keeps writing
        with rf.open_run(path) as live:
            assert live.status == "running" and live.writer_alive
            assert live.n_samples >= flushed
        time.sleep(extra_delay)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        assert proc.returncode == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()

    # bench opens it as is and reports crashed
    assert bench_main(["show", str(path)]) == 0
    out = capsys.readouterr().out
    assert "status     crashed" in out and "--repair" in out

    with rf.open_run(path) as run:
        assert run.status == "crashed" and run.stored_status == "running" and not run.writer_alive
        n = run.n_samples
        assert n >= flushed  # nothing reported as flushed is lost
        assert n % 5000 == 0  # only whole chunks of 0.5 s reach the disk before finish()
        expected = _expected(n)
        for name in rf.DEVICE_CHANNELS:
            np.testing.assert_array_equal(run.channel(name), expected[name], err_msg=name)
        assert run.events["kind"][0] == "info"

    # a truncated copy of the crashed file fails fast with one clear error (no SWMR retry loop)
    cut = tmp_path / "cut.h5"
    cut.write_bytes(path.read_bytes()[: os.path.getsize(path) // 2])
    t0 = time.monotonic()
    with pytest.raises(rf.RunFileError, match="truncated"):
        rf.open_run(cut)
    assert time.monotonic() - t0 < 5.0

    # plain HDF5 refuses the file until the write flags are cleared (HDF5 1.10+ behaviour)
    with pytest.raises(OSError):
        h5py.File(path, "r")

    assert bench_main(["show", str(path), "--repair"]) == 0
    out = capsys.readouterr().out
    assert "status     crashed (marked in the file)" in out
    assert not os.path.exists(rf.lock_path(path))
    with h5py.File(path, "r") as f:
        assert f.attrs["status"] == "crashed" and f.attrs["end_time"] != ""
        assert f["samples/t"].shape == (n,)
        assert f["events"][-1]["kind"] == b"crash"
    # repairing again changes nothing
    assert rf.repair(path) == "crashed"
    with rf.open_run(path) as run:
        assert run.status == "crashed" and run.n_samples == n and len(run.events) == 2
