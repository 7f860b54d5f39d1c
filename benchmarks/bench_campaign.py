"""Campaign analysis at scale: 200-run campaigns of short runs (the C plant through RunWriter; 5 s at 5 kHz for the
target, and 2 s at 1 kHz) analysed by ``hilbench analyse`` serially and on a LocalCluster of 2 worker processes; the
speedup (target >= 1.7x on a 2-core machine), and the two Parquet tables must be identical. Then the faults: one
worker dies (os._exit) on a run and another run raises; the campaign completes with exactly those two rows failed.

Each of the two timed analyses is the command itself, ``hilbench analyse --serial`` and ``--workers 2``, in a fresh
interpreter, timed from outside: both pay the interpreter's start and the imports of the analysis (the serial
process itself, the cluster's fork server once for its workers) and the cluster pays its start and shutdown. The
wall times mean little on a machine other jobs share: the load average is reported beside them, and the CPU times
bound what two idle cores would give."""

from __future__ import annotations

import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pyarrow.parquet as pq

from hilbench.bench.acquisition.campaign import INDEX_NAME
from hilbench.bench.campaign_analysis.engine import analyse
from hilbench.bench.campaign_analysis.steps import StepSettings, identify_step
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign

FAULT_RUN = "id7-1.h5"
ROOT = Path(__file__).resolve().parents[1]
#: one timed analysis in a fresh interpreter: the ``hilbench`` command itself (its main, as the console script calls
#: it); the command's last line, its summary, gives its own wall and start-up times
CHILD = """
import sys, time
from hilbench.bench.cli.main import main
code = main(sys.argv[1:])
# when the command's analysis ended (its summary's wall time counts back from here to its start); the local
# cluster's host process has been waited for, and it waits for its fork server, the parent of the workers, so
# their CPU reaches this process's RUSAGE_CHILDREN
print(f"ended at {time.time():.6f}", file=sys.stderr)
sys.exit(code)
"""
#: the command's last line: "... rows in all (W s, S s of it start-up; client CPU C ms per run[, scheduler H ms per
#: run]) -> TABLE"
SUMMARY = re.compile(r"\((?P<wall>[0-9.]+) s, (?P<startup>[0-9.]+) s of it start-up; client CPU (?P<client>[0-9.]+) "
                     r"ms per run(?:, scheduler (?P<scheduler>[0-9.]+) ms per run)?\) -> (?P<table>.+)$")
ENDED = re.compile(r"^ended at (?P<at>[0-9.]+)$", re.M)


def _children_cpu() -> float:
    """CPU seconds of the reaped child processes (each timed analysis and, reaped by it, its workers)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _timed(folder: Path, out: Path, mode: str) -> dict:
    """``hilbench analyse FOLDER -o OUT`` with ``--serial`` or ``--workers 2``, timed from outside: the wall time
    includes the interpreter's start, the command's imports and the cluster's shutdown."""
    engine = ["--serial"] if mode == "serial" else ["--workers", "2", "--no-dashboard"]
    cpu0, load0 = _children_cpu(), os.getloadavg()[0]
    t0, launched = time.perf_counter(), time.time()
    done = subprocess.run([sys.executable, "-c", CHILD, "analyse", str(folder), "-o", str(out), *engine],
                          cwd=ROOT, check=True, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    m, ended = SUMMARY.search(done.stdout.strip().splitlines()[-1]), ENDED.search(done.stderr)
    if m is None or ended is None:
        raise RuntimeError(f"hilbench analyse: no summary line in {done.stdout!r}")
    # start-up: from the interpreter's launch to the first task (the command's clock starts after its imports:
    # its analysis began at its end less its wall time, and its first task its start-up later); what follows the
    # analysis (the interpreter's exit) is not start-up
    began = float(ended["at"]) - float(m["wall"])
    return {"wall": wall, "startup": began + float(m["startup"]) - launched, "table": m["table"],
            "client_ms": float(m["client"]), "scheduler_ms": float(m["scheduler"]) if m["scheduler"] else None,
            "exit": launched + wall - float(ended["at"]),
            "cpu": _children_cpu() - cpu0, "load": max(load0, os.getloadavg()[0])}


def _dies(path: str, settings: StepSettings) -> dict:
    if path.endswith(FAULT_RUN):
        os._exit(3)  # the worker dies as on a segfault
    return identify_step(path, settings)


#: the campaigns timed (run length s, sample rate Hz): the target is on the second, short runs of a quarter of the
#: default identification's length at half its rate (25 000 samples, about 0.15 s of analysis each); the first,
#: 2000 samples (65 ms each), shows where the cluster's fixed cost (its start, 1 to 1.5 s more than the serial
#: loop's imports) still outweighs the work
SIZES = ((2.0, 1000.0), (5.0, 5000.0))
#: alternating serial, cluster and two-halves analyses of the target campaign (about 65 s a round)
REPEATS = 4


def _halves(folder: Path, tmp: Path) -> tuple[Path, Path]:
    """Two campaign folders of half the runs each (their index, links to the run files)."""
    doc = json.loads((folder / INDEX_NAME).read_text())
    runs, out = doc["runs"], []
    for k, part in enumerate((runs[: len(runs) // 2], runs[len(runs) // 2 :])):
        half = tmp / f"{folder.name}_half{k}"
        half.mkdir()
        for entry in part:
            (half / entry["file"]).symlink_to(folder / entry["file"])
        (half / INDEX_NAME).write_text(json.dumps({**doc, "runs": part}))
        out.append(half)
    return out[0], out[1]


def _two_serial_halves(halves: tuple[Path, Path], out: Path) -> float:
    """Wall time of two ``hilbench analyse --serial``, one per half, at the same time: what two cores give this
    work, with nothing shared (the machine's ceiling for the cluster)."""
    t0 = time.perf_counter()
    procs = [subprocess.Popen([sys.executable, "-c", CHILD, "analyse", str(h), "-o", str(out / h.name), "--serial"],
                              cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for h in halves]
    if any(p.wait() for p in procs):
        raise RuntimeError("hilbench analyse --serial failed on a half campaign")
    return time.perf_counter() - t0


def _speedup_rows(tmp: Path, n: int, duration: float, fs: float, target: bool) -> list[dict]:
    """Serial against a LocalCluster of 2 workers on a campaign of ``n`` runs of ``duration`` s at ``fs`` Hz; with
    ``target`` the speedup rows carry the issue's >= 1.7x."""
    tag = f"{n}_runs_{duration:g}s_{fs / 1e3:g}kHz"
    folder = tmp / f"campaign_{tag}"
    write_campaign(folder, SyntheticCampaign(runs=n, duration=duration, sample_rate=fs, seed=3), fail_runs=(4,))
    # serial and cluster alternate, REPEATS times each for the target, and the fastest of each is compared: other
    # jobs on the machine only ever add time, and this VM's wall times vary by +-15 % from one run to the next
    # with the target, a third analysis each round: the two halves of the campaign serially at the same time
    serials, clusters, ceilings = [], [], []
    halves = _halves(folder, tmp) if target else None
    for k in range(REPEATS if target else 1):
        serials.append(_timed(folder, tmp / f"serial_{tag}_{k}", "serial"))
        clusters.append(_timed(folder, tmp / f"cluster_{tag}_{k}", "cluster"))
        if halves:
            ceilings.append(_two_serial_halves(halves, tmp / f"halves_{tag}_{k}"))
    serial, cluster = min(serials, key=lambda r: r["wall"]), min(clusters, key=lambda r: r["wall"])
    identical = all(pq.read_table(serials[0]["table"]).equals(pq.read_table(r["table"])) for r in serials + clusters)
    shutil.rmtree(folder)
    speedup = serial["wall"] / cluster["wall"]
    ceiling = serial["wall"] / min(ceilings) if ceilings else None
    pairs = sorted(s_["wall"] / c["wall"] for s_, c in zip(serials, clusters, strict=True))
    phase_serial, phase_cluster = serial["wall"] - serial["startup"], cluster["wall"] - cluster["startup"]
    goal = ">= 1.7x (quiet machine)" if target else "informational: 65 ms of work per run"
    # the 1.7x is judged only in a round whose two serial halves reach 1.8x: below that the machine, not the
    # cluster, decides (other jobs on a shared VM)
    judged = target and ceiling is not None and ceiling >= 1.8
    client_ms = max(r["client_ms"] for r in clusters)
    scheduler_ms = max((r["scheduler_ms"] for r in clusters if r["scheduler_ms"] is not None), default=None)
    return [
        {"name": f"analyse_{tag}_speedup_2_workers_end_to_end", "value": speedup, "unit": "x",
         "baseline_name": f"fastest serial wall / fastest cluster wall of {len(serials)}", "baseline_value": None,
         "ratio": None, "target": goal + ("" if judged or not target else
                                          f"; not judged: ceiling {ceiling or 0:.2f}x < 1.8x this round"),
         "ok": speedup >= 1.7 if judged else None},
        # the client's (and the local scheduler's: one process, one GIL) CPU per run after start-up: with 16 workers
        # it must serve 16 runs in one run's time, so this, not the 2-core speedup, shows what limits a big host
        {"name": f"analyse_{tag}_client_cpu_per_run", "value": client_ms, "unit": "ms",
         "baseline_name": "worst of the cluster analyses", "baseline_value": None, "ratio": None,
         "target": "<= 1 ms" if target else None, "ok": client_ms <= 1.0 if target else None},
        # the local cluster's host process (scheduler and nannies), the other process that N workers must not outrun:
        # no target of its own, shown so that moving the scheduler out of the client hides nothing
        *([{"name": f"analyse_{tag}_scheduler_cpu_per_run", "value": scheduler_ms, "unit": "ms",
            "baseline_name": "worst of the cluster analyses (the cluster host: scheduler and nannies)",
            "baseline_value": None, "ratio": None,
            "target": "informational: N workers need N x this below one run's analysis", "ok": None}]
          if scheduler_ms is not None else []),
        {"name": f"analyse_{tag}_speedup_2_workers_median_pair", "value": pairs[len(pairs) // 2], "unit": "x",
         "baseline_name": "median of serial/cluster over the alternating pairs",
         "baseline_value": pairs[0], "ratio": None, "target": f"pairs {', '.join(f'{v:.2f}' for v in pairs)}",
         "ok": None},
        {"name": f"analyse_{tag}_speedup_2_workers_after_startup", "value": phase_serial / phase_cluster,
         "unit": "x", "baseline_name": "same, less start-up", "baseline_value": None, "ratio": None,
         "target": goal, "ok": phase_serial / phase_cluster >= 1.7 if target else None},
        # what two processes of this work get from the machine at this hour (no scheduler, nothing shared): the
        # cluster cannot beat it, and on this shared VM it moved between 1.57x and 1.91x in one morning
        *([{"name": f"analyse_{tag}_machine_ceiling_two_serial_halves", "value": ceiling, "unit": "x",
            "baseline_name": "fastest serial wall / fastest wall of two serial halves at once", "baseline_value": None,
            "ratio": None, "target": None, "ok": None},
           {"name": f"analyse_{tag}_cluster_share_of_machine_ceiling", "value": speedup / ceiling, "unit": "x",
            "baseline_name": "cluster speedup / machine ceiling", "baseline_value": None, "ratio": None,
            "target": ">= 0.9 (what the cluster itself costs)", "ok": speedup / ceiling >= 0.9}] if ceiling else []),
        {"name": f"analyse_{tag}_cluster_wall", "value": cluster["wall"], "unit": "s", "baseline_name": "serial wall",
         "baseline_value": serial["wall"], "ratio": cluster["wall"] / serial["wall"], "target": None, "ok": None},
        {"name": f"analyse_{tag}_cluster_startup", "value": cluster["startup"], "unit": "s",
         "baseline_name": "serial start-up", "baseline_value": serial["startup"],
         "ratio": cluster["startup"] / serial["startup"] if serial["startup"] else None,
         "target": "<= 1.5 s" if target else None, "ok": cluster["startup"] <= 1.5 if target else None},
        {"name": f"analyse_{tag}_cluster_exit", "value": cluster["exit"], "unit": "s",
         "baseline_name": "serial exit", "baseline_value": serial["exit"], "ratio": None,
         "target": "informational: the interpreter's exit after the analysis", "ok": None},
        # the CPU both spent (process and workers): less sensitive to other jobs than the wall times;
        # 2 * serial / cluster is the best speedup two idle cores could give with this much work
        {"name": f"analyse_{tag}_cpu_cluster", "value": cluster["cpu"], "unit": "s", "baseline_name": "serial cpu",
         "baseline_value": serial["cpu"], "ratio": cluster["cpu"] / serial["cpu"], "target": None, "ok": None},
        {"name": f"analyse_{tag}_speedup_bound_2_idle_cores", "value": 2 * serial["cpu"] / cluster["cpu"],
         "unit": "x", "baseline_name": "2 * serial cpu / cluster cpu", "baseline_value": None, "ratio": None,
         "target": None, "ok": None},
        {"name": f"analyse_{tag}_load_average_1min", "value": cluster["load"], "unit": "processes",
         "baseline_name": "during the serial run", "baseline_value": serial["load"],
         "ratio": cluster["load"] / serial["load"] if serial["load"] else None, "target": "< 2 for a clean figure",
         "ok": None},
        {"name": f"analyse_{tag}_parquet_tables_identical", "value": float(identical), "unit": "bool",
         "baseline_name": None, "baseline_value": None, "ratio": None, "target": "1 (serial == cluster)",
         "ok": identical},
    ]


def run(quick: bool = False) -> list[dict]:
    n = int(os.environ.get("HILBENCH_BENCH_CAMPAIGN_RUNS", 0)) or (12 if quick else 200)
    quiet = {"progress": False, "say": lambda _line: None}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, (duration, fs) in enumerate(SIZES[:1] if quick else SIZES):
            rows += _speedup_rows(Path(tmp), n, duration, fs, target=k == len(SIZES) - 1 and not quick)
        folder = Path(tmp) / "faults_campaign"
        write_campaign(folder, SyntheticCampaign(runs=n, duration=2.0, seed=3), fail_runs=(4,))
        faults = analyse([folder], Path(tmp) / "faults", workers=2, dashboard=False, functions={"identify": _dies},
                         **quiet)
        failed = sorted(r["file"] for r in pq.read_table(faults.table).to_pylist() if r["status"] == "failed")
    return rows + [
        {"name": "analyse_faults_rows_failed", "value": float(len(failed)), "unit": "rows",
         "baseline_name": None, "baseline_value": None, "ratio": None,
         "target": f"2 ({FAULT_RUN} worker died twice, id5-1 raised), campaign complete",
         "ok": failed == ["id5-1.h5", FAULT_RUN] and faults.analysed == n},
    ]
