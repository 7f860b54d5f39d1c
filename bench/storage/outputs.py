"""Where commands write what they produce: never onto one of their inputs, and an existing file is replaced only
by an atomic rename of a complete new one.

Every command that writes an output (a JSON summary, a model file, a figure) goes through this module:

- :func:`refuse_inputs` rejects an output path that names one of the command's inputs (the same file, also
  through a symlink or a hard link), before anything is computed;
- :func:`atomic_path` yields a temporary file beside the target; the target is replaced by ``os.replace`` only
  after the writer returned and the data reached the disk (``fsync``). A failure on the way (disk full, a bad
  value met half-way, Ctrl-C) leaves the old file as it was and removes the temporary one;
- an output path that exists and is not a regular file is never renamed over: a character device
  (``/dev/null``, a terminal) or a FIFO is written into, as a shell redirection would; a block device or a
  socket is refused in one line (:func:`atomic_path`);
- every JSON document is strict JSON (RFC 8259): NaN and infinities are written as ``null``
  (:func:`write_json`), never as the bare ``NaN`` that standard parsers reject;
- ``-`` as a JSON path means standard output (:func:`write_json`); the command then prints its human-readable
  lines to standard error (:func:`say`) so that standard output stays valid JSON.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from hilbench.analysis.output_files import (  # noqa: F401  (the one implementation, re-exported)
    OutputError,
    atomic_path,
    begin_command,
    declared_inputs,
    dumps,
    json_safe,
    same_file,
    save_figure,
)
from hilbench.bench.errors import BenchError

STDOUT = "-"

# Verbosity for the whole process, set once by the CLI from -q/-v: 0 quiet, 1 normal, 2 verbose.
verbosity = 1


def refuse_inputs(outputs: dict[str, str | os.PathLike | None], inputs: Iterable[str | os.PathLike | None]) -> None:
    """Raise :class:`BenchError` if an output path (option name -> path) is one of ``inputs``, or is a folder
    that exists where a file is expected. ``None`` and ``-`` (standard output) are skipped."""
    ins = [Path(p) for p in inputs if p is not None and str(p) != STDOUT]
    declared_inputs.extend(p for p in ins if p not in declared_inputs)
    for option, out in outputs.items():
        if out is None or str(out) == STDOUT:
            continue
        path = Path(out)
        for inp in ins:
            if same_file(path, inp):
                raise BenchError(f"{option} {out} is an input of this command; an output never overwrites an "
                                 "input: choose another path")


def refuse_existing(option: str, target: str | os.PathLike | None, overwrite: bool) -> None:
    """Raise :class:`BenchError` if ``target`` (the value of ``option``) is a file that exists and ``overwrite``
    (``--overwrite``) was not given: every command that writes replaces an existing output only with
    --overwrite. Standard output (``-``) and what is not a regular file (``/dev/null``) are written as always."""
    if target is None or str(target) == STDOUT or overwrite:
        return
    if Path(target).is_file():
        raise BenchError(f"{target} exists; use --overwrite to replace it, or another {option}")


def write_text(target: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``target`` atomically, or to standard output if ``target`` is ``-``."""
    if str(target) == STDOUT:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
        sys.stdout.flush()
        return
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json(target: str | os.PathLike, document: Any, indent: int = 1, **dump_options: Any) -> None:
    """Serialise ``document`` completely first (strict JSON: NaN and infinities as null), then write it with
    :func:`write_text`: a value that JSON cannot encode fails before the old file is touched."""
    write_text(target, dumps(document, indent=indent, **dump_options) + "\n")


def say(message: str, json_target: str | os.PathLike | None = None, level: int = 1) -> None:
    """Print a human-readable line unless -q (``level`` 2: only with -v). If the command's JSON goes to
    standard output, the line goes to standard error."""
    if verbosity < level:
        return
    stream = sys.stderr if json_target is not None and str(json_target) == STDOUT else sys.stdout
    print(message, file=stream, flush=True)
