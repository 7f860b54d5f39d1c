"""One writer per folder: an advisory ``flock`` on a lock file inside it, holding the owner's pid.

Used by ``hilbench campaign`` (the campaign folder) and ``hilbench analyse`` (the results folder). The kernel
drops a ``flock`` when its holder dies, however it dies, so a lock file left by a killed process is free to take:
it still names the dead pid, and the taker says it takes it over. A second live writer is refused at once, in one
line naming the holder's pid.
"""

from __future__ import annotations

import fcntl
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def folder_lock(folder: Path, name: str, error: type[Exception], busy: Callable[[str], str],
                say: Callable[[str], None] | None = None) -> Iterator[None]:
    """Hold ``folder/name`` exclusively for the ``with`` block. Raises ``error(busy(pid))`` when a live process
    holds it; ``say`` gets one line when a dead holder's lock is taken over."""
    lock = folder / name
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
        except OSError as exc:
            raise error(f"{lock}: cannot use the lock ({exc.strerror}; a symlink is refused)") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise error(busy(holder)) from None
        # the holder before us unlinks the file, then unlocks: a lock won on an unlinked file is no lock
        try:
            same = os.stat(lock, follow_symlinks=False).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    previous = os.pread(fd, 64, 0).decode(errors="replace").strip()
    if previous and say is not None:
        say(f"{lock}: taking over the lock of pid {previous}, which is gone (killed?)")
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    try:
        yield
    finally:
        os.unlink(lock)  # before unlocking: a waiter that opened this file sees it is gone (the check above)
        os.close(fd)
