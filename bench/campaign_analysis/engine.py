"""Analyse every run of one or more campaign folders, serially or on a Dask cluster, into a results folder.

The client reads the campaign indexes and stats the run files (it opens none: a FIFO or a device is a failed row at
once), and holds the results folder's lock (table.LOCK_NAME) throughout. Tasks take a chunk of runs (up to
:data:`MAX_CHUNK`); the worker hashes each file, checks its uid against the index, analyses it unless its row is
there, writes the chunk's rows as one part of the results folder (table.write_part) and returns only their keys.
The client compacts the parts into the table at the end. Chunks because a Dask task costs the client and the
scheduler 1-4 ms of CPU. The local cluster (scheduler, nannies, the workers' fork server) runs in a process of its
own (cluster_host), so that this process does the client's work only.

Faults: a step that raises gives a row with status ``failed`` and the one-line reason (caught in the worker).
A worker that dies (segfault, out of memory, ``os._exit``) loses its task; the scheduler gives it to a fresh
worker once (``distributed.scheduler.allowed-failures`` = 1 on the local cluster); a chunk that killed two
workers is split into its runs, each submitted alone (again with one retry), so only the run that kills its
worker becomes a ``failed`` row with the reason. The campaign always completes.
"""

from __future__ import annotations

import concurrent.futures
import hashlib
import json
import logging
import math
import os
import re
import stat
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hilbench import __version__
from hilbench.bench.campaign_analysis import cluster_host, opaque
from hilbench.bench.campaign_analysis.fork_server import MAX_WORKERS, warm_up
from hilbench.bench.campaign_analysis.steps import STEPS, StepSettings, steps_for
from hilbench.bench.campaign_analysis.table import ResultsFolder, row_key
from hilbench.bench.campaign_index import INDEX_NAME
from hilbench.bench.errors import AnalyseError

StepFunction = Callable[[str, StepSettings], dict[str, Any]]
#: most runs per task: large enough that the per-task cost vanishes (a task costs the client about 2.7 ms of CPU:
#: its round trips and reading its part; the scheduler as much again; and its worker waits 9-18 ms between two tasks,
#: Dask's hand-over through the scheduler), small enough that a worker's death or a killed client loses little. 32
#: with chunks of a worker's share of what is left: 12 tasks for 200 runs on 2 workers (24 with 16 and half a share:
#: 0.1 s less wall time in three alternating pairs, 6.14-6.50 s against 6.24-6.61 s), the last 3 single runs
MAX_CHUNK = 32
_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(\S*)\s*$")
#: environment keys read into numeric columns: key -> (column, accepted units)
#: largest campaign index read, bytes (a thousand runs are ~1 MB)
MAX_INDEX_BYTES = 64 << 20
ENVIRONMENT = {"ambient": ("ambient", ("C", "degC")), "load": ("load", ("kg",))}


@dataclass
class Task:
    """One run and step to analyse. ``known``: content hashes this run and step already have rows for (a copy of
    a campaign: the worker hashes the file, finds its row, and analyses nothing)."""
    folder: Path
    entry: dict[str, Any]
    step: str
    campaign_uid: str
    settings_hash: str
    base: dict[str, Any]
    known: tuple[str, ...] = ()

    @property
    def path(self) -> Path:
        return self.folder / self.entry["file"]


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
    client_cpu: float = 0.0    # s of this process's CPU (the client's; the local cluster's scheduler runs in its host)
    startup_cpu: float = 0.0   # of client_cpu: before the first task (imports, planning, cluster start)
    work_cpu: float = 0.0      # of client_cpu: from the first task to the table written (not the cluster's close)
    scheduler_cpu: float | None = None  # s of the scheduler's process's CPU from the first task to the last result
    # (the local cluster's host: scheduler and nannies; None serially, or if the scheduler runs no functions)

    @property
    def client_cpu_per_run(self) -> float:
        """s of this process's CPU per analysed run from the first task to the table: with N workers the client
        must handle N runs in the time one run's analysis takes; measurable on 2 cores."""
        return self.work_cpu / max(1, self.analysed + self.skipped)

    @property
    def scheduler_cpu_per_run(self) -> float | None:
        """s of the scheduler's process's CPU per analysed run (scheduler and nannies on a local cluster): the
        other process that must keep up with N workers."""
        return None if self.scheduler_cpu is None else self.scheduler_cpu / max(1, self.analysed + self.skipped)


def one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return (f"{type(exc).__name__}: {text}")[:400]


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


#: index entry fields and the types they must have (None allowed where the tuple has type(None))
ENTRY_TYPES: dict[str, tuple[type, ...]] = {
    "key": (str,), "file": (str,), "status": (str,), "uid": (str, type(None)), "protocol": (str, type(None)),
    "name": (str, type(None)), "repeat": (int, type(None)), "environment": (dict, type(None)),
    "planned": (bool,)}


def _check_entry(index: Path, i: int, e: Any) -> None:
    """One line naming the entry for an index entry that is not what ``hilbench campaign`` writes."""
    if not isinstance(e, dict):
        raise AnalyseError(f"{index}: runs[{i}] is {type(e).__name__}, not an object")
    for name, types in ENTRY_TYPES.items():
        if name in e and (not isinstance(e[name], types) or (isinstance(e[name], bool) and bool not in types)):
            raise AnalyseError(f"{index}: runs[{i}] ({str(e.get('key'))[:60]!r}): {name} is "
                               f"{type(e[name]).__name__}, not {' or '.join(t.__name__ for t in types)}")
    for name in ("key", "file"):
        if name not in e:
            raise AnalyseError(f"{index}: runs[{i}]: no {name}")
    if e["file"] in ("", ".", "..") or "/" in e["file"] or "\0" in e["file"]:
        raise AnalyseError(f"{index}: runs[{i}] ({e['key'][:60]!r}): file {e['file'][:80]!r} is not a file name "
                           "in the campaign folder")


def read_campaign_document(folder: Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """(the index document, its run entries, each type-checked); one line for anything else."""
    index = folder / INDEX_NAME
    try:
        with open(index, "rb") as fh:  # bounded: an index is kilobytes, not a FIFO that never ends
            if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
                raise ValueError("not a regular file")
            raw = fh.read(MAX_INDEX_BYTES + 1)
        if len(raw) > MAX_INDEX_BYTES:
            raise ValueError(f"longer than {MAX_INDEX_BYTES} bytes")
        doc = json.loads(raw)
        if not isinstance(doc, dict) or not isinstance(doc.get("runs"), list):
            raise ValueError("no list of runs")
    except FileNotFoundError:
        raise AnalyseError(f"{folder}: no {INDEX_NAME}; not a campaign folder (hilbench campaign writes one)") from None
    except (OSError, ValueError, RecursionError) as exc:
        raise AnalyseError(f"{index}: unreadable campaign index ({one_line(exc)})") from None
    for i, e in enumerate(doc["runs"]):
        _check_entry(index, i, e)
    if "uid" in doc and not isinstance(doc["uid"], str):
        raise AnalyseError(f"{index}: uid is {type(doc['uid']).__name__}, not a string")
    return doc, doc["runs"]


def campaign_uid(folder: Path, doc: dict[str, Any], wait: float = 5.0) -> str:
    """The campaign's uid; a campaign of an older hilbench gets one now, written into its index under the
    campaign's own lock (a playing campaign holds it for a few seconds at most between runs)."""
    if isinstance(doc.get("uid"), str):
        return doc["uid"]
    if not os.access(folder, os.W_OK):  # a read-only archive: a uid from its runs' uids, the same in every copy
        runs = sorted(str(e.get("uid")) for e in doc["runs"])
        return "runs-" + hashlib.sha256(json.dumps(runs).encode()).hexdigest()[:32]
    from hilbench.bench.acquisition.campaign import (
        LOCK_NAME,
        CampaignError,
        new_campaign_uid,
        write_index_document,
    )
    from hilbench.bench.storage.folder_lock import folder_lock

    deadline = time.monotonic() + wait
    while True:
        try:
            with folder_lock(folder, LOCK_NAME, CampaignError, lambda pid: f"pid {pid}"):
                doc, _ = read_campaign_document(folder)  # another analysis may have given it one meanwhile
                if not isinstance(doc.get("uid"), str):
                    doc["uid"] = new_campaign_uid()
                    write_index_document(folder, doc)
                return doc["uid"]
        except CampaignError as exc:
            if time.monotonic() > deadline:
                raise AnalyseError(f"{folder}: has no campaign uid yet (an older campaign) and its lock is held "
                                   f"({exc}); analyse it when that process ends") from None
            time.sleep(0.1)


def _regular(path: Path) -> tuple[str | None, os.stat_result | None]:
    """(why ``path`` cannot be a run file, or None; its stat) without opening it (a FIFO's open blocks)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return "run file missing", None
    except OSError as exc:
        return f"cannot stat: {exc.strerror}", None
    if not stat.S_ISREG(st.st_mode):
        return f"not a regular file ({_KIND.get(stat.S_IFMT(st.st_mode), 'special file')})", st
    return None, st


_KIND = {stat.S_IFDIR: "a directory", stat.S_IFIFO: "a FIFO", stat.S_IFCHR: "a character device",
         stat.S_IFBLK: "a block device", stat.S_IFSOCK: "a socket"}


def plan(folders: list[Path], steps: tuple[str, ...], settings: StepSettings,
         existing: dict[tuple, dict[str, Any]] | None = None
         ) -> tuple[list[Task], list[dict], dict[tuple, dict[str, Any]], set[tuple]]:
    """(tasks to run, rows the client writes itself (runs not run, files that are no run file), current row keys
    of runs whose row is there -> fields to refresh, unplanned (campaign uid, key)). Reads every index and stats
    every run file; reads no run file: a run whose stat matches its row's (``file_stat``) is not hashed again."""
    by_run: dict[tuple, list[dict[str, Any]]] = {}
    for r in (existing or {}).values():
        by_run.setdefault((r.get("campaign_uid"), r.get("key"), r.get("run_id"), r.get("step"),
                           r.get("settings_hash"), r.get("hilbench_version")), []).append(r)
    tasks, own_rows, reused, unplanned, seen = [], [], {}, set(), set()
    shashes = {step: settings_hash(step, settings) for step in steps}
    for folder in [f.resolve() for f in folders]:  # "." has no name
        doc, entries = read_campaign_document(folder)
        cuid = campaign_uid(folder, doc)
        for entry in entries:
            where = f"{folder / INDEX_NAME}: run {entry['key'][:80]}"
            _environment(entry, where)  # a bad unit stops before any work
            if entry.get("planned") is False:  # a run its campaign no longer plans (resumed with fewer repeats)
                unplanned.add((cuid, entry["key"]))
                continue
            path = folder / entry["file"]
            why, st = _regular(path)  # one stat per run, whatever its steps
            for step in steps_for(str(entry.get("protocol", "")), steps):
                shash = shashes[step]
                if (cuid, entry["key"], step) in seen:  # the same campaign twice (a copy beside its original)
                    continue
                seen.add((cuid, entry["key"], step))
                base = _base(folder, cuid, entry, step, shash)
                if why == "run file missing" or (why is None and entry.get("status") != "completed"
                                                 and not settings.allow_incomplete):
                    own_rows.append({**base, "content_hash": "", "status": "not run",
                                     "error": why or f"run {entry.get('status')}"})
                    continue
                if why is not None:  # a FIFO, a device, a directory: a failed row at once, never opened
                    own_rows.append({**base, "content_hash": "", "status": "failed", "error": f"{path}: {why}"})
                    continue
                rows = by_run.get((cuid, entry["key"], entry.get("uid"), step, shash, __version__), [])
                fingerprint = file_stat(st)
                same = [r for r in rows if r.get("file_stat") == fingerprint]
                if same:
                    reused[row_key(same[0])] = _refresh(base)
                else:
                    tasks.append(Task(folder, entry, step, cuid, shash, base,
                                      tuple(sorted({r["content_hash"] for r in rows if r.get("content_hash")}))))
    return tasks, own_rows, reused, unplanned


def file_stat(st: os.stat_result) -> str:
    return f"{st.st_size}:{st.st_mtime_ns}:{st.st_ctime_ns}:{st.st_ino}"


#: columns a reused row takes from the index as it is now (a renamed or moved campaign)
REFRESHED = ("campaign", "folder", "name", "repeat", "protocol", "file", "environment", "ambient", "load")


def _refresh(base: dict[str, Any]) -> dict[str, Any]:
    return {k: base.get(k) for k in REFRESHED}


def _base(folder: Path, cuid: str, entry: dict[str, Any], step: str, shash: str) -> dict[str, Any]:
    return {"campaign": folder.name, "campaign_uid": cuid, "folder": str(folder), "run_id": entry.get("uid"),
            "key": entry["key"], "name": entry.get("name"), "repeat": entry.get("repeat"),
            "protocol": entry.get("protocol"), "file": entry["file"],
            "environment": json.dumps(entry.get("environment") or {}, sort_keys=True),
            **_environment(entry, f"{folder / INDEX_NAME}: run {entry['key'][:80]}"),
            "step": step, "settings_hash": shash, "hilbench_version": __version__}


def _where() -> str:
    """This process as a row's error names it: the Dask worker's address, or the host."""
    try:
        from distributed import get_worker

        return f"worker {get_worker().address}"
    except (ImportError, ValueError):
        import socket

        return f"host {socket.gethostname()}"


def _hash_regular(path: str) -> tuple[str, str]:
    """(sha256, file_stat) of a regular file, read through one descriptor that is checked before it is read
    (O_NONBLOCK: a FIFO swapped in after planning does not block the open; fstat then refuses it)."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise OSError(f"not a regular file ({_KIND.get(stat.S_IFMT(st.st_mode), 'special file')})")
        with os.fdopen(os.dup(fd), "rb") as fh:
            digest = hashlib.file_digest(fh, "sha256").hexdigest()
        return digest, file_stat(st)
    finally:
        os.close(fd)


def execute(path: str, step: str, settings: StepSettings, function: StepFunction | None = None,
            uid: str | None = None) -> dict[str, Any]:
    """Run one step on one file (in a worker); never raises for a failing analysis. ``uid``: the run's uid in
    its campaign index; a file of another uid (a swapped or replaced file) is a failed row saying so."""
    from hilbench.bench.campaign_analysis.steps import run_meta

    row: dict[str, Any] = {}
    try:
        row.update(run_meta(path))
        if uid is not None and row["run_id"] != uid:
            raise AnalyseError(f"{path}: the file's run uid {row['run_id']} is not its index entry's {uid} "
                               "(a swapped or replaced file)")
        row.update((function or STEPS[step])(path, settings))
        row["status"], row["error"] = "ok", ""
    except Exception as exc:  # a failing run is a row, not the end of the campaign
        row["status"], row["error"] = "failed", one_line(exc)
    if uid is not None:
        row["run_id"] = uid  # the row is the index entry's run, whatever the file holds
    return row


#: what a task returns per run: its row's key, status, error, and the file's stat when an existing row was reused
Outcome = tuple[tuple, str, str, str | None]


def execute_chunk(items: list[dict[str, Any]], settings: StepSettings, functions: dict[str, StepFunction],
                  results: str) -> list[Outcome]:
    """Run the items (path, step, base row, uid, known hashes) of one task in order, in the worker: hash each
    file, analyse it unless its row is there (``known``), write the new rows as one part of the results folder,
    and return only their keys and statuses (the client reads no run file and writes no row)."""
    from hilbench.analysis.execution import limited
    from hilbench.bench.campaign_analysis.table import row_key, write_part

    with limited():  # the execution policy (one BLAS thread): in the serial loop and on any worker
        return _execute_items(items, settings, functions, results, row_key, write_part)


def _execute_items(items, settings, functions, results, row_key, write_part) -> list[Outcome]:
    rows, out = [], []
    for item in items:
        try:
            content, fstat = _hash_regular(item["path"])
        except OSError as exc:  # gone, unreadable, swapped for a FIFO: the worker that could not open it is named
            row = {**item["base"], "content_hash": "", "status": "failed",
                   "error": f"{item['path']}: cannot open on {_where()}: {exc.strerror or exc}"}
        else:
            row = {**item["base"], "content_hash": content, "file_stat": fstat}
            if content in item["known"]:  # a copy or a touched file: its row is there
                out.append((row_key(row), "reused", "", fstat))
                continue
            row.update(execute(item["path"], item["step"], settings, functions.get(item["step"]), item["uid"]))
        rows.append(_finite_or_none(row))
        out.append((row_key(row), row["status"], row["error"], None))
    if rows:
        write_part(results, rows)
    return out


def execute_chunk_timed(items: list[dict[str, Any]], settings: StepSettings, functions: dict[str, StepFunction],
                        results: str) -> tuple[float, list[Outcome]]:
    """(when the task began on its worker, time.time(); :func:`execute_chunk`'s outcomes): the cluster's start-up
    figure ends at its first task's start."""
    began = time.time()
    return began, execute_chunk(items, settings, functions, results)


def chunk(todo: list[Task], workers: int) -> list[list[Task]]:
    """Split the tasks into chunks of at most MAX_CHUNK that shrink as the work left does (guided self-scheduling):
    each is the remaining tasks' share per worker, so the last ones are single runs and no worker waits long for
    another's last big chunk; small campaigns get small chunks."""
    out, i, per = [], 0, max(1, workers)
    while i < len(todo):
        size = max(1, min(MAX_CHUNK, (len(todo) - i) // per))
        out.append(todo[i:i + size])
        i += size
    return out


def _finite_or_none(row: dict[str, Any]) -> dict[str, Any]:
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in row.items()}


#: how long a remote scheduler has to answer, s
CONNECT_TIMEOUT = 10.0


def analyse(folders: list[Path], out: Path, steps: tuple[str, ...] = ("identify",),
            settings: StepSettings | None = None, *, serial: bool = False, workers: int | None = None,
            scheduler: str | None = None, scheduler_file: str | None = None, resume: bool = True,
            progress: bool = True, functions: dict[str, StepFunction] | None = None,
            say: Callable[[str], None] = print, verbose: bool = False, dashboard: bool = True) -> Summary:
    """Analyse the runs of ``folders`` into the results folder ``out``; see the module docstring."""
    from hilbench.bench.campaign_analysis.table import LOCK_NAME
    from hilbench.bench.storage.folder_lock import folder_lock

    settings = settings or StepSettings()
    unknown = [s for s in steps if s not in STEPS and s not in (functions or {})]
    if unknown:
        raise AnalyseError(f"unknown step {unknown[0]!r} (available: {', '.join(STEPS)})")
    if workers is not None and not 1 <= workers <= MAX_WORKERS:
        raise AnalyseError(f"--workers must be in 1..{MAX_WORKERS}, got {workers}")
    t0, cpu0 = time.perf_counter(), time.process_time()
    if not serial and (scheduler or scheduler_file):
        scheduler, scheduler_file = _connect(scheduler, scheduler_file), None  # a Dask scheduler, before any work
    if not (serial or scheduler or scheduler_file):  # the cluster's start (2-3 s of CPU) overlaps the planning
        cluster_host.start_early(cluster_host.local_workers(workers), cluster_host.dashboard_address(dashboard))
    out = Path(out).absolute()  # a remote worker resolves a relative path against its own directory
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise AnalyseError(f"{out}: cannot create the results folder ({exc.strerror})") from None
    def busy(pid):
        return (f"{out}: another analysis is writing into this results folder (pid {pid}); wait for it "
                "or use another -o")
    try:
        with folder_lock(out, LOCK_NAME, AnalyseError, busy, say):
            summary = _analyse_locked(folders, out, steps, settings, serial, workers, scheduler,
                                      resume, progress, functions or {}, say, verbose, dashboard, t0, cpu0)
    finally:
        cluster_host.discard()  # started early and not needed (every row there, or a refusal)
    summary.wall_time = time.perf_counter() - t0
    summary.client_cpu = time.process_time() - cpu0
    return summary


def _analyse_locked(folders, out, steps, settings, serial, workers, scheduler, resume, progress,
                    fn, say, verbose, dashboard, t0, cpu0) -> Summary:
    results = ResultsFolder(out, say)
    results.clean_leftovers()  # of a killed analysis: this one holds the lock, so none is work in progress
    existing = results.read_rows()
    tasks, own_rows, reused, unplanned = plan(folders, steps, settings, existing if resume else None)
    summary = Summary(total=len(tasks) + len(own_rows) + len(reused), skipped=len(reused))
    current: dict[tuple, dict[str, Any]] = dict(reused)
    if own_rows:
        results.add(own_rows)
        current.update({row_key(r): {} for r in own_rows})
    if reused:
        say(f"{len(reused)} of {len(reused) + len(tasks)} analyses already in {out} (resume); {len(tasks)} to run")

    def record(done_chunk: list[Task], outcomes: list[Outcome]) -> None:
        for task, (key, status, error, fstat) in zip(done_chunk, outcomes, strict=True):
            base = _refresh(task.base)
            current[key] = {**base, "file_stat": fstat} if fstat else base
            if status == "reused":
                summary.skipped += 1
                continue
            summary.analysed += 1
            if status != "ok":
                summary.failed += 1
                summary.failures.append(f"{task.folder.name}/{task.entry['key']} {task.step}: {error}")
        if bar is not None:
            bar.update(len(outcomes))

    # no bar at all without progress, not a disabled one: tqdm takes a lock shared across fork (a multiprocessing
    # RLock) even to register a disabled bar, and a forked analysis killed inside it left the next one waiting
    # forever (the chaos test's last analysis hung so)
    bar, host = None, None
    if progress and tasks:
        from tqdm import tqdm

        bar = tqdm(total=len(tasks), unit="run", desc="analyse", dynamic_ncols=True)
    try:
        if serial:
            warm_up()
            summary.startup_time, summary.startup_cpu = time.perf_counter() - t0, time.process_time() - cpu0
            # execute_chunk runs under the execution policy (one BLAS thread; 200 short runs with OpenBLAS's two:
            # 29.9 s of CPU in 15.3 s, against 14.8 s of CPU in 13.9 s with one thread)
            cpu = time.process_time()
            for part in chunk(tasks, 2):  # parts as two workers' (what a killed loop keeps: all but its last)
                record(part, execute_chunk(_items(part), settings, fn, str(out)))
            summary.work_cpu += time.process_time() - cpu  # (serial: the analyses themselves)
        elif tasks:
            host = _on_cluster(tasks, settings, fn, record, summary, workers, scheduler, say, verbose, dashboard, t0,
                               cpu0, out)
    finally:
        if bar is not None:
            bar.close()
    try:
        cpu = time.process_time()
        summary.table = results.compact(results.read_rows(), current, unplanned)
        summary.work_cpu += time.process_time() - cpu
    finally:
        if host is not None:  # it ended its cluster while the table was written (0.07 s; the table 0.04 s)
            host.close()
    return summary


def _items(part: list[Task]) -> list[dict[str, Any]]:
    return [{"path": str(t.path), "step": t.step, "base": t.base, "uid": t.entry.get("uid"), "known": t.known}
            for t in part]


def _died(task: Task, exc: BaseException, out: Path) -> Outcome:
    """The failed row of a run that killed its worker twice (written by the client: no worker can)."""
    from hilbench.bench.campaign_analysis.table import write_part

    try:
        content, fstat = _hash_regular(str(task.path))
    except OSError:
        content, fstat = "", None
    row = {**task.base, "content_hash": content, "file_stat": fstat, "status": "failed",
           "error": f"the worker died twice while analysing this run ({one_line(exc)})"}
    write_part(out, [row])
    return row_key(row), row["status"], row["error"], None


def _check_writable(results: str, dask_worker: Any = None) -> str | None:
    """In a worker (``Client.run`` passes ``dask_worker``): None if it can write the results folder, else why
    not (one line)."""
    import uuid

    probe = Path(results) / f".probe-{uuid.uuid4().hex[:8]}.tmp"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        where = f"worker {dask_worker.address}" if dask_worker is not None else _where()
        return f"{where} cannot write the results folder {results} ({exc.strerror})"
    return None


def _connect(scheduler: str | None, scheduler_file: str | None) -> str:
    """The scheduler's address, after checking within :data:`CONNECT_TIMEOUT` that a Dask scheduler answers there
    (a Dask peer speaks first: an 8-byte frame length; anything else, or silence, is one line, not a hang or a
    client that reads some other service's bytes as a length)."""
    import socket
    import struct
    from urllib.parse import urlsplit

    address = scheduler
    if scheduler_file:
        try:
            with open(scheduler_file, "rb") as fh:
                if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
                    raise ValueError("not a regular file")
                doc = json.loads(fh.read(1 << 20))
            address = doc["address"]
            if not isinstance(address, str):
                raise TypeError("its address is not a string")
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise AnalyseError(f"--scheduler-file {scheduler_file}: no Dask scheduler file ({one_line(exc)})") from None
    assert address is not None
    if "://" not in address:
        address = f"tcp://{address}"
    parts = urlsplit(address)
    if parts.scheme != "tcp":
        return address  # tls, ucx, ...: Dask's own connect timeout applies
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        host = port = None
    if not host or not port:
        raise AnalyseError(f"--scheduler {address}: not an address like tcp://HOST:8786")
    try:
        with socket.create_connection((host, port), timeout=CONNECT_TIMEOUT) as sock:
            header = b""
            while len(header) < 16:
                got = sock.recv(16 - len(header))
                if not got:
                    break
                header += got
    except TimeoutError:
        raise AnalyseError(f"--scheduler {address}: no answer within {CONNECT_TIMEOUT:g} s; is a Dask scheduler "
                           "listening there?") from None
    except OSError as exc:
        raise AnalyseError(f"--scheduler {address}: cannot connect ({exc.strerror or exc})") from None
    total, frames = struct.unpack("<QQ", header) if len(header) == 16 else (0, 0)
    if not (0 < total < 1 << 24 and 0 < frames < 64):
        raise AnalyseError(f"--scheduler {address}: the service there does not speak Dask's protocol")
    return address


def _on_cluster(todo: list[Task], settings: StepSettings, fn: dict[str, StepFunction], record,
                summary: Summary, workers: int | None, scheduler: str | None, say: Callable[[str], None],
                verbose: bool, want_dashboard: bool, t0: float, cpu0: float, out: Path) -> cluster_host.Host | None:
    import dask
    from distributed import Client, as_completed
    from distributed.scheduler import KilledWorker

    t0_wall = time.time() - (time.perf_counter() - t0)  # the command's start on the workers' clock
    dashboard = cluster_host.dashboard_address(want_dashboard)
    if want_dashboard and dashboard is None and verbose:
        say("dask dashboard: not available (it needs the bokeh package); going on without it")
    address = scheduler  # checked by _connect
    host, done = None, False
    # the local cluster's settings are the cluster host's (cluster_host.CONFIG); this client's own: the same where
    # they apply to it, and the connect timeout
    # Dask's own log lines (a lost scheduler, a rescheduled task) stay out of the command's output unless -v: what
    # they mean reaches the user as this command's one line or as a row's error
    with (dask.config.set({**cluster_host.CONFIG, "distributed.comm.timeouts.connect": f"{CONNECT_TIMEOUT:g}s"}),
          _quiet(logging.getLogger("distributed"), not verbose)):
        if address is None:  # the local cluster, in a process of its own (cluster_host)
            host = cluster_host.take(cluster_host.local_workers(workers), dashboard)
            try:
                address, summary.dashboard = host.address()
            except BaseException:  # e.g. Ctrl-C while it starts: no host outlives this call (the GUI lives on)
                host.proc.kill()
                host.close()
                raise
        try:
            client = Client(address, timeout=f"{CONNECT_TIMEOUT:g}s")
        except (OSError, TimeoutError) as exc:
            if host is not None:
                host.close()
            where = f"--scheduler {address}" if scheduler else f"the local cluster at {address}"
            raise AnalyseError(f"{where}: cannot connect ({one_line(exc)})") from None
        try:
            if dashboard is not None and (summary.dashboard or client.dashboard_link):
                summary.dashboard = summary.dashboard or client.dashboard_link
                say(f"dask dashboard: {summary.dashboard}")
            if host is None:  # a remote cluster: its workers are up, they must reach the results folder at the same
                # path, and they import the steps before the first task (a local worker is forked from a fork server
                # that has)
                refused = [why for why in client.run(_check_writable, str(out)).values() if why]
                if refused:
                    raise AnalyseError(refused[0])
                client.run(warm_up)
                n_workers = len(client.scheduler_info()["workers"]) or 1
            else:  # connected while the workers start; the tasks go once they are up (Host.wait_up)
                try:
                    host.wait_up()
                except AnalyseError:
                    host.proc.kill()
                    raise
                n_workers = cluster_host.local_workers(workers)
            summary.startup_cpu = time.process_time() - cpu0
            futures = as_completed()
            submitted: dict[Any, list[Task]] = {}
            began: list[float] = []  # when each task began on its worker (time.time())

            def submit(part: list[Task]) -> None:
                payload = opaque.pack(execute_chunk_timed, _items(part), settings, fn, str(out))
                future = client.submit(opaque.call, payload, key=f"analyse-chunk-{uuid.uuid4().hex}")
                submitted[future] = part
                futures.add(future)

            loop_cpu, scheduler_cpu = time.process_time(), _scheduler_cpu(client)
            for part in chunk(todo, n_workers):
                submit(part)
            for future in futures:
                part = submitted.pop(future)
                try:
                    start, outcomes = future.result()
                    began.append(start)
                except KilledWorker as exc:
                    if len(part) > 1:  # one of its runs kills workers: find which, run by run
                        for task in part:
                            submit([task])
                        continue
                    outcomes = [_died(part[0], exc, out)]
                except Exception as exc:  # e.g. a result that cannot be unpickled: the chunk's runs fail here
                    # a lost scheduler cancels every task, and a connection to it or a worker may close first: the
                    # host's word (or its end: its sockets may close a moment before its reply pipe) comes soon
                    lost = isinstance(exc, concurrent.futures.CancelledError)
                    if host is not None:
                        why = host.failure(wait=5.0 if lost or isinstance(exc, OSError) else 0.0)
                        why = why and f"the local cluster failed: {why}"
                    else:
                        why = f"the connection to --scheduler {address} was lost ({one_line(exc)[:200]})" if lost \
                            else None
                    if why is not None:  # not the runs': the cluster itself is gone; what its workers wrote stays
                        raise AnalyseError(f"{why}; the rows of the runs it finished are kept: the same command "
                                           "again analyses the rest") from None
                    outcomes = [_died(task, exc, out) for task in part]
                record(part, outcomes)
            summary.work_cpu += time.process_time() - loop_cpu
            # start-up: from the command's start to the first task's start on a worker (the local cluster's tasks
            # are submitted while its workers start)
            summary.startup_time = (min(began) - t0_wall if began else time.perf_counter() - t0)
            end = _scheduler_cpu(client)
            if scheduler_cpu is not None and end is not None:
                summary.scheduler_cpu = end - scheduler_cpu
            done = True
        finally:
            client.close()
            if host is not None:  # told to end now; waited for after the compaction, unless this call fails
                host.close(wait=not done)
    return host


@contextmanager
def _quiet(logger: logging.Logger, quiet: bool) -> Iterator[None]:
    """Only critical records through ``logger``'s handlers while it runs, if ``quiet``: Dask logs through the
    handlers of its ``distributed`` logger, and its child loggers' records reach them whatever the parent's
    level."""
    handlers = [(h, h.level) for h in logger.handlers] if quiet else []
    for h, _ in handlers:
        h.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for h, level in handlers:
            h.setLevel(level)


def _scheduler_cpu(client: Any) -> float | None:
    """s of CPU the scheduler's process has spent (the cluster host's: scheduler and nannies), or None if the
    scheduler does not run functions sent to it (``distributed.scheduler.pickle`` off)."""
    try:
        return float(client.run_on_scheduler(time.process_time))
    except Exception:  # noqa: BLE001 -- a figure of the summary, not a reason to stop
        return None
