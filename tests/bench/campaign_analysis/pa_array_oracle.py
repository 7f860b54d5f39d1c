"""The oracle of the results table's construction: to_table as it was before issue 41, one ``pa.array`` per column
(which imports pandas when pandas is installed). A test oracle only: test_table_build.py holds the new to_table to it,
benchmarks/bench_results_table.py times the two."""

from __future__ import annotations

from typing import Any

import pyarrow as pa

from hilbench.bench.campaign_analysis.table import _TYPES, ALL_COLUMNS, SCHEMA


def by_pa_array(rows: list[dict[str, Any]]) -> pa.Table:
    """The oracle: to_table as it was before issue 41's change, one ``pa.array`` per column."""
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
