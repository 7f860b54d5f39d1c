"""Execution policy of numeric work: the threads BLAS and OpenMP may use. One owner; the CLI, the GUI's analysis
worker and the campaign workers (serial loop, Dask workers, their fork server) all take it from here.

The policy is :data:`THREADS` = 1 per process. The analyses' matrices are small (a regression has some 70 columns;
the plant and the filters are single-threaded C), so a second BLAS thread gains nothing, and on a busy machine it
costs: with the other core busy, ``fit_lip`` on 100 000 samples took 1.2 s (a spinning shell loop beside it) to
9.5 s (a long-run analysis beside it) with numpy's default two OpenBLAS threads, 0.51 s with one; a campaign's
workers each spun a second core (200 runs: 32 s of CPU against 15 s). Parallel work is spread over processes
instead (Dask workers of one thread each).

numpy and scipy each load their own OpenBLAS (scipy's when ``scipy.linalg`` is first imported), and OpenBLAS reads
its thread count from the environment once, when it loads. Hence two tools:

- :func:`limit_process` for a process of our own, at its start and in its main thread (the ``hilbench`` command,
  ``bench.gui.app.run_app``): the environment for every library loaded later and for the processes it starts,
  threadpoolctl for those already loaded, for the life of the process;
- :func:`limited`, a context manager and decorator for numeric work inside any process (a campaign chunk, the
  GUI's analysis thread, a library caller): it loads both BLAS libraries, limits them, and restores the caller's
  settings on exit.

OpenBLAS's thread pool is shared by the whole process, so threadpoolctl lets one Python thread at a time change it
(the first to do so; the others' calls do nothing until it lets go). In a process started under
:func:`limit_process` the limit already holds in every thread; :func:`limited` is what holds elsewhere.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

#: BLAS and OpenMP threads per process
THREADS = 1
#: the environment that gives a starting process (and each library it loads) the policy
ENVIRONMENT = {name: str(THREADS) for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}


def limit_process() -> None:
    """Apply the policy to this whole process, for its lifetime, and to the processes it starts."""
    from threadpoolctl import threadpool_limits

    os.environ.update(ENVIRONMENT)  # read by each BLAS when it loads: scipy's comes later, and by child processes
    threadpool_limits(limits=THREADS)  # those already loaded (numpy's); never restored


@contextmanager
def limited() -> Iterator[None]:
    """Run the enclosed numeric work under the policy; as a decorator: ``@limited()``."""
    import numpy  # noqa: F401 -- numpy's OpenBLAS
    import scipy.linalg  # noqa: F401 -- scipy's own OpenBLAS, loaded here so that the limit reaches it
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=THREADS):
        yield


def blas_threads() -> dict[str, int]:
    """Threads of every loaded BLAS and OpenMP library, by file name (what the policy's tests check)."""
    from threadpoolctl import threadpool_info

    return {os.path.basename(i["filepath"]): int(i["num_threads"]) for i in threadpool_info()}
