"""#12 item 4: a disk that fills during a run, a repair and an import. The run ends 'failed' with every
flushed sample intact (bit-identical to the same run on a roomy disk: the lockstep simulator is
deterministic) and nothing made up; nothing segfaults; no lock or partial file is left behind."""

import numpy as np
import pytest

from hilbench.common.runfile import open_run

RUN = ["run", "identify", "--device", "sim://?pacing=lockstep", "--duration", "20", "--quiet"]
#: real-time pacing, so that a kill lands mid-run (a lockstep run of 20 s can complete between two polls)
RUN_REALTIME = ["run", "identify", "--device", "sim://", "--duration", "20", "--quiet"]


def _one_line_error(proc) -> str:
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    return lines[0]


def test_run_on_a_filling_disk_ends_failed_with_the_flushed_samples_intact(small_disk, tmp_path):
    roomy = small_disk(64 << 20, "roomy")
    ref = roomy.hilbench(*RUN, "-o", "ref.h5")
    assert ref.returncode == 0, ref.stderr
    full = small_disk(4 << 20, "full")
    proc = full.hilbench(*RUN, "-o", "w.h5")
    line = _one_line_error(proc)
    print(f"[{full.kind}] {line}")
    assert "failed" in line and "flushed samples kept" in line
    assert sorted(p.name for p in full.path.iterdir()) == ["w.h5"]  # no lock, no partial file
    with open_run(full.path / "w.h5") as run, open_run(roomy.path / "ref.h5") as reference:
        assert run.status == "failed"
        n = run.n_samples
        assert 0 < n < reference.n_samples and n % 5000 == 0  # whole 0.5 s chunks only
        index = run.channel("sample_index")
        np.testing.assert_array_equal(index, np.arange(n))  # no zeros invented at the end
        for name in run.channels:
            np.testing.assert_array_equal(run.channel(name), reference.channel(name, 0, n), err_msg=name)
        events = run.events
        assert events["kind"][-1] == "error" and "write failed" in events["message"][-1]
    shown = full.hilbench("show", "w.h5", "--repair")
    assert shown.returncode == 0, shown.stderr
    assert "status     failed" in shown.stdout


@pytest.mark.usefixtures("starts_devices")  # a real-time simulator: the serial part
def test_repair_and_import_on_a_full_disk(small_disk, tmp_path):
    import signal
    import subprocess
    import sys
    import time

    disk = small_disk(8 << 20, "full")
    if not disk.mounted:
        import pytest

        pytest.skip("filling a disk needs a tmpfs (root); the write-failure path is covered by the test above")
    # a run killed mid-way: a crashed file on the disk
    host = subprocess.Popen([sys.executable, "-m", "hilbench", *RUN_REALTIME, "-o", str(disk.path / "c.h5")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        time.sleep(0.2)
        try:
            with open_run(disk.path / "c.h5") as r:
                r.refresh()
                if r.n_samples >= 10000:
                    break
        except Exception:
            pass
    host.send_signal(signal.SIGKILL)
    host.wait()
    disk.fill()
    repaired = disk.hilbench("show", "c.h5", "--repair")
    assert repaired.returncode in (0, 2), repaired  # never a signal (segfault)
    if repaired.returncode == 2:
        print(f"repair on a full disk: {_one_line_error(repaired)}")
    shown = disk.hilbench("show", "c.h5")
    assert shown.returncode == 0, shown.stderr  # the file still reads
    assert "status     crashed" in shown.stdout
    csv = tmp_path / "in.csv"
    t = np.arange(200000) / 1000
    np.savetxt(csv, np.column_stack([t, np.sin(t), np.cos(t)]), delimiter=",", header="t,position,torque",
               comments="")
    imported = disk.hilbench("import", "csv", str(csv), "-o", "imp.h5")
    print(f"import on a full disk: {_one_line_error(imported)}")
    assert not (disk.path / "imp.h5").exists()
    left = sorted(p.name for p in disk.path.iterdir())
    assert left == ["ballast", "c.h5", "c.h5.lock"], left  # the killed run's lock stays until repaired


def test_setpoints_that_do_not_fit_end_the_new_file_failed(small_disk):
    """The file appears complete, then its (long) setpoint array does not fit: it says 'failed', it does not
    pretend to be a run in progress."""
    import pytest

    from hilbench.common.runfile import RunFileError, RunWriter

    disk = small_disk(2 << 20, "tiny")
    if not disk.mounted:
        pytest.skip("needs a tmpfs (root)")
    u = np.random.default_rng(1).normal(size=1_000_000)  # 8 MB that does not compress
    with pytest.raises(RunFileError, match="cannot write the protocol arrays.*the file says 'failed'"):
        RunWriter(disk.path / "big.h5", sample_rate=10000.0, protocol_arrays={"setpoints": u})
    with open_run(disk.path / "big.h5") as run:
        assert run.status == "failed" and run.n_samples == 0
    assert sorted(p.name for p in disk.path.iterdir()) == ["big.h5"]
