"""How the results table is built (bench.campaign_analysis.table.to_table): each column from its buffers
(``pa.Array.from_buffers``), never through ``pa.array``, which imports pandas when pandas is installed (0.17-0.26 s of
CPU in every process that writes a part; issue 41).

The oracle is the construction to_table used before, ``pa.array`` per column (pa_array_oracle.by_pa_array): the
new table must equal it exactly (``equals`` with the field metadata, every float's bits, and the Parquet bytes
written from each) on rows from a generator written for the purpose: every kind of double (random bit patterns,
subnormals down to 5e-324, 1e308, -0.0), integers across the int64 range, None, text with quotes, backslashes,
control characters, line separators and emoji, columns missing at random."""

from __future__ import annotations

import io
import json
import math
import random
import struct
import subprocess
import sys
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from hilbench.bench.campaign_analysis import table
from hilbench.bench.campaign_analysis.table import ALL_COLUMNS, SCHEMA, to_table
from tests.bench.campaign_analysis.pa_array_oracle import by_pa_array

pytestmark = pytest.mark.device_free

KINDS = {name: kind for name, (kind, _unit) in ALL_COLUMNS.items()}


#: doubles at the edges of the format: subnormals (the smallest, the largest), the smallest normal, the largest
#: double, signed zeros, and values whose shortest repr is long
EDGE_FLOATS = (5e-324, -5e-324, 2.225073858507201e-308, 2.2250738585072014e-308, 1e308, -1e308,
               1.7976931348623157e308, 0.0, -0.0, 0.1, 1 / 3, 2.0**53 + 2, 123456789.12345678, 1e-300, 4.9e-324)
EDGE_INTS = (0, 1, -1, 2**53 + 1, 2**62, -(2**62), 2**63 - 1, -(2**63))
#: text pieces a JSON writer or reader could get wrong
PIECES = ('"', "\\", "\\n", "\n", "\r", "\t", "\x00", "\x1f", "\x7f", "\u2028", "\u2029", "\ufeff", "\uffff", "é",
          "日本", "e\u0301", "\U0001f600", "\U0001f9ea", "{", "}", ":", ",", "null", "NaN", " ", "'", "/", "</script>")


def random_float(rng: random.Random, finite: bool = True) -> float:
    draw = rng.random()
    if draw < 0.3:
        return rng.choice(EDGE_FLOATS)
    if draw < 0.7:  # any double: a random bit pattern covers every exponent, subnormals included
        while True:
            x = struct.unpack("<d", struct.pack("<Q", rng.getrandbits(64)))[0]
            if math.isfinite(x) or not finite:
                return x
    if draw < 0.85:
        return rng.uniform(-1e3, 1e3)
    return rng.gauss(0.0, 1.0) * 10.0 ** rng.randint(-320, 300)


def random_int(rng: random.Random) -> int:
    return rng.choice(EDGE_INTS) if rng.random() < 0.3 else rng.randint(-(2**62), 2**62)


def random_text(rng: random.Random, ascii_only: bool = False) -> str:
    n = rng.randint(0, 12)
    if ascii_only:  # to_table takes a shorter way when a whole column is ASCII
        return "".join(chr(rng.randint(0, 0x7f)) for _ in range(n))
    return "".join(rng.choice(PIECES) if rng.random() < 0.5 else chr(rng.randint(0x20, 0x2fff)) for _ in range(n))


def random_value(rng: random.Random, kind: str, ascii_only: bool = False) -> Any:
    if rng.random() < 0.15:
        return None
    if kind == "float64":
        x = random_float(rng)
        # what a step hands over: a Python float, a numpy scalar, an int or a bool (float(v) of each)
        return rng.choice((x, np.float64(x), x, round(x) if abs(x) < 1e15 else x, bool(x > 0)))
    if kind == "int64":
        i = random_int(rng)
        return rng.choice((i, np.int64(i), i))
    return random_text(rng, ascii_only)


def random_rows(seed: int, n: int, ascii_only: bool = False) -> list[dict[str, Any]]:
    rng = random.Random(seed)
    rows = []
    for _ in range(n):
        names = [name for name in ALL_COLUMNS if rng.random() < 0.7]  # the others missing: null
        rows.append({name: random_value(rng, KINDS[name], ascii_only) for name in names})
    return rows


def parquet_bytes(table: pa.Table) -> bytes:
    out = io.BytesIO()
    pq.write_table(table, out)
    return out.getvalue()


def float_bits(table: pa.Table) -> dict[str, list[int | None]]:
    """Each float column's values as their 64-bit patterns (``equals`` takes -0.0 for 0.0 and NaN for unequal)."""
    out = {}
    for name, kind in KINDS.items():
        if kind == "float64":
            values = table.column(name).to_pylist()
            out[name] = [None if v is None else struct.unpack("<Q", struct.pack("<d", v))[0] for v in values]
    return out


def assert_same(rows: list[dict[str, Any]], finite: bool = True) -> None:
    new, old = to_table(rows), by_pa_array(rows)
    assert new.schema.equals(SCHEMA, check_metadata=True)
    if finite:  # equals takes NaN for unequal to itself (the bits and the Parquet bytes below hold NaN too)
        assert new.equals(old, check_metadata=True)
    assert float_bits(new) == float_bits(old)
    assert parquet_bytes(new) == parquet_bytes(old)


@pytest.mark.parametrize("seed", range(6))
def test_random_rows_give_the_table_pa_array_gave(seed):
    assert_same(random_rows(seed, 1 + 37 * seed, ascii_only=seed % 2 == 1))


def test_every_edge_double_and_integer_keeps_its_bits():
    floats = [n for n, k in KINDS.items() if k == "float64"]
    ints = [n for n, k in KINDS.items() if k == "int64"]
    rows = [{name: x for name in floats} for x in EDGE_FLOATS]
    rows += [{name: i for name in ints} for i in EDGE_INTS]
    assert_same(rows)
    assert to_table(rows).column(floats[0]).to_pylist()[:len(EDGE_FLOATS)] == list(EDGE_FLOATS)
    assert math.copysign(1.0, to_table([{floats[0]: -0.0}]).column(floats[0])[0].as_py()) == -1.0


def test_nan_and_infinities_of_an_older_table_stay_as_they_were():
    """Rows read back from a table an older hilbench wrote may hold NaN or infinities: compaction keeps them."""
    rows = [{"key": "r", "ambient": float("nan"), "load": float("inf"), "inertia": -float("inf")}]
    rows += random_rows(99, 20)
    for row in rows[1:]:
        row["viscous"] = random_float(random.Random(len(row)), finite=False)
    assert_same(rows, finite=False)
    got = to_table(rows[:1]).to_pylist()[0]
    assert math.isnan(got["ambient"]) and got["load"] == math.inf and got["inertia"] == -math.inf


def test_zero_rows_and_all_null_columns():
    assert_same([])
    assert to_table([]).num_rows == 0 and to_table([]).schema.equals(SCHEMA, check_metadata=True)
    assert_same([{}, {}, {}])
    assert_same([{name: None for name in ALL_COLUMNS} for _ in range(4)])
    table = to_table([{"key": "a"}, {"key": "b", "step": None}])
    assert table.column("inertia").null_count == 2 and table.column("key").to_pylist() == ["a", "b"]


def test_text_beyond_one_chunk_goes_into_several(monkeypatch):
    """A text column of more bytes than Arrow's 32-bit offsets reach is split into chunks (here with the limit set
    to 60 bytes, more than any one generated text): the same values, each chunk within the limit, none of the 32-bit
    offsets wrapped; a single text beyond the limit is one line naming its column and run."""
    monkeypatch.setattr(table, "TEXT_CHUNK", 60)
    for ascii_only in (False, True):
        rows = random_rows(7, 60, ascii_only)
        new = to_table(rows)
        new.validate(full=True)
        assert new.equals(by_pa_array(rows), check_metadata=True)
        column = new.column("environment")
        assert column.num_chunks > 3
        assert all(len(chunk.buffers()[2] or b"") <= 60 for chunk in column.chunks)
    with pytest.raises(ValueError, match=r"^result column 'name' of 'k' \(step None\): a text of 61 bytes, more "):
        to_table([{"key": "k", "name": "x" * 61}])


def test_an_unknown_column_is_refused_with_the_same_message():
    row = {"key": "a", "bogus": 1.0, "also": "x"}
    with pytest.raises(KeyError) as new:
        to_table([row])
    with pytest.raises(KeyError) as old:
        by_pa_array([row])
    assert str(new.value) == str(old.value) == "'result columns not in the table schema: also, bogus'"


@pytest.mark.parametrize(("column", "value", "kind", "says"), [
    ("file", "runs/\udc80.h5", ValueError, "result column 'file' of 'r7' (step 'identify'): text 'runs/\\udc80.h5' "
                                           "is not valid UTF-8 (a lone surrogate at 5"),
    ("name", 3, TypeError, "result column 'name' of 'r7' (step 'identify'): int 3 where text is expected"),
    ("error", b"bytes", TypeError, "result column 'error' of 'r7' (step 'identify'): bytes b'bytes' where text"),
    ("repeat", 2**63, OverflowError, "result column 'repeat' of 'r7' (step 'identify'): 9223372036854775808 is "
                                     "outside the int64 range"),
])
def test_a_value_arrow_cannot_hold_is_one_line_naming_its_column_and_run(column, value, kind, says):
    """A lone surrogate (an undecodable file name, decoded with surrogateescape) ended in a bare UnicodeEncodeError
    naming no column; the new error says which column of which run, and is of the same kind as before (a
    ValueError for the text; the type and overflow errors pa.array raised), so no caller's except changes."""
    rows = [{"key": "r1", "step": "identify", "name": "ok"}, {"key": "r7", "step": "identify", column: value}]
    with pytest.raises(kind) as new:
        to_table(rows)
    assert str(new.value).startswith(says) and "\n" not in str(new.value)
    if column != "error":  # pa.array took bytes as text; nothing in hilbench hands it bytes
        with pytest.raises(kind):
            by_pa_array(rows)


#: a fresh interpreter writes a part, reads it back and compacts, as a worker and the client do
NO_PANDAS = """
import json, sys
from hilbench.bench.campaign_analysis.table import ResultsFolder, row_key, write_part
rows = [{"campaign_uid": "u", "key": f"r{i}", "run_id": f"id{i}", "content_hash": "h", "step": "identify",
         "settings_hash": "s", "hilbench_version": "v", "status": "ok", "error": "", "inertia": 1e-4 * i,
         "repeat": i} for i in range(16)]
write_part(sys.argv[1], rows)
folder = ResultsFolder(sys.argv[1], say=print)
got = folder.read_rows()
folder.compact(got, {row_key(r): {} for r in got.values()})
print(json.dumps([len(got), len(folder.read_rows()), "pandas" in sys.modules]))
"""


def test_writing_reading_and_compacting_rows_never_imports_pandas(tmp_path):
    pytest.importorskip("pandas", reason="pandas not installed: nothing could import it")
    done = subprocess.run([sys.executable, "-c", NO_PANDAS, str(tmp_path / "results")], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout.strip().splitlines()[-1]) == [16, 16, False]
