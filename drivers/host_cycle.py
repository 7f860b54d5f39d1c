"""Host-clocked cycles: the timing loop and its honest bookkeeping.

A host-clocked drive buffers nothing; the host sends one trigger (SYNC, or a cyclic message) per period
``T`` at the scheduled times ``t0 + k*T``. The loop never skips a setpoint: when it falls behind it sends
the overdue cycles back to back, so every sample exists, but the drive held the previous torque for longer
than ``T``. :func:`timing_summary` turns the host timestamps into the figures the run file keeps.

Definitions (``d_k = host_time[k+1] - host_time[k]``, the cycle time the drive saw, give or take the bus):

- cycle-time p50, p99, max: percentiles of ``d_k``;
- **missed** cycles: scheduled trigger slots that stayed empty, ``sum(max(0, round(d_k/T) - 1))``;
- **late** cycles: triggers sent more than ``LATE_FRACTION*T`` after their scheduled time;
- **jitter**: p99 of ``|d_k - T|``. A run is unfit for identification when that exceeds ``JITTER_LIMIT*T``
  or when more than ``MISSED_LIMIT`` of the cycles were missed: the plant then integrated a held torque
  over a span the analysis (which takes ``t = k*T``) does not know about.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

LATE_FRACTION = 0.25
JITTER_LIMIT = 0.10
MISSED_LIMIT = 1e-3
SLEEP_MARGIN = 0.0  # s; sleeping only (no spinning: a spinning thread starves the receiver of the GIL)


@dataclass(frozen=True)
class TimingSummary:
    """Timing of one host-clocked stream (times in s)."""

    cycles: int
    rate: float
    p50: float
    p99: float
    max: float
    missed: int
    late: int
    jitter_p99: float

    @property
    def fit(self) -> bool:
        period = 1.0 / self.rate
        return self.jitter_p99 <= JITTER_LIMIT * period and self.missed <= MISSED_LIMIT * max(self.cycles, 1)

    def line(self) -> str:
        """One line with the figures and the verdict."""
        period = 1.0 / self.rate
        figures = (f"host-clocked timing: {self.cycles} cycles at {self.rate:g} Hz; cycle p50 {self.p50 * 1e3:.3f} "
                   f"ms, p99 {self.p99 * 1e3:.3f} ms, max {self.max * 1e3:.3f} ms; {self.missed} missed, "
                   f"{self.late} late; jitter p99 {self.jitter_p99 * 1e6:.0f} us ({self.jitter_p99 / period:.1%} of T)")
        if self.fit:
            return figures + "; fit for identification"
        return figures + (f"; UNFIT for identification (limits {JITTER_LIMIT:.0%} of T, "
                          f"{MISSED_LIMIT:.1%} missed)")

    def as_dict(self) -> dict:
        return {"cycles": self.cycles, "rate_hz": self.rate, "cycle_time_p50_s": self.p50,
                "cycle_time_p99_s": self.p99, "cycle_time_max_s": self.max, "missed": self.missed,
                "late": self.late, "jitter_p99_s": self.jitter_p99, "fit_for_identification": self.fit}


def timing_summary(host_time: np.ndarray, scheduled: np.ndarray, rate: float) -> TimingSummary:
    """Figures of a stream from the host times its triggers went out and the times they were due (s)."""
    host_time = np.asarray(host_time, dtype=np.float64)
    period = 1.0 / rate
    d = np.diff(host_time)
    if d.size == 0:
        return TimingSummary(int(host_time.size), rate, period, period, period, 0, 0, 0.0)
    missed = int(np.maximum(np.rint(d / period) - 1, 0).sum())
    late = int(np.count_nonzero(host_time - np.asarray(scheduled) > LATE_FRACTION * period))
    return TimingSummary(int(host_time.size), rate, float(np.percentile(d, 50)), float(np.percentile(d, 99)),
                         float(d.max()), missed, late, float(np.percentile(np.abs(d - period), 99)))


def run_cycles(n: int, rate: float, send: Callable[[int], None], host_time: np.ndarray, scheduled: np.ndarray,
               stop: Callable[[], bool], start_delay: float = 0.005) -> int:
    """Call ``send(k)`` for k = 0..n-1 at ``t0 + k/rate`` (monotonic clock); record when each went out.

    Stops early when ``stop()`` is true (checked before each cycle); returns the number of cycles sent.
    """
    period = 1.0 / rate
    t0 = time.monotonic() + start_delay
    clock, sleep = time.monotonic, time.sleep
    for k in range(n):
        if stop():
            return k
        due = t0 + k * period
        wait = due - clock() - SLEEP_MARGIN
        if wait > 0:
            sleep(wait)
        send(k)
        host_time[k] = clock()
        scheduled[k] = due
    return n
