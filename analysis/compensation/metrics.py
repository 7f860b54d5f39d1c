"""Tracking metrics of a position-controlled run against its reference.

With e[k] = q_ref[k] - q[k] (rad) and the motor current i[k] (A):

- ``rms_error`` = sqrt(mean(e^2)), ``max_error`` = max|e| over the run;
- reversal glitch of reversal r (reference sample k_r where the reference velocity changes sign) =
  max |e[k]| for k_r <= k < k_r + round(window*fs): the presliding lag after a reversal;
  ``glitch_mean``/``glitch_median``/``glitch_max`` over all reversals;
- settling time of move m (point-to-point) = the time from the end of the move until |e| stays within
  ``tolerance`` for the rest of the rest period (0 if it never leaves; the rest length plus one sample if it
  never settles: it is then reported as not settled);
- ``effort_rms`` = sqrt(mean(i^2)) (A).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hilbench.analysis.compensation.references import Reference
from hilbench.analysis.errors import AnalysisError


@dataclass
class Metrics:
    """Figures of one run; per-reversal and per-move arrays are kept for the report."""

    rms_error: float        # rad
    max_error: float        # rad
    effort_rms: float       # A
    glitch: np.ndarray      # rad, one per reversal
    reversal_index: np.ndarray  # sample index of each reversal
    settling: np.ndarray    # s, one per move (NaN: not settled within its rest)
    window_s: float
    tolerance: float        # rad
    extra: dict = field(default_factory=dict)

    @property
    def glitch_mean(self) -> float:
        return float(np.mean(self.glitch)) if self.glitch.size else math.nan

    @property
    def glitch_median(self) -> float:
        return float(np.median(self.glitch)) if self.glitch.size else math.nan

    @property
    def glitch_max(self) -> float:
        return float(np.max(self.glitch)) if self.glitch.size else math.nan

    @property
    def settling_max(self) -> float:
        return float(np.max(self.settling)) if self.settling.size else math.nan

    def summary(self) -> dict:
        """JSON-able figures with units in the keys."""
        return {"rms_error_rad": self.rms_error, "max_error_rad": self.max_error, "effort_rms_a": self.effort_rms,
                "reversals": int(self.glitch.size), "glitch_mean_rad": self.glitch_mean,
                "glitch_median_rad": self.glitch_median, "glitch_max_rad": self.glitch_max,
                "glitch_rad": self.glitch.tolist(), "reversal_sample": self.reversal_index.tolist(),
                "moves": int(self.settling.size),
                "settling_s": [None if not math.isfinite(s) else float(s) for s in self.settling],
                "settling_max_s": self.settling_max, "glitch_window_s": self.window_s,
                "settling_tolerance_rad": self.tolerance, **self.extra}


def reversal_glitch(error: np.ndarray, reversals: np.ndarray, fs: float, window: float) -> np.ndarray:
    """max|error| over [k_r, k_r + round(window*fs)) for each reversal index k_r (rad), shape (r,)."""
    n_win = max(1, int(round(window * fs)))
    e = np.abs(np.asarray(error, float))
    return np.array([float(np.max(e[k:k + n_win])) for k in np.asarray(reversals, int) if k < e.size])


def settling_times(error: np.ndarray, moves: np.ndarray, fs: float, tolerance: float) -> np.ndarray:
    """Seconds from the end of each move until |error| stays <= ``tolerance`` up to the next move (or the end);
    NaN when it is still outside at the end of the rest."""
    e = np.abs(np.asarray(error, float))
    moves = np.asarray(moves, int).reshape(-1, 2)
    out = []
    for m, (_, stop) in enumerate(moves):
        end = moves[m + 1, 0] if m + 1 < len(moves) else e.size
        seg = e[stop:end]
        outside = np.flatnonzero(seg > tolerance)
        if seg.size == 0 or (outside.size and outside[-1] == seg.size - 1):
            out.append(math.nan)
        else:
            out.append(0.0 if outside.size == 0 else (outside[-1] + 1) / fs)
    return np.array(out)


def tracking_metrics(ref: Reference, position: np.ndarray, current: np.ndarray, *, window: float = 0.05,
                     tolerance: float = 1e-4) -> Metrics:
    """Metrics of a run that measured ``position`` (rad) and ``current`` (A), both shape (n,) aligned with
    ``ref``; ``window`` (s) after each reversal, settling ``tolerance`` (rad)."""
    q = np.asarray(position, float)
    i = np.asarray(current, float)
    if q.shape != (ref.n,) or i.shape != (ref.n,):
        raise AnalysisError(f"position and current must have the reference's {ref.n} samples, got {q.shape} and "
                            f"{i.shape}")
    if not (window > 0 and tolerance > 0):
        raise AnalysisError(f"window ({window} s) and tolerance ({tolerance} rad) must be > 0")
    e = ref.position - q
    rev = ref.reversals()
    return Metrics(float(np.sqrt(np.mean(e * e))), float(np.max(np.abs(e))), float(np.sqrt(np.mean(i * i))),
                   reversal_glitch(e, rev, ref.fs, window), rev, settling_times(e, ref.moves, ref.fs, tolerance),
                   float(window), float(tolerance))
