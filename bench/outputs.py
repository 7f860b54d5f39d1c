"""Where commands write what they produce: never onto one of their inputs, and an existing file is replaced only
by an atomic rename of a complete new one.

Every command that writes an output (a JSON summary, a model file, a figure) goes through this module:

- :func:`refuse_inputs` rejects an output path that names one of the command's inputs (the same file, also
  through a symlink or a hard link), before anything is computed;
- :func:`atomic_path` yields a temporary file beside the target; the target is replaced by ``os.replace`` only
  after the writer returned and the data reached the disk (``fsync``). A failure on the way (disk full, a bad
  value met half-way, Ctrl-C) leaves the old file as it was and removes the temporary one;
- ``-`` as a JSON path means standard output (:func:`write_json`); the command then prints its human-readable
  lines to standard error (:func:`say`) so that standard output stays valid JSON.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from hilbench.bench.errors import BenchError

STDOUT = "-"

# Verbosity for the whole process, set once by the CLI from -q/-v: 0 quiet, 1 normal, 2 verbose.
verbosity = 1


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def refuse_inputs(outputs: dict[str, str | os.PathLike | None], inputs: Iterable[str | os.PathLike | None]) -> None:
    """Raise :class:`BenchError` if an output path (option name -> path) is one of ``inputs``, or is a folder
    that exists where a file is expected. ``None`` and ``-`` (standard output) are skipped."""
    ins = [Path(p) for p in inputs if p is not None and str(p) != STDOUT]
    for option, out in outputs.items():
        if out is None or str(out) == STDOUT:
            continue
        path = Path(out)
        for inp in ins:
            if _same_file(path, inp):
                raise BenchError(f"{option} {out} is an input of this command; an output never overwrites an "
                                 "input: choose another path")


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``target`` (same folder, same suffix); when the block ends without an
    exception, flush it to disk and rename it onto ``target`` in one step. Otherwise remove it and leave
    ``target`` untouched."""
    target = Path(target)
    folder = target.parent if str(target.parent) else Path(".")
    if target.is_dir():
        raise BenchError(f"{target} is a folder; give a file name")
    if not folder.is_dir():
        raise BenchError(f"{target}: folder {folder} does not exist")
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


def write_text(target: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``target`` atomically, or to standard output if ``target`` is ``-``."""
    if str(target) == STDOUT:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
        sys.stdout.flush()
        return
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json(target: str | os.PathLike, document: Any, indent: int = 1, **dump_options: Any) -> None:
    """Serialise ``document`` completely first, then write it with :func:`write_text`: a value that JSON
    cannot encode fails before the old file is touched."""
    write_text(target, json.dumps(document, indent=indent, **dump_options) + "\n")


def save_figure(fig: Any, target: str | os.PathLike, **savefig_options: Any) -> Path:
    """``fig.savefig`` through :func:`atomic_path`; returns ``Path(target)``."""
    target = Path(target)
    with atomic_path(target) as tmp:
        fig.savefig(tmp, format=target.suffix.lstrip(".") or "png", **savefig_options)
    return target


def say(message: str, json_target: str | os.PathLike | None = None, level: int = 1) -> None:
    """Print a human-readable line unless -q (``level`` 2: only with -v). If the command's JSON goes to
    standard output, the line goes to standard error."""
    if verbosity < level:
        return
    stream = sys.stderr if json_target is not None and str(json_target) == STDOUT else sys.stdout
    print(message, file=stream, flush=True)
