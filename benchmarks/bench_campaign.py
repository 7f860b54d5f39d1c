"""Campaign analysis at scale: a 200-run campaign of short runs (2 s at 1 kHz, the C plant through RunWriter)
analysed by ``hilbench analyse`` serially and on a LocalCluster of 2 worker processes; the speedup (target
>= 1.7x on a 2-core machine), and the two Parquet tables must be identical. Then the faults: one worker dies
(os._exit) on a run and another run raises; the campaign completes with exactly those two rows failed."""

from __future__ import annotations

import os
import resource
import tempfile
from pathlib import Path

import pyarrow.parquet as pq

from hilbench.bench.campaign_analysis.engine import analyse
from hilbench.bench.campaign_analysis.steps import StepSettings, identify_step
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign

FAULT_RUN = "id7-1.h5"


def _cpu() -> float:
    """CPU seconds of this process and of its reaped children (the local cluster's workers, once closed)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _dies(path: str, settings: StepSettings) -> dict:
    if path.endswith(FAULT_RUN):
        os._exit(3)  # the worker dies as on a segfault
    return identify_step(path, settings)


def run(quick: bool = False) -> list[dict]:
    n = 12 if quick else 200
    quiet = {"progress": False, "say": lambda _line: None}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "campaign"
        write_campaign(folder, SyntheticCampaign(runs=n, duration=2.0, seed=3), fail_runs=(4,))
        load_before = os.getloadavg()[0]  # the machine is shared: the figures mean little under others' load
        cpu0 = _cpu()
        serial = analyse([folder], Path(tmp) / "serial", serial=True, **quiet)
        cpu1 = _cpu()
        cluster = analyse([folder], Path(tmp) / "cluster", workers=2, dashboard=False, **quiet)
        cpu2 = _cpu()
        load_after = os.getloadavg()[0]
        identical = pq.read_table(serial.table).equals(pq.read_table(cluster.table))
        faults = analyse([folder], Path(tmp) / "faults", workers=2, dashboard=False, functions={"identify": _dies},
                         **quiet)
        failed = sorted(r["file"] for r in pq.read_table(faults.table).to_pylist() if r["status"] == "failed")
    phase_serial = serial.wall_time - serial.startup_time
    phase_cluster = cluster.wall_time - cluster.startup_time
    return [
        {"name": f"analyse_{n}_runs_speedup_2_workers_end_to_end", "value": serial.wall_time / cluster.wall_time,
         "unit": "x", "baseline_name": "serial wall / cluster wall", "baseline_value": None, "ratio": None,
         "target": ">= 1.7x", "ok": None if quick else serial.wall_time / cluster.wall_time >= 1.7},
        {"name": f"analyse_{n}_runs_speedup_2_workers_after_startup", "value": phase_serial / phase_cluster,
         "unit": "x", "baseline_name": "same, less start-up", "baseline_value": None, "ratio": None,
         "target": ">= 1.7x", "ok": None if quick else phase_serial / phase_cluster >= 1.7},
        {"name": "analyse_cluster_wall", "value": cluster.wall_time, "unit": "s", "baseline_name": "serial wall",
         "baseline_value": serial.wall_time, "ratio": cluster.wall_time / serial.wall_time, "target": None,
         "ok": None},
        {"name": "analyse_cluster_startup", "value": cluster.startup_time, "unit": "s",
         "baseline_name": "serial start-up", "baseline_value": serial.startup_time,
         "ratio": cluster.startup_time / serial.startup_time if serial.startup_time else None,
         "target": None, "ok": None},
        # the CPU both spent: less sensitive to other jobs than the wall times; 2 * serial / cluster is the best
        # speedup two idle cores could give with this much work
        {"name": "analyse_cpu_cluster", "value": cpu2 - cpu1, "unit": "s", "baseline_name": "serial cpu",
         "baseline_value": cpu1 - cpu0, "ratio": (cpu2 - cpu1) / (cpu1 - cpu0), "target": None, "ok": None},
        {"name": "analyse_speedup_bound_2_idle_cores", "value": 2 * (cpu1 - cpu0) / (cpu2 - cpu1), "unit": "x",
         "baseline_name": "2 * serial cpu / cluster cpu", "baseline_value": None, "ratio": None,
         "target": ">= 1.7x", "ok": None},
        {"name": "analyse_load_average_1min", "value": load_after, "unit": "processes",
         "baseline_name": "before the serial run", "baseline_value": load_before,
         "ratio": load_after / load_before if load_before else None, "target": "< 2 for a clean figure",
         "ok": None},
        {"name": "analyse_parquet_tables_identical", "value": float(identical), "unit": "bool", "baseline_name": None,
         "baseline_value": None, "ratio": None, "target": "1 (serial == cluster)", "ok": identical},
        {"name": "analyse_faults_rows_failed", "value": float(len(failed)), "unit": "rows",
         "baseline_name": None, "baseline_value": None, "ratio": None,
         "target": f"2 ({FAULT_RUN} worker died twice, id5-1 raised), campaign complete",
         "ok": failed == ["id5-1.h5", FAULT_RUN] and faults.analysed == n},
    ]
