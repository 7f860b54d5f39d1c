"""Control charts and change points on a standardised series z (unit variance when in control).

- EWMA: w_i = lam*z_i + (1 - lam)*w_{i-1}, w_{-1} = 0; control limits +-L*sqrt(lam/(2 - lam)*(1 - (1 - lam)^(2(i+1))))
  (Montgomery, Introduction to Statistical Quality Control, 6th ed., sec. 9.2).
- CUSUM, tabular: C+_i = max(0, z_i - k + C+_{i-1}), C-_i = max(0, -z_i - k + C-_{i-1}); a signal when either
  exceeds h (sec. 9.1). k = 0.5 is tuned to a shift of one standard deviation.
- Change points: PELT (Killick et al. 2012, the ``ruptures`` package) on the mean of z (cost ``l2``) with a
  penalty per change point.
"""

from __future__ import annotations

import math

import numpy as np

from hilbench.analysis.errors import AnalysisError


def ewma(z: np.ndarray, lam: float, limit: float) -> tuple[np.ndarray, np.ndarray]:
    """(EWMA statistic, control limit) for every sample of z."""
    if not (0 < lam <= 1 and limit > 0):
        raise AnalysisError(f"EWMA needs 0 < lambda <= 1 and a limit > 0, got {lam}, {limit}")
    z = np.asarray(z, dtype=float)
    w = np.empty(z.size)
    prev = 0.0
    for i, v in enumerate(z):
        prev = lam * v + (1 - lam) * prev
        w[i] = prev
    i = np.arange(1, z.size + 1)
    return w, limit * np.sqrt(lam / (2 - lam) * (1 - (1 - lam) ** (2 * i)))


def cusum(z: np.ndarray, k: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(C+, C-) of the tabular CUSUM; signals where either exceeds h (:func:`signals`)."""
    if not (k >= 0 and h > 0):
        raise AnalysisError(f"CUSUM needs k >= 0 and h > 0, got {k}, {h}")
    z = np.asarray(z, dtype=float)
    hi, lo = np.empty(z.size), np.empty(z.size)
    a = b = 0.0
    for i, v in enumerate(z):
        a = max(0.0, v - k + a)
        b = max(0.0, -v - k + b)
        hi[i], lo[i] = a, b
    return hi, lo


def signals(outside: np.ndarray) -> list[int]:
    """Indices where a run of True starts (one alarm per excursion beyond the limit)."""
    o = np.asarray(outside, dtype=bool)
    return [int(i) for i in np.flatnonzero(o & ~np.concatenate([[False], o[:-1]]))]


def default_penalty(n: int) -> float:
    """PELT penalty for a mean change of a unit-variance series: 3 ln n, above the BIC's 2 ln n so that a
    stationary campaign of a few hundred runs shows no change point (tests/analysis/drift)."""
    return 3.0 * math.log(max(n, 2))


def change_points(z: np.ndarray, penalty: float | None = None, min_size: int = 5) -> list[int]:
    """Indices where a new segment of the mean of z starts (PELT, cost l2)."""
    import ruptures

    z = np.asarray(z, dtype=float)
    if z.size < 2 * min_size:
        return []
    pen = default_penalty(z.size) if penalty is None else penalty
    ends = ruptures.Pelt(model="l2", min_size=min_size, jump=1).fit(z.reshape(-1, 1)).predict(pen=pen)
    return [int(e) for e in ends[:-1]]
