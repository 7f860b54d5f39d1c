"""bench.storage.folder_lock: one writer per folder (campaign folders, results folders)."""

import os
import signal
import subprocess
import sys

import pytest

from hilbench.bench.storage.folder_lock import folder_lock


class Busy(Exception):
    pass


def test_a_live_holder_is_named_and_a_killed_ones_lock_is_taken_over_saying_so(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", f"""
import sys, time
from pathlib import Path
from hilbench.bench.storage.folder_lock import folder_lock
with folder_lock(Path({str(tmp_path)!r}), ".lock", RuntimeError, str):
    print("held", flush=True)
    time.sleep(600)
"""], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(Busy, match=f"^pid {holder.pid}$"), folder_lock(tmp_path, ".lock", Busy,
                                                                            lambda pid: f"pid {pid}"):
            pass
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    said: list[str] = []
    with folder_lock(tmp_path, ".lock", Busy, str, said.append):  # the kernel dropped the dead holder's flock
        assert (tmp_path / ".lock").read_text() == f"{os.getpid()}\n"
    assert len(said) == 1 and f"taking over the lock of pid {holder.pid}" in said[0]
    assert not (tmp_path / ".lock").exists()


def test_a_lock_file_that_is_a_symlink_is_refused(tmp_path):
    (tmp_path / ".lock").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(Busy, match="symlink"), folder_lock(tmp_path, ".lock", Busy, str):
        pass
    assert not (tmp_path / "elsewhere").exists()
