"""The execution policy (analysis/execution.py): one BLAS thread inside ``limited()`` and after ``limit_process()``,
in every BLAS library the process loads (numpy's and scipy's own OpenBLAS), the caller's settings back after
``limited()``."""

import json
import os
import subprocess
import sys

import scipy.linalg  # noqa: F401 -- scipy's own OpenBLAS loaded before the tests raise every library to 2 threads
from threadpoolctl import threadpool_limits

from hilbench.analysis import execution


def _threads() -> set[int]:
    return set(execution.blas_threads().values())


def test_limited_sets_every_blas_to_the_policy_and_restores_the_callers():
    with threadpool_limits(limits=2):  # numpy's default on two cores
        assert _threads() == {2}
        with execution.limited():
            names = execution.blas_threads()
            assert len(names) >= 2 and set(names.values()) == {execution.THREADS}, names
        assert _threads() == {2}


def test_limited_is_a_decorator():
    @execution.limited()
    def inner() -> set[int]:
        return _threads()

    with threadpool_limits(limits=2):
        assert inner() == {1}
        assert _threads() == {2}


_LATER = """
import json, numpy
from hilbench.analysis.execution import blas_threads, limit_process
limit_process()
import scipy.linalg  # scipy's own OpenBLAS, loaded after the policy was set
print(json.dumps(blas_threads()))
"""


def test_limit_process_reaches_a_blas_loaded_after_it():
    # a fresh process without the thread variables (make test sets them for its own processes): numpy's OpenBLAS
    # starts with a thread per core; limit_process limits it and, through the environment, scipy's loaded later
    env = {k: v for k, v in os.environ.items() if k not in execution.ENVIRONMENT}
    done = subprocess.run([sys.executable, "-c", _LATER], capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    threads = json.loads(done.stdout)
    assert len(threads) >= 2 and set(threads.values()) == {1}, threads
