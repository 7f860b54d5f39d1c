"""The results table of ``hilbench analyse``: one Parquet row per run and step.

Layout of a results folder::

    results.parquet          the compacted table (sorted by campaign, run key, step)
    parts/<campaign>-<run>-<step>-<settings>-<n>.parquet   the rows of one task (a chunk of runs) each, written
                                                           as results arrive (atomic rename)

Only the client writes. Every part is complete or absent (written beside, then renamed), so a client killed
at any moment leaves a folder whose rows are all good: a rerun reads ``results.parquet`` and the parts,
skips the rows it has, analyses the rest, and compacts. A row's key is (campaign, run key, content hash of the
run file, step, settings hash, hilbench version): a changed file, setting or version is analysed again.
"""

from __future__ import annotations

import hashlib
import os
import uuid
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from hilbench.bench.campaign_analysis.steps import COLUMNS
from hilbench.common.units import AXIS_UNITS, axis_unit

TABLE_NAME = "results.parquet"
PARTS = "parts"
#: a row's identity: the run (campaign folder name and run key: two runs may hold the same bytes) and its content,
#: the step, the settings and the version that computed it
KEY_COLUMNS = ("campaign", "key", "content_hash", "step", "settings_hash", "hilbench_version")
#: columns every row has, with their Arrow types and units
BASE_COLUMNS: dict[str, tuple[str, str]] = {
    "campaign": ("string", ""), "folder": ("string", ""), "run_id": ("string", ""), "key": ("string", ""),
    "axis": ("string", ""),
    "name": ("string", ""), "repeat": ("int64", "1"), "protocol": ("string", ""), "file": ("string", ""),
    "start_time": ("string", "ISO 8601 UTC"), "operator": ("string", ""), "environment": ("string", "JSON"),
    "ambient": ("float64", "degC"), "load": ("float64", "kg"),
    "step": ("string", ""), "status": ("string", ""), "error": ("string", ""),
    "content_hash": ("string", "sha256"), "settings_hash": ("string", "sha256"), "hilbench_version": ("string", ""),
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


def to_table(rows: Iterable[dict[str, Any]]) -> pa.Table:
    """Rows (dicts; missing columns null, unknown ones refused) as a table of :data:`SCHEMA`."""
    rows = list(rows)
    for row in rows:
        unknown = set(row) - set(ALL_COLUMNS)
        if unknown:
            raise KeyError(f"result columns not in the table schema: {', '.join(sorted(unknown))}")
    columns = {}
    for name, (kind, _unit) in ALL_COLUMNS.items():
        values = [row.get(name) for row in rows]
        if kind == "float64":
            values = [None if v is None else float(v) for v in values]
        elif kind == "int64":
            values = [None if v is None else int(v) for v in values]
        columns[name] = pa.array(values, type=_TYPES[kind])
    return pa.Table.from_pydict(columns, schema=SCHEMA)


def _write_atomic(table: pa.Table, target: Path) -> None:
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        pq.write_table(table, tmp)
        os.replace(tmp, target)
    finally:
        if tmp.exists():
            tmp.unlink()


class ResultsFolder:
    """The results folder: rows already there, parts as they arrive, compaction."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self.parts = self.path / PARTS

    def read_rows(self) -> list[dict[str, Any]]:
        """Every row in the compacted table and the parts (a part wins over the table for the same key)."""
        rows: dict[tuple, dict[str, Any]] = {}
        files = ([self.path / TABLE_NAME] if (self.path / TABLE_NAME).exists() else []) + sorted(
            self.parts.glob("*.parquet") if self.parts.is_dir() else [])
        for f in files:
            for row in pq.read_table(f).to_pylist():
                rows[row_key(row)] = row
        return list(rows.values())

    def add(self, rows: list[dict[str, Any]]) -> Path:
        """Write rows (the results of one task) as one part (atomic). One part per row cost 17 ms of the
        client's time per run, as much as a tenth of a short run's analysis."""
        self.parts.mkdir(parents=True, exist_ok=True)
        first = rows[0]
        keys = hashlib.sha256(repr(sorted(repr(row_key(r)) for r in rows)).encode()).hexdigest()[:8]
        target = self.parts / f"{first['campaign']}-{first['key']}-{first['step']}-{keys}-{len(rows)}.parquet"
        _write_atomic(to_table(rows), target)
        return target

    def compact(self, current: set[tuple] | None = None) -> Path:
        """Merge the parts into ``results.parquet`` (sorted; atomic), then remove the parts. With ``current``
        (row keys of this analysis), an older row of the same run and step (other settings or version, or an
        older file) is dropped: the table holds one row per run and step."""
        rows = self.read_rows()
        if current is not None:
            fresh = {(r["campaign"], r["key"], r["step"]) for r in rows if row_key(r) in current}
            rows = [r for r in rows if row_key(r) in current or (r["campaign"], r["key"], r["step"]) not in fresh]
        rows.sort(key=lambda r: tuple(str(r.get(k) or "") for k in ORDER) + row_key(r))
        self.path.mkdir(parents=True, exist_ok=True)
        target = self.path / TABLE_NAME
        _write_atomic(to_table(rows), target)
        if self.parts.is_dir():
            for f in self.parts.glob("*.parquet"):
                f.unlink()
            self.parts.rmdir()
        return target
