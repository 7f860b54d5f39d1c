"""What the local cluster's workers import before their first task, and the cap on their number. Light to import
(``hilbench analyse`` reads it before its parser is built).

The local cluster's workers are forked from a multiprocessing fork server that imported :data:`WORKER_MODULES`
once (the cluster host starts it: cluster_host), so no worker imports scipy & co. itself (3.5 s of CPU each when
spawned). The server runs under the execution policy's environment (analysis.execution.ENVIRONMENT: one BLAS
thread), set on the host process when it starts, not read from Dask's config (``distributed.nanny.pre-spawn-environ``
loads only when distributed is imported, and a forked worker has the server's environment, not what a nanny sets);
anything else a worker needs in its environment goes into the shell's before ``hilbench analyse``. Without the
limits each worker ran OpenBLAS on two threads (200 runs of 2 s: 32 s of CPU against 15 s serial; tables that
differed from the serial ones in the last bits). Not MALLOC_TRIM_THRESHOLD_ (in Dask's defaults): set, it also fixes
glibc's mmap threshold at 128 KiB, so every array of a run's analysis above that was mapped and unmapped again; the
workers spent 1.7x the serial loop's CPU on a campaign of 25 000-sample runs (the serial loop with it set: 51 s,
19.5 s of it sys; without: 30.5 s, 4.2 s)."""

from __future__ import annotations

#: what the default step (identify) imports, much of it inside its functions: imported once per process before the
#: first task, by the local cluster's fork server for all its workers. About 1 s of CPU on an idle core: distributed
#: 0.22 s, scipy.signal 0.47 s (0.21 s of it the scipy.stats it imports; the step needs its filters), the engine and
#: the analyses' modules 0.18 s. Only what the step imports (tests/bench/campaign_analysis/test_fork_server.py): the
#: other steps import the rest in the worker
WORKER_MODULES = ("numpy", "scipy.signal", "scipy.optimize", "scipy.interpolate", "h5py",
                  "hilbench.common.runfile", "hilbench.analysis.identification.identify",
                  "hilbench.analysis.identification.maxwell_fit", "hilbench.analysis.identification.output_error",
                  "hilbench.analysis.record", "hilbench.bench.campaign_analysis.engine")
#: most local workers (each a process with its own imports; more than the host's cores only slow it down)
MAX_WORKERS = 256


#: the module the local cluster's fork server imports before it forks a worker (its import is :func:`warm_up` with
#: distributed)
PRELOAD = "hilbench.bench.campaign_analysis.preload"


def warm_up(extra: tuple[str, ...] = ()) -> None:
    """Import ``extra`` and :data:`WORKER_MODULES` (the serial loop, a remote worker, the fork server before the
    first task) with the cyclic garbage collector paused, then freeze what exists out of later collections.

    Paused: the collector walked the imports' new objects again and again, 7 % of their CPU (0.84-0.85 s against
    0.90-0.92 s, distributed and the step's modules, alternating). Frozen (``gc.freeze``): a collection no longer walks
    the modules' objects, and in a worker forked from the fork server it no longer writes to, and so copies, the
    server's memory pages."""
    import gc
    import importlib

    enabled = gc.isenabled()
    gc.disable()
    try:
        for name in (*extra, *WORKER_MODULES):
            importlib.import_module(name)
    finally:
        gc.freeze()
        if enabled:
            gc.enable()
