"""What the analysis commands (identify, residual, skeleton, afrf) read from a run file, checked once.

- One default torque channel for every analysis: the measured ``torque`` when the file has it, else the
  commanded ``torque_cmd`` (``force``/``force_cmd`` on a linear axis are the same channels). ``--torque-channel``
  chooses another.
- A channel must hold finite numbers within :data:`MAX_ABS_VALUE`; strings, NaN and values near the float64
  range (1e300, whose squares overflow) are refused with one line naming the channel.
- Option values that size an allocation are checked against a stated bound before anything is allocated.
"""

from __future__ import annotations

import math

import numpy as np

from hilbench.bench.errors import BenchError

TORQUE_CHANNELS = ("torque", "torque_cmd")
# Largest magnitude accepted in a channel. The analyses square and sum samples: 1e100 squared is 1e200, far
# from float64's 1.8e308 even summed over 1e9 samples; real torques, forces and positions are many decades below.
MAX_ABS_VALUE = 1e100
# --thresholds: candidate Maxwell-slip thresholds; each one is a regressor column of the record's length, and
# a fitted model must fit the C plant, whose element limit is 1024.
MAX_THRESHOLDS = 1024
# --bins: log-spaced bins per skeleton curve; more bins than this leave most of them empty for any record.
MAX_BINS = 10_000


def whole_number(text: str) -> int:
    """argparse type for a count: ``64``, ``1e6`` (a whole number written in floating point) are accepted."""
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value != int(value):
        raise ValueError(f"{text!r} is not a whole number")
    return int(value)


def torque_channel(channels, requested: str | None, path: str, axis: str = "rotary") -> str:
    """The torque channel to analyse: ``requested`` if given (must exist), else ``torque``, else
    ``torque_cmd``."""
    names = set(channels)
    aliases = {"force": "torque", "force_cmd": "torque_cmd"} if axis == "linear" else {}
    if requested is not None:
        name = aliases.get(requested, requested)
        if name not in names:
            raise BenchError(f"{path}: no channel {requested!r} (has: {', '.join(sorted(names))})")
        return name
    for name in TORQUE_CHANNELS:
        if name in names:
            return name
    raise BenchError(f"{path}: no torque channel (torque or torque_cmd; has: {', '.join(sorted(names))})")


def numeric(values, name: str, path: str) -> np.ndarray:
    """``values`` as a float64 array, or a one-line :class:`BenchError` saying what is wrong with it."""
    raw = np.asarray(values)
    if raw.dtype.kind not in "biuf":
        what = "strings" if raw.dtype.kind in "SUO" else raw.dtype.name
        raise BenchError(f"{path}: channel {name!r} holds {what}, not numbers")
    arr = raw.astype(float)
    bad = ~np.isfinite(arr)
    if bad.any():
        i = int(np.argmax(bad))
        raise BenchError(f"{path}: channel {name!r} has {int(bad.sum())} non-finite value(s), first at sample {i}")
    if arr.size and float(np.max(np.abs(arr))) > MAX_ABS_VALUE:
        i = int(np.argmax(np.abs(arr)))
        raise BenchError(f"{path}: channel {name!r} sample {i} is {arr[i]:.3g}, beyond the analysis bound "
                         f"+-{MAX_ABS_VALUE:g}")
    return arr


def check_cutoff(cutoff: float | None, sample_rate: float, option: str = "--cutoff") -> None:
    """A low-pass cutoff must lie strictly between 0 and the Nyquist frequency."""
    if cutoff is None:
        return
    nyquist = 0.5 * sample_rate
    if not (math.isfinite(cutoff) and 0.0 < cutoff < nyquist):
        raise BenchError(f"{option} {cutoff:g} Hz: must lie in (0, {nyquist:g}) Hz, the run's Nyquist frequency")


def check_count(value: int, option: str, minimum: int, maximum: int, why: str) -> None:
    """An option that sizes an allocation, checked before anything is allocated."""
    if not (minimum <= value <= maximum):
        raise BenchError(f"{option} {value}: must lie in [{minimum}, {maximum}] ({why})")
