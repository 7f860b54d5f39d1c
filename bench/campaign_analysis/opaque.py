"""A Dask task's function and arguments as one opaque payload.

Dask's scheduler unpickles every task it is given, to build its graph. Unpickling ours (the engine's
``execute_chunk_timed`` and its :class:`~hilbench.bench.campaign_analysis.steps.StepSettings`) imported the engine,
pyarrow and every registered analysis into the scheduler's process: 0.14 s of its CPU, with its event loop blocked
while the local cluster's first workers waited for their first tasks (0.4 s from a worker's fork to its first task,
200 runs of 5 s at 5 kHz on 2 cores). The scheduler now unpickles a reference to :func:`call` (this module imports
nothing) and bytes; the worker unpickles the rest. A remote scheduler needs no more of hilbench than this module.
"""

from __future__ import annotations

import pickle
from collections.abc import Callable
from typing import Any


def pack(function: Callable[..., Any], *args: Any) -> bytes:
    """``function`` and ``args`` as bytes for :func:`call` (cloudpickle, as Dask pickles: a step function may be a
    closure)."""
    import cloudpickle

    return cloudpickle.dumps((function, args), protocol=pickle.HIGHEST_PROTOCOL)


def call(payload: bytes) -> Any:
    """Unpickle :func:`pack`'s payload and call it (in the worker)."""
    function, args = pickle.loads(payload)
    return function(*args)
