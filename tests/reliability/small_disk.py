"""A disk that fills up: a tmpfs of a given size when this process may mount one (root), else a file-size
limit (RLIMIT_FSIZE, so writes past it fail with EFBIG) applied to the child process that writes."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


class SmallDisk:
    def __init__(self, where: Path, size: int) -> None:
        self.path = where
        self.size = size
        where.mkdir(parents=True, exist_ok=True)
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                           capture_output=True, text=True) if os.geteuid() == 0 else None
        self.mounted = r is not None and r.returncode == 0
        self.kind = "tmpfs" if self.mounted else "RLIMIT_FSIZE"

    def _limit(self) -> None:
        if not self.mounted:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (self.size, self.size))

    def hilbench(self, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
        """Run the CLI as a separate process writing to this disk."""
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        return subprocess.run([sys.executable, "-m", "hilbench", *args], capture_output=True, text=True,
                              timeout=timeout, preexec_fn=self._limit, env=env, cwd=self.path)

    def fill(self) -> None:
        """Take every free byte (tmpfs only; under RLIMIT_FSIZE each file is already capped)."""
        if self.mounted:
            with open(self.path / "ballast", "wb") as fh:
                try:
                    while True:
                        fh.write(b"\0" * 65536)
                        fh.flush()
                except OSError:
                    pass

    def close(self) -> None:
        if self.mounted:
            subprocess.run(["umount", "-l", str(self.path)], capture_output=True)
