"""Where outputs are written: never onto an input of the running command, and an existing file is replaced only by an
atomic rename of a complete new one. The one implementation of these rules: every command
(``bench.storage.outputs``) and every analysis report (figures, summaries) writes through it.

- :func:`atomic_path` yields a temporary file beside the target; the target is replaced by ``os.replace`` only
  after the writer returned and the data reached the disk (``fsync``). A failure on the way (disk full, a bad
  value met half-way, Ctrl-C) leaves the old file as it was and removes the temporary one;
- an output path that exists and is not a regular file is never renamed over: a character device
  (``/dev/null``, a terminal) or a FIFO is written into, as a shell redirection would; a block device or a
  socket is refused in one line;
- every JSON document is strict JSON (RFC 8259): NaN and infinities are written as ``null`` (:func:`dumps`).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import stat
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from hilbench.analysis.errors import AnalysisError

#: 2: say every file written on standard error (the CLI sets it from -q/-v, as bench.storage.outputs.verbosity)
verbosity = 1


class OutputError(AnalysisError):
    """An output path that cannot be written as asked (the message names it and why, in one line)."""


# The inputs the running command declared (refuse_inputs): every write through atomic_path checks its target
# against them, so an output the command only names late (compare's models/FAMILY.json, a plot) is never one of
# its inputs either. The CLI clears it before each command (begin_command).
declared_inputs: list[Path] = []


def begin_command() -> None:
    """Forget the inputs of a previous command of this process (the CLI calls it before each command)."""
    declared_inputs.clear()


def same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def _written_in_place(target: Path) -> bool:
    """True when ``target`` exists and is a character device or a FIFO: it is written into, never replaced
    (renaming a regular file onto /dev/null as root would replace the device). Raises :class:`OutputError` for
    a folder, a block device or a socket."""
    try:
        mode = os.stat(target).st_mode  # follows a symlink: a link to /dev/null is /dev/null
    except FileNotFoundError:
        return False
    except OSError as exc:
        raise OutputError(f"{target}: cannot use as an output ({exc.strerror})") from None
    if stat.S_ISREG(mode):
        return False
    if stat.S_ISDIR(mode):
        raise OutputError(f"{target} is a folder; give a file name")
    if stat.S_ISCHR(mode) or stat.S_ISFIFO(mode):
        return True
    kind = "a block device" if stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode) else "not a regular file"
    raise OutputError(f"{target} is {kind}; an output is a regular file, a character device or a FIFO")


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``target`` (same folder, same suffix); when the block ends without an
    exception, flush it to disk and rename it onto ``target`` in one step. Otherwise remove it and leave
    ``target`` untouched. A ``target`` that is a character device or a FIFO is yielded itself: the writer
    writes into it, nothing is renamed."""
    target = Path(target)
    folder = target.parent if str(target.parent) else Path(".")
    for inp in declared_inputs:
        if same_file(target, inp):
            raise OutputError(f"{target} is an input of this command ({inp}); an output never overwrites an input")
    if _written_in_place(target):
        yield target
        if verbosity >= 2:
            print(f"hilbench: wrote into {target}", file=sys.stderr, flush=True)
        return
    if not folder.is_dir():
        raise OutputError(f"{target}: folder {folder} does not exist")
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


def json_safe(value: Any) -> Any:
    """A copy of ``value`` that strict JSON can hold: NaN and infinities (Python or numpy) become None, numpy
    scalars and arrays become Python numbers and lists, tuples become lists."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if type(value).__module__ == "numpy":  # numpy scalars and arrays, without importing numpy here
        if hasattr(value, "tolist"):
            return json_safe(value.tolist())
    return value


def dumps(document: Any, indent: int | None = 1, **dump_options: Any) -> str:
    """Strict JSON text of ``document`` (:func:`json_safe`, then ``allow_nan=False``)."""
    dump_options.pop("allow_nan", None)  # strict everywhere: NaN is null, never the bare token NaN
    return json.dumps(json_safe(document), indent=indent, allow_nan=False, **dump_options)


def save_figure(fig: Any, target: str | os.PathLike, **savefig_options: Any) -> Path:
    """``fig.savefig`` through :func:`atomic_path`; returns ``Path(target)``."""
    target = Path(target)
    with atomic_path(target) as tmp:
        fig.savefig(tmp, format=target.suffix.lstrip(".") or "png", **savefig_options)
    return target
