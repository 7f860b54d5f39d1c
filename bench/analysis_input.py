"""The analysis commands' shared options, a thin adapter over the analysis registry (hilbench.analysis.protocol).

- Every analysis command reads its runs through its registry entry (:func:`read_runs`, hilbench.analysis.protocol:
  the one loader's channel choice, torque timing, host-clock resampling, numeric and completeness checks, and the
  analysis's choice of whole, streamed or decimated reading within ``--memory``), as the GUI and campaigns do.
- Option values that size an allocation are checked against a stated bound before anything is allocated.
"""

from __future__ import annotations

import argparse
import math
import re
import sys

from hilbench.bench.errors import BenchError

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


def add_record_options(parser: argparse.ArgumentParser) -> None:
    """The options every analysis command shares for reading its runs (hilbench.analysis.record)."""
    parser.add_argument("--allow-incomplete", action="store_true",
                        help="analyse a run that is aborted, crashed, shorter than its plan or marked unfit by its "
                        "device (refused by default); every report then says the record is incomplete")


def read_options(args: argparse.Namespace, budget: int | None, progress=None):
    """The command's reading options (``--torque-channel``, ``--torque-timing``, ``--allow-incomplete``) and its
    memory budget as :class:`hilbench.analysis.protocol.ReadOptions`."""
    from hilbench.analysis.protocol import ReadOptions

    timing = getattr(args, "torque_timing", None) or getattr(args, "timing", None) or "auto"
    return ReadOptions(memory=budget, torque_channel=getattr(args, "torque_channel", None), timing=timing,
                       allow_incomplete=bool(getattr(args, "allow_incomplete", False)), progress=progress)


def add_hold_out_option(parser: argparse.ArgumentParser) -> None:
    """``--hold-out FRACTION``: fit the run's head and score its last FRACTION, as a campaign step does."""
    parser.add_argument("--hold-out", type=float, default=None, metavar="FRACTION",
                        help="fit the first 1 - FRACTION of the run and score the model on its last FRACTION (e.g. "
                        "0.3), from the state the head left, as hilbench analyse's steps do; instead of --validate")


def read_runs(name: str, args: argparse.Namespace, paths: list, validation: list, budget: int | None,
              progress=None, warn: bool = True):
    """(entry, training inputs, validation inputs or None) of registry analysis ``name``
    (:func:`hilbench.analysis.protocol.read_runs`), read within ``budget`` bytes; an incomplete record let
    through is said on standard error (unless ``warn`` is False: the command says it itself)."""
    from hilbench.analysis.protocol import entry
    from hilbench.analysis.protocol import read_runs as read_both

    analysis = entry(name)
    hold_out = getattr(args, "hold_out", None)
    validation = [v for v in validation if v]
    if hold_out is not None:
        if validation:
            raise BenchError("--hold-out scores the run's own tail; it does not go with --validate")
        if not (math.isfinite(hold_out) and 0 < hold_out < 1):
            raise BenchError(f"--hold-out {hold_out:g}: the fraction of the run held out must lie in (0, 1)")
    inputs, val = read_both(analysis, paths, validation, read_options(args, budget, progress))
    if hold_out is not None:
        from hilbench.analysis.protocol import held_out

        inputs, val = held_out(inputs, hold_out)
    for rec in inputs.records + (val.records if val is not None else []):
        line = rec.incomplete_line()
        if line and warn:
            print(f"warning: {line}", file=sys.stderr)
    return analysis, inputs, val


#: the memory budget's bounds, bytes: below the floor no analysis of a real record fits; the cap keeps a shared
#: machine (a Dask worker, a lab PC running the GUI) usable whatever it has free
MEMORY_FLOOR = 256 << 20
MEMORY_CAP = 16 << 30
_UNITS = {"": 1, "b": 1, "k": 1 << 10, "kb": 1 << 10, "kib": 1 << 10, "m": 1 << 20, "mb": 1 << 20, "mib": 1 << 20,
          "g": 1 << 30, "gb": 1 << 30, "gib": 1 << 30}


def add_memory_option(parser: argparse.ArgumentParser) -> None:
    """``--memory``: the peak memory an analysis may use (docs/long-runs.md)."""
    parser.add_argument("--memory", default="auto", metavar="SIZE",
                        help="memory budget of the analysis, e.g. 2G or 512M (default auto: half the memory "
                        "available now, at least 256 MiB, at most 16 GiB); a record whose whole arrays would not "
                        "fit is read chunk by chunk, and an analysis that cannot fit says so before reading")


def available_memory() -> int:
    """Bytes the kernel says are available now (``MemAvailable``), or 4 GiB where it does not say."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 4 << 30


def memory_budget(text: str) -> int:
    """The budget in bytes from ``--memory`` (``auto`` or a size with an optional unit)."""
    if text.strip().lower() == "auto":
        return int(min(max(available_memory() // 2, MEMORY_FLOOR), MEMORY_CAP))
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?)\s*([a-zA-Z]*)\s*", text)
    if not m or m.group(2).lower() not in _UNITS:
        raise BenchError(f"--memory {text!r}: give a size such as 2G, 512M or 1.5GiB, or auto")
    value = int(float(m.group(1)) * _UNITS[m.group(2).lower()])
    if value < MEMORY_FLOOR:
        raise BenchError(f"--memory {text}: below the floor of {MEMORY_FLOOR >> 20} MiB that an analysis needs")
    return value


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
