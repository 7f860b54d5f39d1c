"""The local cluster's fork server: one process that imports what the steps need once, from which every local worker
is forked. Its own module, light to import, so that ``hilbench analyse`` starts the server before it imports the
engine (numpy, pyarrow, the table): the server's imports (about 2 s on one core) are the local cluster's critical
path, and everything the client does meanwhile (its own imports, hashing the run files, starting the scheduler)
runs on the other core."""

from __future__ import annotations

import os

from hilbench.analysis.execution import ENVIRONMENT

#: what the steps import (much of it inside their functions; scipy.signal alone takes a second): imported once per
#: process before the first task, by the local cluster's fork server for all its workers
WORKER_MODULES = ("numpy", "scipy.signal", "scipy.optimize", "scipy.interpolate", "h5py",
                  "hilbench.common.runfile", "hilbench.bench.verdict", "hilbench.bench.analysis_input",
                  "hilbench.analysis.identification.identify", "hilbench.analysis.identification.maxwell_fit",
                  "hilbench.analysis.identification.output_error", "hilbench.analysis.record",
                  "hilbench.bench.campaign_analysis.engine")
#: most local workers (each a process with its own imports; more than the host's cores only slow it down)
MAX_WORKERS = 256


def start_fork_server() -> None:
    """Start multiprocessing's fork server now, preloading distributed and :data:`WORKER_MODULES`, so that its
    imports overlap the client's own start (its imports, the planning, the scheduler); with one BLAS thread per
    worker (the execution policy's environment, analysis.execution). A server already running (an earlier
    analysis in this process) is kept.

    The thread counts are set here, not read from Dask's config (``distributed.nanny.pre-spawn-environ``): its
    defaults load only when distributed is imported, after this, and importing dask alone costs 0.2 s on the
    critical path. A forked worker has the server's environment (a nanny's pre-spawn-environ changes only the client
    process's), so anything else a worker needs in its environment goes into the shell's before ``hilbench analyse``.
    Without the limits each worker ran OpenBLAS on two threads (200 runs of 2 s: 32 s of CPU against 15 s serial;
    tables that differed from the serial ones in the last bits). Not MALLOC_TRIM_THRESHOLD_ (in Dask's defaults):
    set, it also fixes glibc's mmap threshold at 128 KiB, so every array of a run's analysis above that was mapped
    and unmapped again; the workers spent 1.7x the serial loop's CPU on a campaign of 25 000-sample runs (the serial
    loop with it set: 51 s, 19.5 s of it sys; without: 30.5 s, 4.2 s)."""
    import multiprocessing
    from multiprocessing import forkserver

    saved = {k: os.environ.get(k) for k in ENVIRONMENT}
    os.environ.update(ENVIRONMENT)
    try:
        multiprocessing.get_context("forkserver").set_forkserver_preload(["distributed", *WORKER_MODULES])
        forkserver.ensure_running()  # launches the server and returns: it imports while this process goes on
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def warm_up() -> None:
    """Import :data:`WORKER_MODULES` (the serial loop, and a remote worker, before the first task)."""
    import importlib

    for name in WORKER_MODULES:
        importlib.import_module(name)
