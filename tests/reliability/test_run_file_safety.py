"""#12 items 6, 7 and 8 (run files): the old file survives a failed replacement; a kill at any moment of
creation leaves nothing or a repairable run; the lock never follows a planted link; a file claiming more
samples than the stated bound is refused before anything is allocated."""

import os
import resource
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.record import load_record
from hilbench.common.runfile import MAX_SAMPLES, RunFileError, RunWriter, open_run, repair
from tests.reliability.cli import ENV, hilbench, one_line_error


def _small_run(path, n=1000, **kw):
    with RunWriter(path, sample_rate=1000.0, channels=("sample_index", "t", "position"), **kw) as w:
        w.append({"sample_index": np.arange(n), "t": np.arange(n) / 1000, "position": np.sin(np.arange(n))})
    with open_run(path) as r:
        return r.uid


@pytest.mark.usefixtures("starts_devices")  # a real-time simulator: the serial part
def test_overwrite_that_fails_on_metadata_keeps_the_old_file(tmp_path):
    old = tmp_path / "run.h5"
    uid = _small_run(old)
    before = old.read_bytes()
    # a non-UTF-8 --notes (argv bytes decoded with surrogateescape) fails the new file's metadata
    proc = subprocess.run([sys.executable, "-m", "hilbench", "run", "identify", "--duration", "1", "--quiet",
                           "--overwrite", "-o", os.fsencode(old), "--notes", b"caf\xe9"], capture_output=True,
                          text=True, env=ENV, timeout=60)
    assert "notes is not valid UTF-8" in one_line_error(proc)
    assert old.read_bytes() == before
    with open_run(old) as r:
        assert r.uid == uid and r.status == "completed"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.h5"]
    with pytest.raises(RunFileError, match="not valid UTF-8"):
        _small_run(old, overwrite=True, notes="caf\udce9")
    assert old.read_bytes() == before


def test_overwrite_replaces_only_with_a_complete_file(tmp_path):
    path = tmp_path / "run.h5"
    _small_run(path)
    with RunWriter(path, sample_rate=1000.0, overwrite=True, protocol_arrays={"setpoints": np.ones(10)}) as w:
        with open_run(path) as live:  # the new file is at the path, complete and readable, from the start
            assert live.uid == w.uid and live.status == "running"
            np.testing.assert_array_equal(live.protocol_array("setpoints"), np.ones(10))


CREATE = r"""
import sys, numpy as np
from hilbench.common.runfile import RunWriter
u = np.random.default_rng(0).normal(size=4_000_000)  # 32 MB of setpoints: seconds to compress and write
print("go", flush=True)
RunWriter(sys.argv[1], sample_rate=10000.0, protocol_arrays={"setpoints": u})
print("done", flush=True)
import time; time.sleep(60)
"""


def test_sigkill_at_any_moment_of_creation_leaves_nothing_or_a_repairable_run(tmp_path):
    outcomes = {"absent": 0, "repaired": 0}
    for i, delay in enumerate(np.linspace(0.0, 1.2, 9)):
        path = tmp_path / f"k{i}.h5"
        proc = subprocess.Popen([sys.executable, "-c", CREATE, str(path)], stdout=subprocess.PIPE, env=ENV)
        assert proc.stdout.readline() == b"go\n"
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
        if not path.exists():
            outcomes["absent"] += 1
            continue
        assert repair(path) == "crashed"
        with open_run(path) as run:
            assert run.status == "crashed" and run.n_samples == 0
        outcomes["repaired"] += 1
    print(f"SIGKILL during creation: {outcomes}")
    assert outcomes["repaired"] >= 1  # the kills did land after the file appeared
    # a new writer of the same path clears what a killed one left half-made
    RunWriter(tmp_path / "k0.h5", sample_rate=10.0, overwrite=True).finish()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".k0.h5.")]


@pytest.mark.parametrize("link", ["symlink", "link"])
def test_the_lock_file_never_follows_a_planted_link(tmp_path, link):
    victim = tmp_path / "victim"
    victim.write_text("precious\n")
    out = tmp_path / "out.h5"
    getattr(os, link)(victim, str(out) + ".lock")
    csv = tmp_path / "in.csv"
    csv.write_text("t,position,torque\n0,0,0\n0.001,1,1\n0.002,2,2\n")
    line = one_line_error(hilbench("import", "csv", csv, "-o", out))
    assert "lock file" in line
    assert victim.read_text() == "precious\n"
    assert not out.exists()


def _claiming(path, n_claimed):
    _small_run(path)
    with h5py.File(path, "r+") as f:
        for ds in f["samples"].values():
            ds.resize((n_claimed,))
    return os.path.getsize(path)


def _address_space_limit():
    resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))


def test_a_small_file_claiming_2_to_the_33_samples_is_refused(tmp_path):
    path = tmp_path / "liar.h5"
    size = _claiming(path, 2**33)
    assert size < 64 << 10
    with pytest.raises(RunFileError, match=f"above the bound of {MAX_SAMPLES}"):
        open_run(path)
    with pytest.raises(AnalysisError, match="MAX_SAMPLES"):
        load_record(path)
    for cmd in (["show", path],):  # in a process capped at 3 GiB of address space
        proc = subprocess.run([sys.executable, "-m", "hilbench", *map(str, cmd)], capture_output=True, text=True,
                              env=ENV, timeout=60, preexec_fn=_address_space_limit)
        assert "above the bound of 268435456" in one_line_error(proc)
