"""The results table of ``hilbench analyse``: one Parquet row per run and step.

Layout of a results folder::

    .analyse.lock            held by the one analysis writing here (bench.storage.folder_lock)
    results.parquet          the compacted table (sorted by campaign, run key, step)
    parts/<keys>-<n>.parquet the rows of one task (a chunk of runs), written by the worker that computed them
    set-aside/               tables or parts that could not be read, renamed out of the way (their rows are redone)

Every part and table is complete or absent: written beside as ``.<name>.<random>.tmp``, fsynced, renamed, and the
folder fsynced. A client or worker killed at any moment leaves good files and, at worst, a temp file that the next
analysis removes (it holds the lock, so no temp file there is anyone's work in progress). A file that cannot be
read (zero bytes, truncated, foreign, of an older layout) is moved to ``set-aside/`` with one line, never a folder
that blocks every later analysis.

A row's identity (:data:`KEY_COLUMNS`) is the campaign's uid (its index's, not its folder's name: a copied or
renamed campaign keeps its rows, two campaigns of one name never share them), the run key and the run's uid, the
run file's content hash, the step, the settings hash and the hilbench version. The table holds one current row per
campaign uid, run key and step (:data:`SLOT`).
"""

from __future__ import annotations

import hashlib
import os
import uuid
from array import array
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from hilbench.bench.campaign_analysis.steps import COLUMNS
from hilbench.common.units import AXIS_UNITS, axis_unit

TABLE_NAME = "results.parquet"
PARTS = "parts"
SET_ASIDE = "set-aside"
LOCK_NAME = ".analyse.lock"
#: a row's identity: the run (campaign uid, run key and run uid: two runs may hold the same bytes) and its
#: content, the step, the settings and the version that computed it
KEY_COLUMNS = ("campaign_uid", "key", "run_id", "content_hash", "step", "settings_hash", "hilbench_version")
#: one current row per slot: a newer row of a slot (new file, settings or version) replaces the older one
SLOT = ("campaign_uid", "key", "step")
#: columns every row has, with their Arrow types and units
BASE_COLUMNS: dict[str, tuple[str, str]] = {
    "campaign": ("string", ""), "campaign_uid": ("string", ""),
    "folder": ("string", ""), "run_id": ("string", ""), "key": ("string", ""), "axis": ("string", ""),
    "name": ("string", ""), "repeat": ("int64", "1"), "protocol": ("string", ""), "file": ("string", ""),
    "start_time": ("string", "ISO 8601 UTC"), "operator": ("string", ""), "environment": ("string", "JSON"),
    "ambient": ("float64", "degC"), "load": ("float64", "kg"),
    "step": ("string", ""), "status": ("string", ""), "error": ("string", ""),
    "content_hash": ("string", "sha256"), "settings_hash": ("string", "sha256"), "hilbench_version": ("string", ""),
    # the run file's size, mtime, ctime (ns) and inode when it was hashed: a file whose stat is unchanged is not
    # read again on resume (a copy, a rename or a swap changes the ctime, so it is hashed again)
    "file_stat": ("string", "size:mtime_ns:ctime_ns:inode"),
}
ALL_COLUMNS = {**BASE_COLUMNS, **COLUMNS}
_TYPES = {"string": pa.string(), "float64": pa.float64(), "int64": pa.int64()}


def column_units(axis: str = "rotary") -> dict[str, str]:
    """The unit of every column in a row of a run on ``axis``: a column of an axis quantity follows it."""
    return {name: axis_unit(unit, axis) if unit in AXIS_UNITS[axis] else unit
            for name, (_kind, unit) in ALL_COLUMNS.items()}


def _metadata(unit: str) -> dict[str, str]:
    """A column's Parquet metadata: its unit, and for an axis quantity the linear unit and the column it follows."""
    if unit not in AXIS_UNITS["rotary"]:
        return {"unit": unit}
    return {"unit": axis_unit(unit, "rotary"), "unit_linear": axis_unit(unit, "linear"), "unit_follows": "axis"}


SCHEMA = pa.schema([pa.field(name, _TYPES[kind], metadata=_metadata(unit)) for name, (kind, unit) in
                    ALL_COLUMNS.items()])
ORDER = ("campaign", "key", "step")


def row_key(row: dict[str, Any]) -> tuple:
    return tuple(row.get(k) for k in KEY_COLUMNS)


def slot_of(row: dict[str, Any]) -> tuple:
    return tuple(row.get(k) for k in SLOT)


_NAMES = frozenset(ALL_COLUMNS)
#: the most bytes of text in one chunk of a column (Arrow's 32-bit offsets); a column of more has several chunks
TEXT_CHUNK = 2**31 - 1


def to_table(rows: Iterable[dict[str, Any]]) -> pa.Table:
    """Rows (dicts; missing columns null, unknown ones refused) as a table of :data:`SCHEMA`: float columns hold
    ``float(v)``, int64 ones ``int(v)``, text ones str (valid UTF-8); one line naming the column and run otherwise.

    Each column is made from its buffers (the values packed by the standard library's ``array``, the validity bits
    by numpy), not by ``pa.array``: that one imports pandas when pandas is installed (it asks whether the values
    are a pandas object), 0.17-0.26 s of CPU in every process that writes a part. The table is the one ``pa.array``
    made, bit for bit (tests/bench/campaign_analysis/test_table_build.py), in 0.9x its CPU on 16 or 800 rows."""
    rows = list(rows)
    for row in rows:
        if not _NAMES.issuperset(row):
            unknown = set(row) - _NAMES
            raise KeyError(f"result columns not in the table schema: {', '.join(sorted(unknown))}")
    try:
        columns = [_column(kind, [row.get(name) for row in rows]) for name, (kind, _unit) in ALL_COLUMNS.items()]
    except (TypeError, ValueError, OverflowError):  # say which column of which run
        _refuse(rows)
        raise
    return pa.Table.from_arrays(columns, schema=SCHEMA)


def _column(kind: str, values: list[Any]) -> pa.Array | pa.ChunkedArray:
    """One column's values (None: null) as an Arrow array of ``kind``'s type."""
    n = len(values)
    if values.count(None) == n:
        return pa.nulls(n, _TYPES[kind])
    if kind == "float64":
        data = array("d", [0.0 if v is None else float(v) for v in values])
    elif kind == "int64":
        data = array("q", [0 if v is None else int(v) for v in values])
    else:
        return _text(values)
    return pa.Array.from_buffers(_TYPES[kind], n, [_validity(values), pa.py_buffer(data)])


def _validity(values: list[Any]) -> pa.Buffer | None:
    """Arrow's validity bitmap (bit i of byte i // 8, least significant first), None when nothing is null."""
    if None not in values:
        return None
    return pa.py_buffer(np.packbits(np.array([v is not None for v in values], dtype=bool), bitorder="little"))


def _text(values: list[Any]) -> pa.Array | pa.ChunkedArray:
    """A text column: the UTF-8 bytes end to end and their offsets, in chunks of at most :data:`TEXT_CHUNK` bytes."""
    texts = ["" if v is None else v for v in values]
    joined = "".join(texts)  # refuses what is not text
    data = joined.encode("utf-8")  # refuses a lone surrogate
    # one byte per character when all is ASCII (one comparison), else each text's own UTF-8 length
    sizes = map(len, texts) if len(data) == len(joined) else (len(t.encode("utf-8")) for t in texts)
    ends = np.fromiter(sizes, dtype=np.int64, count=len(texts)).cumsum()
    chunks, start, base = [], 0, 0
    while start < len(values):
        stop = int(np.searchsorted(ends, base + TEXT_CHUNK, side="right"))
        if stop == start:
            raise ValueError(f"a text of more than {TEXT_CHUNK} bytes (what one Arrow string holds)")
        offsets = np.concatenate(([0], ends[start:stop] - base)).astype(np.int32)
        chunk = data if start == 0 and stop == len(values) else memoryview(data)[base:ends[stop - 1]]
        chunks.append(pa.Array.from_buffers(pa.string(), stop - start, [
            _validity(values[start:stop]), pa.py_buffer(offsets), pa.py_buffer(chunk)]))
        start, base = stop, int(ends[stop - 1])
    return chunks[0] if len(chunks) == 1 else pa.chunked_array(chunks, type=pa.string())


def _refuse(rows: list[dict[str, Any]]) -> None:
    """Raise one line naming the column and the run of a value Arrow cannot hold (of the kind ``pa.array`` raised
    for it: a text column of another type, an integer outside int64, text with a lone surrogate, or too long)."""
    for row in rows:
        for name, v in row.items():
            if v is None:
                continue
            where = f"result column {name!r} of {row.get('key')!r} (step {row.get('step')!r})"
            kind = ALL_COLUMNS[name][0]
            if kind == "int64" and not -2**63 <= int(v) < 2**63:
                raise OverflowError(f"{where}: {int(v)} is outside the int64 range")
            if kind != "string":
                continue
            if not isinstance(v, str):
                raise TypeError(f"{where}: {type(v).__name__} {v!r} where text is expected")
            try:
                size = len(v.encode("utf-8"))
            except UnicodeEncodeError as exc:
                raise ValueError(f"{where}: text {v!r} is not valid UTF-8 (a lone surrogate at {exc.start}, e.g. "
                                 "an undecodable file name)") from None
            if size > TEXT_CHUNK:
                raise ValueError(f"{where}: a text of {size} bytes, more than one Arrow string holds ({TEXT_CHUNK})")


def fsync_folder(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _write_atomic(table: pa.Table, target: Path) -> None:
    """``target`` complete or absent after any crash: written beside, fsynced, renamed, the folder fsynced."""
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        with open(tmp, "wb") as fh:
            pq.write_table(table, fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
        fsync_folder(target.parent)
    finally:
        if tmp.exists():
            tmp.unlink()


def part_name(rows: list[dict[str, Any]]) -> str:
    """A part's file name from its rows' keys alone: no campaign or run name in it (those may be any length)."""
    keys = hashlib.sha256(repr(sorted(repr(row_key(r)) for r in rows)).encode()).hexdigest()[:24]
    return f"{keys}-{len(rows)}.parquet"


def write_part(results: str | os.PathLike, rows: list[dict[str, Any]]) -> Path:
    """Write the rows of one task as one part of the results folder (atomic, durable); a worker calls this."""
    parts = Path(results) / PARTS
    parts.mkdir(parents=True, exist_ok=True)
    target = parts / part_name(rows)
    _write_atomic(to_table(rows), target)
    return target


class ResultsFolder:
    """The results folder: rows already there, leftovers, set-aside files, compaction. Used by the one client
    that holds the folder's lock."""

    def __init__(self, path: str | os.PathLike, say: Callable[[str], None] = print):
        self.path = Path(path)
        self.parts = self.path / PARTS
        self.say = say

    def clean_leftovers(self) -> int:
        """Remove the temp files of killed writes (only under the lock: none is anyone's write in progress)."""
        n = 0
        for folder in (self.path, self.parts):
            for f in folder.glob(".*.tmp") if folder.is_dir() else ():
                f.unlink(missing_ok=True)
                n += 1
        return n

    def files(self) -> list[Path]:
        table = self.path / TABLE_NAME
        return ([table] if table.exists() else []) + sorted(self.parts.glob("*.parquet") if self.parts.is_dir()
                                                             else [])

    def _read(self, f: Path) -> list[dict[str, Any]] | None:
        """The rows of one file, or None after setting an unreadable one aside (one line)."""
        try:
            table = pq.ParquetFile(f).read()  # not read_table: its dataset layer costs twice the CPU per file
            missing = [k for k in KEY_COLUMNS if k not in table.column_names]
            if missing:
                raise ValueError(f"no {', '.join(missing)} column (written by an older hilbench)")
            return table.to_pylist()
        except (OSError, ValueError, pa.ArrowException) as exc:
            aside = self.path / SET_ASIDE
            aside.mkdir(exist_ok=True)
            n = 1
            while (target := aside / f"{f.name}.{n}").exists():
                n += 1
            os.replace(f, target)
            why = " ".join(str(exc).split())[:200]
            self.say(f"{f}: unreadable ({why}); set aside as {target}, its rows are analysed again")
            return None

    def read_rows(self, files: list[Path] | None = None) -> dict[tuple, dict[str, Any]]:
        """Rows by key of ``files`` (default: the table and every part; a part wins over the table)."""
        rows: dict[tuple, dict[str, Any]] = {}
        for f in self.files() if files is None else files:
            for row in self._read(f) or ():
                rows[row_key(row)] = row
        return rows

    def add(self, rows: list[dict[str, Any]]) -> Path:
        """Write rows the client made itself (runs that were not analysed, a run that killed its worker)."""
        return write_part(self.path, rows)

    def compact(self, rows: dict[tuple, dict[str, Any]], current: dict[tuple, dict[str, Any]],
                drop: set[tuple] = frozenset()) -> Path:
        """Write ``rows`` as ``results.parquet`` (sorted; atomic), then remove the parts.

        ``current``: row key -> fields to refresh (the campaign's folder and name as of now: a renamed campaign's
        reused rows say where it is). A row of a slot that has a current row, but is not current itself (other
        settings, version or file), is dropped: one row per campaign uid, run key and step. ``drop``: slots
        (campaign uid, run key) of runs that their campaign no longer plans; their rows go."""
        fresh = {slot_of(rows[k]) for k in current if k in rows}
        out = []
        for k, r in rows.items():
            if k in current:
                out.append({**r, **current[k]})
            elif slot_of(r) not in fresh and (r.get("campaign_uid"), r.get("key")) not in drop:
                out.append(r)
        out.sort(key=lambda r: tuple(str(r.get(k) or "") for k in ORDER) + tuple(str(v) for v in row_key(r)))
        self.path.mkdir(parents=True, exist_ok=True)
        target = self.path / TABLE_NAME
        _write_atomic(to_table(out), target)
        if self.parts.is_dir():
            for f in self.parts.glob("*.parquet"):
                f.unlink()
            self.clean_leftovers()
            try:
                self.parts.rmdir()
            except OSError:  # something else in there: harmless, later analyses ignore what is not a part
                pass
        return target
