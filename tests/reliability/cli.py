"""Running the ``hilbench`` CLI as a separate process, as an operator would."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def hilbench(*args: str, timeout: float = 120, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hilbench", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env=ENV, cwd=cwd)


def start(*args: str, cwd=None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "hilbench", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=ENV, cwd=cwd)


def one_line_error(proc: subprocess.CompletedProcess) -> str:
    """The single stderr line of a refused command (exit 2, no traceback)."""
    assert proc.returncode == 2, (proc.returncode, proc.stdout[-1000:], proc.stderr[-2000:])
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    return lines[0]


def wait_for_samples(path: Path, n: int, timeout: float = 60.0, proc: subprocess.Popen | None = None) -> int:
    """Wait until the live run file at ``path`` holds ``n`` flushed samples; returns how many it holds.

    With ``proc`` (the process writing it), fail at once, with its output and the file's events, when it ends
    first: a run that died early is reported as what it is, not as a slow start."""
    from hilbench.common.runfile import RunFileError, open_run

    deadline = time.monotonic() + timeout
    have = 0
    while time.monotonic() < deadline:
        time.sleep(0.1)
        if proc is not None and proc.poll() is not None:
            stdout, stderr = proc.communicate()
            raise AssertionError(f"{path}: the run ended (exit {proc.returncode}) with {have} samples flushed, "
                                 f"before {n}; events {run_events(path)}; stdout {stdout[-1000:]!r}; stderr "
                                 f"{stderr[-2000:]!r}")
        if not path.exists():
            continue
        try:
            with open_run(path) as run:
                have = run.refresh()
        except RunFileError:
            continue
        if have >= n:
            return have
    raise TimeoutError(f"{path}: {have} samples after {timeout} s, waited for {n}")


def run_events(path: Path) -> list[tuple[str, str]]:
    """The (kind, message) events of the run file at ``path`` (for a failing test's message); [] when it
    cannot be read."""
    from hilbench.common.runfile import RunFileError, open_run

    try:
        with open_run(path) as run:
            return [(str(e["kind"]), str(e["message"])) for e in run.events]
    except (RunFileError, OSError):
        return []
