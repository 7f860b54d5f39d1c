"""The local cluster in a process of its own: the Dask scheduler, the nannies and the fork server of the workers run
in a child process of ``hilbench analyse`` (the *cluster host*), and the command is one more client of it, as with
``--scheduler``. So the command's process carries only the client's work: with the scheduler and the nannies in it
(one process, one GIL, one event loop) it spent 1.4-2 ms of CPU per analysed run on 200 runs of 5 s at 5 kHz on a
quiet 2-core machine, and 5-8 ms under load, most of it the scheduler's ticks, the workers' heartbeats and the
nannies' monitors, which grow with the wall time, not the work. The host's own CPU per run is reported beside the
client's (engine.Summary.scheduler_cpu_per_run): with N workers it is what one scheduler process must keep up with.

The host starts the workers' fork server first thing, before it imports anything of hilbench or Dask: the server's
imports (:data:`fork_server.WORKER_MODULES`, about 1-2 s on one core) are the cluster's critical path. It is started
from a ``-c`` program (:data:`BOOT`), not ``-m``: multiprocessing would make the fork server and every worker import
a ``__main__`` module again.

The host gets its worker count and dashboard on its command line and starts the cluster at once, so that the whole
start (the fork server's imports, distributed's, the scheduler, the workers) overlaps the client's own imports and
planning. It answers with JSON lines on a copy of its stdout (its stdout itself goes to stderr, so that nothing a
library prints can break the reply): ``{"address", "dashboard"}`` as soon as the scheduler listens (the client
connects while the workers start), then ``{"workers"}`` once they are up (the client submits then: a task that
killed its worker during the start would fail the start itself), or ``{"error"}`` instead of either, after which it
exits (its start is bounded by :data:`START_TIMEOUT`). Then it holds the cluster until its stdin ends (the client
closed it, or died however it died: no cluster outlives its client), closes it, kills and reaps the fork server (so
that its and its workers' CPU reach the client's resource usage) and exits without an interpreter teardown (the two
teardowns cost 0.35 s after the last task).
"""

from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import time

from hilbench.analysis.execution import ENVIRONMENT
from hilbench.bench.campaign_analysis.fork_server import PRELOAD
from hilbench.bench.errors import AnalyseError

#: the host's program: its reply channel first, then the fork server (before any other import), then the cluster
#: until its stdin ends. A program of its own, not a function of this module: the host imports nothing of hilbench
#: (CPU taken from the fork server's imports, the critical path).
#: argv: the fork server's preload (JSON list), the request (JSON: workers, dashboard, Dask config)
BOOT = """
import json, os, signal, sys, threading
reply = os.fdopen(os.dup(1), "w")
os.dup2(2, 1)  # anything printed goes to stderr, not into the reply
started, gone, lock = threading.Event(), threading.Event(), threading.Lock()

def say(doc):  # one JSON line to the client (from this thread, the scheduler's loop and the start's deadline)
    with lock:
        reply.write(json.dumps(doc) + "\\n")
        reply.flush()

def fail(why):  # the cluster cannot start: the client reads why; its connection to the scheduler ends with this
    try:
        say({"error": " ".join(why.split())})
    except OSError:
        pass
    os._exit(1)  # the fork server quits when this process goes; a nanny's worker watches its parent

def watch():  # the client's end of stdin: it closed it or died. During the start nobody else listens: exit at once
    sys.stdin.read()
    gone.set()
    if not started.is_set():
        os._exit(1)

threading.Thread(target=watch, daemon=True).start()
from multiprocessing import forkserver, get_context
get_context("forkserver").set_forkserver_preload(json.loads(sys.argv[1]))
forkserver.ensure_running()
request = json.loads(sys.argv[2])
deadline = threading.Timer(request["timeout"], fail, (f"it did not start within {request['timeout']:g} s",))
deadline.daemon = True
deadline.start()
import logging
import dask
import distributed.utils
from distributed import LocalCluster
# the fork server runs with its preload: Dask's first nanny would otherwise import every package its version report
# lists (numpy, pandas, lz4: 0.2-0.3 s of CPU here, on the start's critical path) to preload a server that exists
distributed.utils._forkserver_preload_set = True
from distributed.comm import get_address_host
from distributed.diagnostics.plugin import SchedulerPlugin
from distributed.utils import format_dashboard_link

class Announce(SchedulerPlugin):
    # the scheduler's address as soon as it listens, before the workers start: the client connects while the fork
    # server still imports, and submits once the workers are up (its second word)
    async def start(self, scheduler):
        server = scheduler.services.get("dashboard") if request["dashboard"] else None  # (its HTTP server runs anyway)
        link = format_dashboard_link(get_address_host(scheduler.address), server.port) if server else None
        say({"address": scheduler.address, "dashboard": link})

cluster = None
try:
    dask.config.set(request["config"])
    cluster = LocalCluster(n_workers=request["workers"], threads_per_worker=1, processes=True,
                           dashboard_address=request["dashboard"], silence_logs=logging.CRITICAL,
                           scheduler_kwargs={"plugins": [Announce()]})
except Exception as exc:
    why, seen = [], exc
    while seen is not None and len(why) < 4:  # Dask's "Nanny failed to start." says why in its cause
        why.append(f"{type(seen).__name__}: {seen}")
        seen = seen.__cause__ or seen.__context__
    fail("; because ".join(why))
deadline.cancel()
started.set()
try:
    say({"workers": request["workers"]})
    gone.wait()  # until the client closes the pipe or dies
    code = 0
except BrokenPipeError:  # the client is gone
    code = 0
except BaseException:
    import traceback
    traceback.print_exc()
    code = 1
cluster.close()  # the nannies end their workers, and the fork server reaps them
# then the fork server, killed and reaped: the workers' CPU counts in this process's children's, and so in the
# command's. Killed, not stopped: its interpreter's teardown (numpy, scipy, h5py, distributed) took 0.17 s of
# CPU after the last task, and it holds nothing to flush. This process's own teardown took as long again: it
# flushes its two streams and skips it (os._exit)
pid = getattr(forkserver._forkserver, "_forkserver_pid", None)
if pid:
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
sys.stdout.flush()
sys.stderr.flush()
os._exit(code)
"""
#: the local cluster's Dask settings (the host's scheduler and nannies, and the workers they start).
#: allowed-failures 1: a task whose worker dies is given to a fresh worker once. worker-saturation 1.0: a worker
#: holds only the task it runs (at the default 1.1 a one-thread worker also holds a queued task, and a death then
#: counts against that innocent task too: a 200-run benchmark lost a third row that way). profile off: the worker's
#: statistical profiler samples the task's stack every 10 ms and cost 15-25 % of the CPU of a 0.1 s identification
#: (0.104-0.108 s against 0.077-0.091 s per task, measured). multiprocessing-method forkserver: the workers are forked
#: from the server this process starts first (fork_server.WORKER_MODULES imported once; 3.5 s of CPU per worker when
#: spawned). Housekeeping at a run's pace, not a web dashboard's: the event loops' health tick every 200 ms (20 ms),
#: the system monitor every 2 s (0.5 s), the worker's memory check every 1 s (0.1 s), no work stealing (the chunks
#: are sized by the client): the process of the scheduler and nannies spent 3.3-3.6 s of CPU on a 200-run campaign
#: with Dask's defaults, 2.6 s with these.
CONFIG = {"distributed.scheduler.allowed-failures": 1, "distributed.scheduler.worker-saturation": 1.0,
          "distributed.worker.profile.enabled": False, "distributed.admin.tick.limit": "60s",
          "distributed.admin.tick.interval": "200ms", "distributed.admin.system-monitor.interval": "2s",
          "distributed.worker.memory.monitor-interval": "1s", "distributed.scheduler.work-stealing": False,
          "distributed.worker.multiprocessing-method": "forkserver"}
#: how long the cluster may take to come up, s (the fork server's imports take 1-2 s on an idle core, 10 s at a load
#: of 20)
START_TIMEOUT = 300.0


def local_workers(workers: int | None) -> int:
    """Worker processes of a local cluster: ``workers``, by default one per core."""
    return workers or os.cpu_count() or 1


def dashboard_address(wanted: bool) -> str | None:
    """Where the cluster's dashboard listens: any free port (several analyses may run on one machine) when wanted
    and the bokeh package is there, else None."""
    import importlib.util

    return ":0" if wanted and importlib.util.find_spec("bokeh") is not None else None


class Host:
    """The client's handle on a cluster host process of ``workers`` workers (started at once: its fork server starts
    importing, then the cluster starts)."""

    def __init__(self, workers: int, dashboard: str | None) -> None:
        self.request = {"workers": workers, "dashboard": dashboard}
        # -W: the host's interpreter flags reach the fork server and multiprocessing's resource tracker, which warns
        # on the command's stderr of the semaphores it cleans up when the host was killed (the command says so)
        self.proc = subprocess.Popen([sys.executable, "-W", "ignore::UserWarning:multiprocessing.resource_tracker",
                                      "-c", BOOT, json.dumps([PRELOAD]),
                                      json.dumps({**self.request, "config": CONFIG, "timeout": START_TIMEOUT})],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, env={**os.environ, **ENVIRONMENT},
                                     close_fds=True)
        self._pending = b""
        self.up = False  # the host said its workers are up

    def address(self, timeout: float = START_TIMEOUT) -> tuple[str, str | None]:
        """(scheduler address, dashboard link), once the scheduler listens (its workers may still be starting:
        :meth:`wait_up`)."""
        line = self._line(timeout)
        if line is None:
            self.close()
            raise AnalyseError(f"the local cluster did not start within {timeout:g} s")
        if not line:
            self.close()
            raise AnalyseError(f"the local cluster's process ended before it started (exit code {self.proc.wait()})")
        doc = json.loads(line)
        if "error" in doc:
            self.close()
            raise AnalyseError(f"the local cluster did not start: {doc['error'][:300]}")
        return doc["address"], doc["dashboard"]

    def wait_up(self, timeout: float = START_TIMEOUT) -> None:
        """Until the host says its workers are up; one line if it says why they are not, ends, or is silent for
        ``timeout`` s. The command submits after this: a task that kills its worker while the cluster starts would
        fail the cluster's start (Dask's "Nanny failed to start worker process"), not just its own runs."""
        deadline = time.monotonic() + timeout
        while not self.up:
            line = self._line(max(0.0, deadline - time.monotonic()))
            if line is None:
                raise AnalyseError(f"the local cluster's workers did not start within {timeout:g} s")
            if not line:
                raise AnalyseError(f"the local cluster's process ended before its workers started (exit code "
                                   f"{self.proc.wait()})")
            doc = json.loads(line)
            if "error" in doc:
                raise AnalyseError(f"the local cluster did not start: {str(doc['error'])[:300]}")
            self.up = "workers" in doc

    def failure(self, wait: float = 0.0) -> str | None:
        """Why the cluster failed after its address came (its workers did not start, or its process ended), or
        None while it is well (the host said its workers are up, or says nothing more within ``wait`` s)."""
        deadline = time.monotonic() + wait
        while True:
            line = self._line(max(0.0, deadline - time.monotonic()))
            if line is None:  # nothing (more) said in time
                return None if self.alive() else f"its process ended (exit code {self.proc.wait()})"
            if not line:
                return f"its process ended (exit code {self.proc.wait()})"
            doc = json.loads(line)
            if "error" in doc:
                return str(doc["error"])[:300]
            self.up = self.up or "workers" in doc  # they came up; what follows tells

    def _line(self, timeout: float) -> bytes | None:
        """The host's next reply line; b"" at its end; None if none came within ``timeout`` s."""
        assert self.proc.stdout is not None
        deadline, fd = time.monotonic() + timeout, self.proc.stdout.fileno()
        while b"\n" not in self._pending:
            left = deadline - time.monotonic()
            if not select.select([fd], [], [], max(0.0, left))[0]:
                return None
            got = os.read(fd, 65536)
            if not got:
                return b""
            self._pending += got
        line, _, self._pending = self._pending.partition(b"\n")
        return line

    def alive(self) -> bool:
        return self.proc.poll() is None

    def close(self, timeout: float = 60.0, wait: bool = True) -> None:
        """End the host: it closes the cluster, stops its fork server and exits; killed if it does not in time.
        ``wait=False`` only tells it (a later close waits)."""
        for pipe in (self.proc.stdin, self.proc.stdout):
            if pipe is not None and not pipe.closed:
                try:
                    pipe.close()
                except BrokenPipeError:
                    pass
        if not wait:
            return
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


_early: Host | None = None


def start_early(workers: int, dashboard: str | None) -> None:
    """Start a host now (``hilbench analyse`` calls this before it builds its parser); :func:`take` hands it over."""
    global _early
    if _early is None:
        _early = Host(workers, dashboard)


def discard() -> None:
    """End a host started early that no analysis took (nothing to analyse, or a refusal): killed, it never ran a
    task; its workers exit with it (a nanny's worker watches its parent)."""
    global _early
    host, _early = _early, None
    if host is not None:
        host.proc.kill()
        host.close()


def take(workers: int, dashboard: str | None) -> Host:
    """The host started early if it still runs with these settings, else a new one."""
    global _early
    host, _early = _early, None
    if host is not None and host.alive() and host.request == {"workers": workers, "dashboard": dashboard}:
        return host
    if host is not None:  # started for other settings: it ran no task, killed like discard's
        host.proc.kill()
        host.close()
    return Host(workers, dashboard)
