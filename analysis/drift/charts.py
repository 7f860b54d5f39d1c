"""Control charts and change points on a standardised series z (unit variance when in control).

- EWMA: w_i = lam*z_i + (1 - lam)*w_{i-1}, w_{-1} = 0; control limits +-L*sqrt(lam/(2 - lam)*(1 - (1 - lam)^(2(i+1))))
  (Montgomery, Introduction to Statistical Quality Control, 6th ed., sec. 9.2).
- CUSUM, tabular: C+_i = max(0, z_i - k + C+_{i-1}), C-_i = max(0, -z_i - k + C-_{i-1}); a signal when either
  exceeds h (sec. 9.1). k = 0.5 is tuned to a shift of one standard deviation.
- Change points: binary segmentation (the ``ruptures`` package, ``Binseg``, cost ``l2``) on the mean of z, splitting
  while the best split's gain exceeds a penalty. Its first split is the classical CUSUM test of one mean change, so
  the penalty that gives a stated false-alarm rate can be calibrated (analysis.drift.calibration.split_gain).

The single-series functions here delegate to the vectorised cores of :mod:`hilbench.analysis.drift.calibration`,
so a campaign's charts and the simulated campaigns that calibrate them are computed by the same code.
"""

from __future__ import annotations

import numpy as np

from hilbench.analysis.drift.calibration import cusum_paths, ewma_paths
from hilbench.analysis.errors import AnalysisError


def ewma(z: np.ndarray, lam: float, limit: float) -> tuple[np.ndarray, np.ndarray]:
    """(EWMA statistic, control limit) for every sample of z."""
    if not (0 < lam <= 1 and limit > 0):
        raise AnalysisError(f"EWMA needs 0 < lambda <= 1 and a limit > 0, got {lam}, {limit}")
    w, sd = ewma_paths(np.asarray(z, dtype=float)[None, :], lam)
    return w[0], limit * sd


def cusum(z: np.ndarray, k: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(C+, C-) of the tabular CUSUM; signals where either exceeds h (:func:`signals`)."""
    if not (k >= 0 and h > 0):
        raise AnalysisError(f"CUSUM needs k >= 0 and h > 0, got {k}, {h}")
    hi, lo = cusum_paths(np.asarray(z, dtype=float)[None, :], k)
    return hi[0], lo[0]


def signals(outside: np.ndarray) -> list[int]:
    """Indices where a run of True starts (one alarm per excursion beyond the limit)."""
    o = np.asarray(outside, dtype=bool)
    return [int(i) for i in np.flatnonzero(o & ~np.concatenate([[False], o[:-1]]))]


def change_points(z: np.ndarray, penalty: float, min_size: int = 5) -> list[int]:
    """Indices where a new segment of the mean of z starts: binary segmentation, cost l2, splitting while the gain
    exceeds ``penalty``."""
    import ruptures

    z = np.asarray(z, dtype=float)
    if z.size < 2 * min_size or not np.isfinite(penalty):
        return []
    if penalty <= 0:
        raise AnalysisError(f"the change-point penalty must be > 0, got {penalty:g}")
    ends = ruptures.Binseg(model="l2", min_size=min_size, jump=1).fit(z.reshape(-1, 1)).predict(pen=penalty)
    return sorted(int(e) for e in ends[:-1])
