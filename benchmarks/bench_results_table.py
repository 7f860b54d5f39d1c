"""The results table's rows into Arrow (bench.campaign_analysis.table.to_table, issue 41): CPU per table of 16 rows
(a worker's part) and of 800 rows (a compaction), and the CPU of a fresh process that imports the table module and
writes one part of 16 rows, each against the construction it replaced, ``pa.array`` per column (the test oracle
tests/bench/campaign_analysis/pa_array_oracle.py), in the same run. ``pa.array`` imports pandas when pandas is
installed: the fresh process pays that (0.17-0.26 s) once; the timed loops of the 16- and 800-row tables do not (the
oracle runs once before them)."""

from __future__ import annotations

import hashlib
import json
import random
import resource
import subprocess
import sys
import tempfile
import time
import timeit
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: a fresh interpreter: import the table module, write one part of the rows in argv[2] (JSON) into argv[3], with
#: to_table as it is ("new") or the pa.array oracle ("old"); prints whether pandas got imported
CHILD = """
import json, sys
from hilbench.bench.campaign_analysis import table
if sys.argv[1] == "old":
    from tests.bench.campaign_analysis.pa_array_oracle import by_pa_array
    table.to_table = by_pa_array
table.write_part(sys.argv[3], json.loads(open(sys.argv[2]).read()))
print(json.dumps("pandas" in sys.modules))
"""


def rows(n: int, seed: int = 41) -> list[dict]:
    """Rows shaped as an identify step's: the base columns as text (hashes, paths, times, the environment as
    JSON), the step's figures as floats, about 40 of the table's columns set and the others missing."""
    from hilbench.bench.campaign_analysis.table import ALL_COLUMNS, BASE_COLUMNS

    rng = random.Random(seed)
    figures = [name for name, (kind, _u) in ALL_COLUMNS.items() if kind == "float64" and name not in BASE_COLUMNS]
    out = []
    for i in range(n):
        digest = hashlib.sha256(str(i).encode()).hexdigest()
        row = {"campaign": "warm-2026", "campaign_uid": digest[:32], "folder": "/data/campaigns/warm-2026",
               "run_id": digest[32:], "key": f"id{i}-1", "axis": "rotary", "name": f"id{i}", "repeat": 1,
               "protocol": "identification", "file": f"id{i}-1.h5", "start_time": "2026-11-28T10:00:00Z",
               "operator": "lab", "environment": json.dumps({"ambient": 22.5, "note": "après midi"}),
               "ambient": 22.5 + rng.random(), "load": 0.0, "step": "identify", "status": "ok", "error": "",
               "content_hash": digest, "settings_hash": digest[::-1], "hilbench_version": "0.2.0",
               "file_stat": f"{rng.randint(1, 10**8)}:{rng.randint(1, 10**18)}:{rng.randint(1, 10**18)}:{i}"}
        row.update({name: rng.gauss(0.0, 1.0) * 10.0 ** rng.randint(-6, 3) for name in figures[:18]})
        out.append(row)
    return out


def _cpu_per_call(fn, number: int) -> float:
    """Least CPU seconds per call over 5 repeats (process time: the machine's other work does not count)."""
    return min(timeit.Timer(fn, timer=time.process_time).repeat(5, number)) / number


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _fresh_part(which: str, rows_file: Path, out: Path) -> tuple[float, bool]:
    """CPU seconds of a fresh interpreter writing one part (interpreter start to exit), and whether it imported
    pandas."""
    before = _children_cpu()
    done = subprocess.run([sys.executable, "-c", CHILD, which, str(rows_file), str(out)], capture_output=True,
                          text=True, check=True, cwd=ROOT)
    return _children_cpu() - before, json.loads(done.stdout.strip().splitlines()[-1])


def run(quick: bool = False) -> list[dict]:
    import importlib.util

    from hilbench.bench.campaign_analysis.table import to_table
    from tests.bench.campaign_analysis.pa_array_oracle import by_pa_array

    results = []
    for n in (16, 800):
        rs = rows(n)
        assert to_table(rs).equals(by_pa_array(rs), check_metadata=True)  # and the oracle's pandas import is paid
        number = (20 if quick else 200) if n == 16 else (2 if quick else 10)
        new, old = _cpu_per_call(lambda rs=rs: to_table(rs), number), _cpu_per_call(lambda rs=rs: by_pa_array(rs),
                                                                                     number)
        results.append({"name": f"results_table_{n}_rows_cpu", "value": new * 1e3, "unit": "ms",
                        "baseline_name": "pa.array per column", "baseline_value": old * 1e3, "ratio": new / old,
                        "target": "<= 1.1x pa.array", "ok": new <= 1.1 * old})
    has_pandas = importlib.util.find_spec("pandas") is not None
    cpu: dict[str, list[float]] = {"new": [], "old": []}
    imported = {"new": False, "old": False}
    with tempfile.TemporaryDirectory() as tmp:
        rows_file = Path(tmp) / "rows.json"
        rows_file.write_text(json.dumps(rows(16)))
        for k in range(1 if quick else 7):  # interleaved, so that the machine's load falls on both alike
            for which in ("new", "old"):
                seconds, pandas = _fresh_part(which, rows_file, Path(tmp) / f"{which}{k}")
                cpu[which].append(seconds)
                imported[which] |= pandas
    new, old = sorted(cpu["new"])[len(cpu["new"]) // 2], sorted(cpu["old"])[len(cpu["old"]) // 2]
    results.append({"name": "results_part_fresh_process_cpu", "value": new * 1e3, "unit": "ms",
                    "baseline_name": "with pa.array" + (" (imports pandas)" if imported["old"] else ""),
                    "baseline_value": old * 1e3, "ratio": new / old,
                    "target": "pandas never imported" + ("" if has_pandas else " (pandas not installed)"),
                    "ok": not imported["new"]})
    return results
