"""Analyse every run of one or more campaign folders, serially or on a Dask cluster, into a results folder.

Tasks take a chunk of run files' paths (up to :data:`MAX_CHUNK`) and open each inside the worker; what comes
back is one small dict per run. The client alone writes the table (table.ResultsFolder): one part per chunk as it
arrives, compacted at the end. Chunks because a Dask task costs the client and the scheduler (which share one
process and its GIL on a LocalCluster) about 30 ms of CPU, a third of a short run's analysis.

Faults: a step that raises gives a row with status ``failed`` and the one-line reason (caught in the worker).
A worker that dies (segfault, out of memory, ``os._exit``) loses its task; the scheduler gives it to a fresh
worker once (``distributed.scheduler.allowed-failures`` = 1 on the local cluster); a chunk that killed two
workers is split into its runs, each submitted alone (again with one retry), so only the run that kills its
worker becomes a ``failed`` row with the reason. The campaign always completes.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hilbench import __version__
from hilbench.bench.acquisition.campaign import INDEX_NAME
from hilbench.bench.campaign_analysis.fork_server import start_fork_server, warm_up
from hilbench.bench.campaign_analysis.steps import STEPS, StepSettings, steps_for
from hilbench.bench.campaign_analysis.table import ResultsFolder, row_key
from hilbench.bench.errors import AnalyseError

StepFunction = Callable[[str, StepSettings], dict[str, Any]]
#: most runs per task: large enough that the per-task cost vanishes, small enough that both workers stay busy to
#: the end and that a killed client loses little
MAX_CHUNK = 8
_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(\S*)\s*$")
#: environment keys read into numeric columns: key -> (column, accepted units)
ENVIRONMENT = {"ambient": ("ambient", ("C", "degC")), "load": ("load", ("kg",))}


@dataclass
class Task:
    folder: Path
    entry: dict[str, Any]
    step: str
    content_hash: str
    settings_hash: str

    @property
    def path(self) -> Path:
        return self.folder / self.entry["file"]

    @property
    def key(self) -> tuple:
        return (self.folder.name, self.entry["key"], self.content_hash, self.step, self.settings_hash, __version__)


@dataclass
class Summary:
    total: int = 0            # rows of this analysis (runs x supported steps)
    skipped: int = 0          # already in the table (resume)
    analysed: int = 0
    failed: int = 0
    table: Path | None = None
    wall_time: float = 0.0
    startup_time: float = 0.0  # of wall_time: cluster start and every worker's imports of the steps
    dashboard: str | None = None
    failures: list[str] = field(default_factory=list)


def one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return (f"{type(exc).__name__}: {text}")[:400]


def file_hash(path: Path) -> str:
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def settings_hash(step: str, settings: StepSettings) -> str:
    doc = json.dumps({"step": step, "settings": settings.to_dict()}, sort_keys=True)
    return hashlib.sha256(doc.encode()).hexdigest()


def _environment(entry: dict[str, Any], where: str) -> dict[str, float]:
    out: dict[str, float] = {}
    env = entry.get("environment") or {}
    for key, (column, units) in ENVIRONMENT.items():
        if key not in env:
            continue
        raw = env[key]
        m = _QUANTITY.match(str(raw)) if not isinstance(raw, int | float) else None
        if isinstance(raw, int | float):
            out[column] = float(raw)
        elif m and m.group(2) in units:
            out[column] = float(m.group(1))
        else:
            raise AnalyseError(f"{where}: environment {key} = {raw!r} is not a number with unit "
                               f"{' or '.join(units)}")
    return out


def read_campaign(folder: Path) -> list[dict[str, Any]]:
    index = folder / INDEX_NAME
    try:
        doc = json.loads(index.read_text())
        runs = doc["runs"]
        for e in runs:
            e["key"], e["file"]  # noqa: B018 -- both are needed
    except FileNotFoundError:
        raise AnalyseError(f"{folder}: no {INDEX_NAME}; not a campaign folder (hilbench campaign writes one)") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise AnalyseError(f"{index}: unreadable campaign index ({one_line(exc)})") from None
    return runs


def plan(folders: list[Path], steps: tuple[str, ...], settings: StepSettings) -> tuple[list[Task], list[dict]]:
    """(tasks to run, rows of runs that did not complete). Reads every index and hashes every run file."""
    tasks, not_run = [], []
    folders = [f.resolve() for f in folders]  # "." has no name
    names = [f.name for f in folders]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:  # a row names its campaign by the folder's name
        raise AnalyseError(f"two campaign folders are both named {twice[0]!r}; rename one (rows name the campaign "
                           "by its folder)")
    for folder in folders:
        for entry in read_campaign(folder):
            path = folder / entry["file"]
            _environment(entry, f"{folder / INDEX_NAME}: run {entry['key']}")  # a bad unit stops before any work
            for step in steps_for(str(entry.get("protocol", "")), steps):
                if entry.get("status") != "completed" or not path.exists():
                    reason = "run file missing" if not path.exists() else f"run {entry.get('status')}"
                    not_run.append({**_base(folder, entry, step, f"missing:{folder.name}/{entry['key']}",
                                            settings_hash(step, settings)), "status": "not run", "error": reason})
                    continue
                tasks.append(Task(folder, entry, step, file_hash(path), settings_hash(step, settings)))
    return tasks, not_run


def _base(folder: Path, entry: dict[str, Any], step: str, content: str, shash: str) -> dict[str, Any]:
    return {"campaign": folder.name, "folder": str(folder.resolve()), "run_id": entry.get("uid"),
            "key": entry["key"], "name": entry.get("name"), "repeat": entry.get("repeat"),
            "protocol": entry.get("protocol"), "file": entry["file"],
            "environment": json.dumps(entry.get("environment") or {}, sort_keys=True),
            **_environment(entry, f"{folder / INDEX_NAME}: run {entry['key']}"),
            "step": step, "content_hash": content, "settings_hash": shash, "hilbench_version": __version__}


def execute(path: str, step: str, settings: StepSettings, function: StepFunction | None = None) -> dict[str, Any]:
    """Run one step on one file (in a worker); never raises for a failing analysis."""
    from hilbench.bench.campaign_analysis.steps import run_meta

    row: dict[str, Any] = {}
    try:
        row.update(run_meta(path))
        row.update((function or STEPS[step])(path, settings))
        row["status"], row["error"] = "ok", ""
    except Exception as exc:  # a failing run is a row, not the end of the campaign
        row["status"], row["error"] = "failed", one_line(exc)
    return row


def execute_chunk(items: list[tuple[str, str]], settings: StepSettings,
                  functions: dict[str, StepFunction]) -> list[dict[str, Any]]:
    """Run the (path, step) items of one task, in order; one row each; under the execution policy (one BLAS
    thread: analysis.execution), in the serial loop and on any worker, ours or a remote scheduler's."""
    from hilbench.analysis.execution import limited

    with limited():
        return [execute(path, step, settings, functions.get(step)) for path, step in items]


def chunk(todo: list[Task], workers: int) -> list[list[Task]]:
    """Split the tasks into chunks of at most MAX_CHUNK that shrink as the work left does (guided scheduling):
    each is a quarter of the remaining tasks' share per worker, so the last ones are single runs and no worker
    waits for another's last chunk of eight; small campaigns get one run per chunk."""
    out, i, per = [], 0, 4 * max(1, workers)
    while i < len(todo):
        size = max(1, min(MAX_CHUNK, (len(todo) - i) // per))
        out.append(todo[i:i + size])
        i += size
    return out


def _finite_or_none(row: dict[str, Any]) -> dict[str, Any]:
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in row.items()}


def analyse(folders: list[Path], out: Path, steps: tuple[str, ...] = ("identify",),
            settings: StepSettings | None = None, *, serial: bool = False, workers: int | None = None,
            scheduler: str | None = None, scheduler_file: str | None = None, resume: bool = True,
            progress: bool = True, functions: dict[str, StepFunction] | None = None,
            say: Callable[[str], None] = print, verbose: bool = False, dashboard: bool = True) -> Summary:
    """Analyse the runs of ``folders`` into the results folder ``out``; see the module docstring."""
    settings = settings or StepSettings()
    unknown = [s for s in steps if s not in STEPS and s not in (functions or {})]
    if unknown:
        raise AnalyseError(f"unknown step {unknown[0]!r} (available: {', '.join(STEPS)})")
    t0 = time.perf_counter()
    if not (serial or scheduler or scheduler_file):
        start_fork_server()  # its imports (2 s) overlap the planning: hashing every run file
    results = ResultsFolder(out)
    tasks, not_run = plan(folders, steps, settings)
    done = {row_key(r) for r in results.read_rows()} if resume else set()
    summary = Summary(total=len(tasks) + len(not_run))
    todo = [t for t in tasks if t.key not in done]
    summary.skipped = len(tasks) - len(todo)
    if not_run:
        results.add(not_run)
    if summary.skipped:
        say(f"{summary.skipped} of {len(tasks)} analyses already in {out} (resume); {len(todo)} to run")

    def record(done_chunk: list[Task], results_of: list[dict[str, Any]]) -> None:
        rows = []
        for task, result in zip(done_chunk, results_of, strict=True):
            row = {**_base(task.folder, task.entry, task.step, task.content_hash, task.settings_hash), **result}
            rows.append(_finite_or_none(row))
            summary.analysed += 1
            if row["status"] != "ok":
                summary.failed += 1
                summary.failures.append(f"{task.folder.name}/{task.entry['key']} {task.step}: {row['error']}")
        results.add(rows)
        bar.update(len(rows))

    fn = functions or {}
    from tqdm import tqdm

    bar = tqdm(total=len(todo), unit="run", desc="analyse", disable=not progress or not todo, dynamic_ncols=True)
    try:
        if serial:
            warm_up()
            summary.startup_time = time.perf_counter() - t0
            # execute_chunk runs under the execution policy (one BLAS thread; 200 short runs with OpenBLAS's two:
            # 29.9 s of CPU in 15.3 s, against 14.8 s of CPU in 13.9 s with one thread)
            for part in chunk(todo, 1):
                record(part, execute_chunk(_items(part), settings, fn))
        elif todo:
            _on_cluster(todo, settings, fn, record, summary, workers, scheduler, scheduler_file, say, verbose,
                        dashboard, t0)
    finally:
        bar.close()
    summary.table = results.compact(current={t.key for t in tasks} | {row_key(r) for r in not_run})
    summary.wall_time = time.perf_counter() - t0
    return summary


def _items(part: list[Task]) -> list[tuple[str, str]]:
    return [(str(t.path.resolve()), t.step) for t in part]


def _on_cluster(todo: list[Task], settings: StepSettings, fn: dict[str, StepFunction], record,
                summary: Summary, workers: int | None, scheduler: str | None, scheduler_file: str | None,
                say: Callable[[str], None], verbose: bool, want_dashboard: bool, t0: float) -> None:
    import dask
    from distributed import Client, LocalCluster, as_completed
    from distributed.scheduler import KilledWorker

    dashboard: str | None = None
    if want_dashboard:
        try:
            import bokeh  # noqa: F401 -- the dashboard needs it

            dashboard = ":0"  # any free port: several analyses may run on one machine
        except ImportError:
            if verbose:
                say("dask dashboard: not available (it needs the bokeh package); going on without it")
    cluster = None
    # allowed-failures 1: a task whose worker dies is given to a fresh worker once. worker-saturation 1.0: a
    # worker holds only the task it runs (at the default 1.1 a one-thread worker also holds a queued task, and
    # a death then counts against that innocent task too: a 200-run benchmark lost a third row that way)
    # profile off: the worker's statistical profiler samples the task's stack every 10 ms and cost 15-25 % of
    # the CPU of a 0.1 s identification (0.104-0.108 s against 0.077-0.091 s per task, measured)
    # multiprocessing-method forkserver (local cluster only): the workers are forked from a server process that
    # imported what the steps need once (WORKER_MODULES), so none imports scipy & co. itself (3.5 s of CPU each
    # when spawned). A fork server, not a fork of this process: this one runs threads (the cluster's event loop
    # forks), which can deadlock a forked child, and a fork would inherit its BLAS set-up, made before Dask's
    # pre-spawn environment (OMP_NUM_THREADS=1 ...); start_fork_server starts the server in that environment.
    # housekeeping at a run's pace, not a web dashboard's: the event loops' health tick every 200 ms (20 ms), the
    # system monitor every 2 s (0.5 s), the worker's memory check every 1 s (0.1 s), no work stealing (the chunks
    # are sized here): the client process (scheduler, nannies) spent 3.3-3.6 s of CPU on a 200-run campaign with
    # Dask's defaults, 2.6 s with these, on the two cores the workers need
    with dask.config.set({"distributed.scheduler.allowed-failures": 1, "distributed.scheduler.worker-saturation": 1.0,
                          "distributed.worker.profile.enabled": False, "distributed.admin.tick.limit": "60s",
                          "distributed.admin.tick.interval": "200ms", "distributed.admin.system-monitor.interval": "2s",
                          "distributed.worker.memory.monitor-interval": "1s",
                          "distributed.scheduler.work-stealing": False,
                          "distributed.worker.multiprocessing-method": "forkserver"}):
        if scheduler or scheduler_file:
            client = Client(scheduler, scheduler_file=scheduler_file, timeout="20s")
        else:
            cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                                   dashboard_address=dashboard, silence_logs=logging.CRITICAL)
            client = Client(cluster)
        try:
            if dashboard is not None and client.dashboard_link:
                summary.dashboard = client.dashboard_link
                say(f"dask dashboard: {client.dashboard_link}")
            client.run(warm_up)  # a remote worker imports before the tasks (a forked one has); startup_time: how long
            summary.startup_time = time.perf_counter() - t0
            n_workers = len(client.scheduler_info()["workers"]) or 1
            futures = as_completed()
            submitted: dict[Any, list[Task]] = {}

            def submit(part: list[Task]) -> None:
                future = client.submit(execute_chunk, _items(part), settings, fn, pure=False)
                submitted[future] = part
                futures.add(future)

            for part in chunk(todo, n_workers):
                submit(part)
            for future in futures:
                part = submitted.pop(future)
                try:
                    rows = future.result()
                except KilledWorker as exc:
                    if len(part) > 1:  # one of its runs kills workers: find which, run by run
                        for task in part:
                            submit([task])
                        continue
                    rows = [{"status": "failed", "error": f"the worker died twice while analysing this run "
                                                          f"({one_line(exc)})"}]
                except Exception as exc:  # e.g. a result that cannot be unpickled
                    rows = [{"status": "failed", "error": one_line(exc)}] * len(part)
                record(part, rows)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
