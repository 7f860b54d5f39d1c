"""Files an analysis writes (figures, reports): an existing file is replaced only by an atomic rename of a complete
new one. The one implementation of that rule: ``bench.outputs`` (every command's output) uses it too."""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from hilbench.analysis.errors import AnalysisError

#: 2: say every file written on standard error (the CLI's -v sets it through bench.outputs)
verbosity = 1


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``target`` (same folder, same suffix); when the block ends without an
    exception, flush it to disk and rename it onto ``target`` in one step. Otherwise remove it and leave
    ``target`` untouched."""
    target = Path(target)
    folder = target.parent if str(target.parent) else Path(".")
    if target.is_dir():
        raise AnalysisError(f"{target} is a folder; give a file name")
    if not folder.is_dir():
        raise AnalysisError(f"{target}: folder {folder} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=f".tmp{target.suffix}", dir=folder)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as fh:
            os.fsync(fh.fileno())
        if target.exists():
            os.chmod(tmp_path, target.stat().st_mode & 0o7777)
        else:
            os.chmod(tmp_path, 0o666 & ~_umask())
        os.replace(tmp_path, target)
        if verbosity >= 2:
            print(f"hilbench: wrote {target}", file=sys.stderr, flush=True)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def save_figure(fig: Any, target: str | os.PathLike, **savefig_options: Any) -> Path:
    """``fig.savefig`` through :func:`atomic_path`; returns ``Path(target)``."""
    target = Path(target)
    with atomic_path(target) as tmp:
        fig.savefig(tmp, format=target.suffix.lstrip(".") or "png", **savefig_options)
    return target
