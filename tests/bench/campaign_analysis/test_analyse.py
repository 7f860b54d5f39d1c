"""``hilbench analyse``: every run of a campaign folder into one Parquet table, resumable, fault-tolerant.

Campaigns here are short simulated runs (bench.campaign_analysis.synthetic: the C plant through RunWriter)."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from hilbench.bench.campaign_analysis.engine import MAX_CHUNK, analyse, chunk
from hilbench.bench.campaign_analysis.steps import StepSettings, identify_step
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign
from hilbench.bench.cli import main
from hilbench.firmware_sim.engine.friction_models import DC_MOTOR_BREAKAWAY, DC_MOTOR_INERTIA

quiet = {"progress": False, "say": lambda _line: None}


@pytest.fixture(scope="module")
def campaign(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("campaign") / "c"
    write_campaign(folder, SyntheticCampaign(runs=8, repeats=2, duration=1.5, seed=11), fail_runs=(5,))
    return folder


def _rows(table: Path) -> list[dict]:
    return pq.read_table(table).to_pylist()


def test_serial_analysis_recovers_the_plant_and_records_a_failing_run(campaign, tmp_path):
    s = analyse([campaign], tmp_path / "r", serial=True, **quiet)
    rows = {r["key"]: r for r in _rows(s.table)}
    assert s.analysed == 8 and s.failed == 1 and len(rows) == 8
    bad = rows["id3-2"]  # run index 5 was written without its position channel
    assert bad["status"] == "failed" and "position" in bad["error"] and bad["breakaway"] is None
    good = [r for r in rows.values() if r["status"] == "ok"]
    for r in good:
        # the plant's J within 3 of its standard errors and break-away within 5 % (no drift configured), from
        # 1.05 s of 1 kHz data
        assert abs(r["inertia"] - DC_MOTOR_INERTIA) <= 3 * r["inertia_se"]
        assert r["breakaway"] == pytest.approx(DC_MOTOR_BREAKAWAY, rel=0.05)
        assert r["breakaway_se"] > 0 and r["validation_torque_nrmse"] < 0.2
        assert r["verdict"] == ("good" if r["validation_torque_nrmse"] <= 0.1 else "fair")  # bench.verdict bands
        assert r["start_time"].startswith("2026-01-05T") and r["operator"] == "sim" and r["ambient"] == 23.0
        assert r["temperature_mean"] >= 23.0
    assert {r["repeat"] for r in good} == {1, 2}
    index = json.loads((campaign / "index.json").read_text())["runs"]
    assert {r["run_id"] for r in rows.values()} == {e["uid"] for e in index}
    units = pq.read_schema(s.table).field("breakaway").metadata[b"unit"]
    assert units == b"N*m"


def test_resume_skips_what_is_there_and_a_changed_setting_or_file_reanalyses(campaign, tmp_path):
    copy = tmp_path / "c"
    shutil.copytree(campaign, copy)
    out = tmp_path / "r"
    first = pq.read_table(analyse([copy], out, serial=True, **quiet).table)
    again = analyse([copy], out, serial=True, **quiet)
    assert (again.analysed, again.skipped) == (0, 8)
    assert pq.read_table(again.table).equals(first)
    shutil.copyfile(copy / "id1-1.h5", copy / "id4-2.h5")  # another run's file under this run's name
    one = analyse([copy], out, serial=True, **quiet)
    assert (one.analysed, one.skipped) == (1, 7)
    rows = {r["key"]: r for r in _rows(one.table)}
    # its uid is not the index entry's: a failed row that says so, never id1-1's numbers as id4-2's
    assert rows["id4-2"]["status"] == "failed" and "run uid" in rows["id4-2"]["error"] and len(rows) == 8
    assert rows["id4-2"]["breakaway"] is None
    changed = analyse([copy], out, settings=StepSettings(thresholds=16), serial=True, **quiet)
    assert (changed.analysed, changed.skipped) == (8, 0)
    assert len(_rows(changed.table)) == 8  # one row per run and step: the older settings' rows are replaced
    assert {r["settings_hash"] for r in _rows(changed.table)} != set(first.column("settings_hash").to_pylist())


def test_identify_step_matches_hilbench_identify(campaign, tmp_path):
    # the adapter runs the same identification as the command (same file, no held-out tail, same thresholds)
    path = campaign / "id1-1.h5"
    row = identify_step(str(path), StepSettings(thresholds=32, validation_fraction=0.0))
    assert main(["-q", "identify", str(path), "--thresholds", "32", "--json", str(tmp_path / "m.json")]) == 0
    model = json.loads((tmp_path / "m.json").read_text())["parameters"]
    assert row["inertia"] == pytest.approx(model["inertia"], rel=1e-12)
    assert row["viscous"] == pytest.approx(model["viscous"], rel=1e-12)


def _dies(path: str, settings: StepSettings) -> dict:
    """A step whose worker dies (as on a segfault or an out-of-memory kill) on id2-1."""
    if path.endswith("id2-1.h5"):
        os._exit(3)
    return identify_step(path, settings)


def test_cluster_survives_dying_workers_and_matches_serial(campaign, tmp_path):
    serial = {r["key"]: r for r in _rows(analyse([campaign], tmp_path / "serial", serial=True, **quiet).table)}
    # tasks of 2 runs then 1 here (8 runs, 2 workers: engine.chunk); the split of a task of many runs that kills its
    # workers is measured by benchmarks/bench_campaign.py (200 runs, tasks of 16: exactly the 2 bad rows fail)
    s = analyse([campaign], tmp_path / "cluster", workers=2, dashboard=False, functions={"identify": _dies}, **quiet)
    rows = {r["key"]: r for r in _rows(s.table)}
    assert len(rows) == 8 and s.analysed == 8 and s.failed == 2
    # a worker that dies on every try: retried once on a fresh worker, then a failed row with the reason
    assert rows["id2-1"]["status"] == "failed" and "worker died twice" in rows["id2-1"]["error"]
    assert "on 2 different workers" in rows["id2-1"]["error"]
    assert rows["id3-2"]["status"] == "failed" and "position" in rows["id3-2"]["error"]  # a step that raises
    # every other row is the serial one, bit for bit, whichever worker computed it
    for key in rows.keys() - {"id2-1"}:
        assert rows[key] == serial[key]


def _rows_in_parts(parts: Path) -> int:
    return sum(pq.read_metadata(f).num_rows for f in parts.glob("*.parquet")) if parts.is_dir() else 0


def test_a_killed_client_leaves_good_parts_and_a_rerun_analyses_only_the_missing(campaign, tmp_path):
    out = tmp_path / "r"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    proc = subprocess.Popen([sys.executable, "-m", "hilbench.bench.cli", "-q", "analyse", str(campaign), "-o",
                             str(out), "--serial"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    parts = out / "parts"
    while time.monotonic() < deadline and _rows_in_parts(parts) < 3:  # parts of 2 runs each (8 runs, 1 worker)
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done = _rows_in_parts(parts)
    assert 3 <= done < 8, "the client was to be killed mid-campaign"
    assert not (out / "results.parquet").exists()
    s = analyse([campaign], out, serial=True, **quiet)
    assert (s.skipped, s.analysed) == (done, 8 - done)
    assert len(_rows(s.table)) == 8 and not parts.exists()


def test_chunks_balance_the_workers_and_cap_the_task_size():
    todo = list(range(200))
    parts = chunk(todo, 2)  # 200 runs, 2 workers: 32 per task while 64 or more are left, then shrinking to 1
    sizes = [len(p) for p in parts]
    assert sum(parts, []) == todo and sizes[:5] == [MAX_CHUNK] * 5 and sizes == sorted(sizes, reverse=True)
    # each the remaining share per worker (guided self-scheduling): the last 3 are single runs
    left = [sum(sizes[:k]) for k in range(len(sizes))]
    assert all(s == max(1, min(MAX_CHUNK, (200 - a) // 2)) for s, a in zip(sizes, left, strict=True))
    assert sizes == [32] * 5 + [20, 10, 5, 2, 1, 1, 1] and len(parts) == 12
    # what one worker takes while the other runs the biggest chunk of the tail: never more than one run apart
    assert sum(sizes[6:]) == sizes[5]
    assert [len(p) for p in chunk(todo[:20], 2)] == [10, 5, 2, 1, 1, 1]
    assert [len(p) for p in chunk(todo[:3], 2)] == [1] * 3


def test_cli_bad_input_is_one_line_and_exit_2(campaign, tmp_path, capsys):
    assert main(["analyse", str(tmp_path)]) == 2
    assert "no index.json" in capsys.readouterr().err
    assert main(["analyse", str(campaign), str(campaign)]) == 2
    assert "-o" in capsys.readouterr().err
    assert main(["analyse", str(campaign), "-o", str(campaign)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "campaign folder" in err


_EARLY_CHILD = """
import sys
from hilbench.bench.campaign_analysis import cluster_host
from hilbench.bench.cli.commands.analyse import start_early
start_early(sys.argv[1:])
print(cluster_host._early is not None)
"""


def test_the_cluster_host_starts_before_the_parser_only_for_a_local_cluster(campaign, tmp_path):
    """`hilbench analyse` starts its cluster's host process (and with it the workers' fork server, whose 1-2 s of
    imports are the local cluster's critical path) first thing, but only for a line that names a campaign folder and
    asks for no other engine."""
    def started(*args: str) -> bool:
        done = subprocess.run([sys.executable, "-c", _EARLY_CHILD, *args], capture_output=True, text=True,
                              timeout=60)
        assert done.returncode == 0, done.stderr[-2000:]
        return done.stdout.split() == ["True"]

    assert started(str(campaign), "-o", str(tmp_path / "r"), "--workers", "2")
    assert not started(str(campaign), "--serial")
    assert not started(str(campaign), "--scheduler", "tcp://127.0.0.1:8786")
    assert not started(str(campaign), "--scheduler-file", str(tmp_path / "s.json"))
    assert not started(str(campaign), "--help")
    assert not started(str(tmp_path))  # no index.json: the command refuses it


_BLAS_CHILD = """
import json, sys
from pathlib import Path
from hilbench.bench.campaign_analysis.engine import analyse

def blas_threads(path, settings):
    from hilbench.analysis.execution import blas_threads
    # carried in numeric columns of the table's fixed schema: the most threads of any library (numpy's and scipy's
    # own OpenBLAS), and how many libraries
    threads = blas_threads()
    return {"inertia": float(max(threads.values(), default=0)), "viscous": float(len(threads))}

if __name__ == "__main__":
    mode = sys.argv[3]
    s = analyse([Path(sys.argv[1])], Path(sys.argv[2]), serial=mode == "serial", workers=2, dashboard=False,
                progress=False, say=lambda _line: None, functions={"identify": blas_threads})
    print(json.dumps(s.table and str(s.table)))
"""


@pytest.mark.parametrize("mode", ["serial", "cluster"])
def test_every_run_is_analysed_with_one_blas_thread(campaign, tmp_path, mode):
    """A fresh `hilbench analyse` (distributed not imported before it starts the workers' fork server) ran each worker's
    OpenBLAS on two threads: Dask's pre-spawn environment was read before distributed had loaded its config.
    That spun a second core per worker (200 runs: 32 s of CPU against 15 s serial) and made the tables differ
    from the serial ones in the last bits. The serial loop, too, now limits BLAS to one thread; every chunk runs
    under the execution policy (analysis.execution), which limits every BLAS library, scipy's own included."""
    script = tmp_path / "child.py"  # a file, not -c: the fork server re-imports the main module
    script.write_text(_BLAS_CHILD)
    # without the thread limits make test sets for its own processes: the analysis must set them itself
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                                             "MKL_NUM_THREADS")}
    done = subprocess.run([sys.executable, str(script), str(campaign), str(tmp_path / "r"), mode],
                          capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    rows = [r for r in _rows(tmp_path / "r" / "results.parquet") if r["status"] == "ok"]
    assert len(rows) == 8 and {r["inertia"] for r in rows} == {1.0}, [r["inertia"] for r in rows]  # BLAS threads
    assert min(r["viscous"] for r in rows) >= 2  # libraries: numpy's and scipy's OpenBLAS
