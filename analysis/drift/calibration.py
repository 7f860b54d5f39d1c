"""Control limits calibrated for the campaign at hand: the baseline's own size and covariates, the number of runs
monitored, and a stated false-alarm rate per campaign.

Classical chart constants (an EWMA at +-L sigma, a CUSUM at h) assume sigma and the in-control mean are known. A
campaign's baseline estimates both from a handful of runs, so every monitored score shares the baseline's error,
and a covariate slope fitted over a narrow range is extrapolated to the runs after it: fixed constants then alarm
on a stationary campaign far more often than their tables say, and more the shorter the baseline.

The scores the charts read are pivotal under the in-control model y = X c + e, e ~ N(0, sigma^2 I): the
standardised residuals of :func:`standardise` do not depend on c or sigma. Their joint law depends only on the
design X (the covariate values of every run) and on which runs form the baseline. So the limits are the quantiles
of each statistic's maximum over ``draws`` simulated in-control campaigns with *this* design (a parametric
bootstrap; Montgomery, Introduction to Statistical Quality Control, 6th ed., sec. 9.2 and 10.3 on the effect of
estimated parameters). Each chart gets an equal share of the false-alarm budget, so by the union bound the chance
that a stationary campaign raises any alarm is at most the stated rate.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from hilbench.analysis.errors import AnalysisError


def standardise(y: np.ndarray, design: np.ndarray, base: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scores of series ``y`` (shape (B, n): B series of n runs) against a least-squares fit of ``design`` (n, p)
    on the baseline runs ``base`` (bool, n).

    Returns (z, fitted, s): s = sqrt(sum of squared baseline residuals / (n_b - p)) per series; for a baseline
    run z = r/(s*sqrt(1 - h)) (the internally studentised residual), for a run after it z = r/(s*sqrt(1 + h)) (the
    residual over its prediction standard error), h = x_i^T (X_b^T X_b)^-1 x_i the run's leverage. A run whose
    covariates lie outside the baseline's range has a large h, so its score shrinks instead of extrapolating the
    fitted slope into an alarm."""
    y = np.atleast_2d(np.asarray(y, float))
    xb = design[base]
    dof = int(base.sum()) - design.shape[1]
    if dof < 2:
        raise AnalysisError(f"a baseline of {int(base.sum())} runs is too short for {design.shape[1]} coefficients "
                            "and a spread (need 2 more runs than coefficients)")
    inv = np.linalg.pinv(xb.T @ xb)
    lev = np.einsum("ij,jk,ik->i", design, inv, design)
    coef = y[:, base] @ xb @ inv  # (B, p): (X_b^T X_b)^-1 X_b^T y_b per series
    fitted = coef @ design.T
    r = y - fitted
    s = np.sqrt(np.sum(r[:, base] ** 2, axis=1) / dof)
    scale = np.where(base, np.sqrt(np.clip(1.0 - lev, 1e-12, None)), np.sqrt(1.0 + lev))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = r / (s[:, None] * scale)
    return z, fitted, s


def clipped(z: np.ndarray, base: np.ndarray, clip: float) -> np.ndarray:
    """The scores the charts read: z clipped to +-``clip``, less the mean of the baseline's clipped scores.

    Clipping keeps one wild run from reading as a drift, but it takes more from the long side of a skewed estimate
    (the viscous term of short runs has skewness 1.7) than from the short one, so the clipped scores of an
    unchanged motor have a mean below zero that a long EWMA or CUSUM accumulates into alarms. The baseline's
    clipped scores carry the same offset; subtracting it leaves a clipped series centred on the in-control level."""
    zc = np.clip(z, -clip, clip)
    return zc - np.mean(zc[:, base], axis=1, keepdims=True)


def ewma_paths(z: np.ndarray, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """(EWMA of each row of z, the EWMA's standard deviation for unit-variance input), shapes (B, m) and (m,):
    w_i = lam*z_i + (1 - lam)*w_{i-1}, w_{-1} = 0; sd_i = sqrt(lam/(2 - lam)*(1 - (1 - lam)^(2(i+1))))."""
    z = np.atleast_2d(z)
    w = np.empty_like(z)
    prev = np.zeros(z.shape[0])
    for i in range(z.shape[1]):
        prev = lam * z[:, i] + (1.0 - lam) * prev
        w[:, i] = prev
    i = np.arange(1, z.shape[1] + 1)
    return w, np.sqrt(lam / (2.0 - lam) * (1.0 - (1.0 - lam) ** (2 * i)))


def cusum_paths(z: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray]:
    """Tabular CUSUM (C+, C-) of each row of z:
    C+_i = max(0, z_i - k + C+_{i-1}), C-_i = max(0, -z_i - k + C-_{i-1})."""
    z = np.atleast_2d(z)
    hi, lo = np.empty_like(z), np.empty_like(z)
    a = np.zeros(z.shape[0])
    b = np.zeros(z.shape[0])
    for i in range(z.shape[1]):
        a = np.maximum(0.0, z[:, i] - k + a)
        b = np.maximum(0.0, -z[:, i] - k + b)
        hi[:, i], lo[:, i] = a, b
    return hi, lo


def split_gain(z: np.ndarray, min_size: int) -> np.ndarray:
    """The largest l2 gain of one split of each row of z (shape (B, n)) into two segments of at least ``min_size``:
    max_k n/(k(n-k)) * (S_k - k/n S_n)^2, S_k the partial sums. It is the gain binary segmentation with the l2
    cost (``ruptures.Binseg``) compares with its penalty before its first split; -inf when no split fits."""
    z = np.atleast_2d(z)
    n = z.shape[1]
    k = np.arange(min_size, n - min_size + 1)
    if k.size == 0:
        return np.full(z.shape[0], -np.inf)
    s = np.cumsum(z, axis=1)
    d = s[:, k - 1] - (k / n) * s[:, -1:]
    return np.max(d**2 * (n / (k * (n - k))), axis=1)


@dataclass(frozen=True)
class Limits:
    """The calibrated limits of one series: EWMA limit in sigma of the EWMA (L), CUSUM decision interval (h), the
    change-point penalty of binary segmentation (l2 gain) and the outlier threshold on |z|; each set so that its
    statistic exceeds it on a stationary campaign of this design with probability ``alpha`` (the outlier one
    with ``alpha_outlier``)."""

    ewma: float
    cusum: float
    penalty: float
    outlier: float
    alpha: float
    alpha_outlier: float
    draws: int


#: limits already calibrated in this process, by design, baseline and constants (campaigns of one length without
#: a covariate share one design; a drift report over many series calibrates each design once)
_MEMO: dict[tuple, Limits] = {}
_MEMO_SIZE = 256


#: the shortest baseline whose own residuals shape the simulated noise (shorter ones: normal noise)
MIN_BOOTSTRAP = 10


def calibrate(design: np.ndarray, base: np.ndarray, *, alpha: float, alpha_outlier: float, lam: float, k: float,
              clip: float, min_size: int, draws: int = 4000, seed: int = 0,
              shape: np.ndarray | None = None) -> Limits:
    """:class:`Limits` for the charts of a campaign with ``design`` and baseline ``base`` (see the module text).

    ``shape``: the baseline's scores (:func:`standardise`), whose law the simulated noise follows (a smoothed
    bootstrap, :func:`noise`) when the baseline has at least :data:`MIN_BOOTSTRAP` runs; else, or with None, the
    noise is normal. The estimates of short runs are skewed and heavy-tailed (the viscous term of 2 s runs:
    skewness 1.7, excess kurtosis 4.8): the standard deviation of a 50-run baseline then varies twice as much as
    under normal noise, and limits calibrated on normal noise alarmed on 3.1 % of stationary 200-run campaigns
    where 0.83 % was asked. The simulated campaigns are seeded, so a campaign gets the same limits every time."""
    if not (0 < alpha < 1 and 0 < alpha_outlier < 1):
        raise AnalysisError(f"false-alarm rates must lie in (0, 1), got {alpha:g} and {alpha_outlier:g}")
    design = np.asarray(design, float)
    base = np.asarray(base, bool)
    shape = None if shape is None or int(base.sum()) < MIN_BOOTSTRAP else np.asarray(shape, float)
    key = (design.shape, design.tobytes(), base.tobytes(), None if shape is None else shape.tobytes(), alpha,
           alpha_outlier, lam, k, clip, min_size, draws, seed)
    if key not in _MEMO:
        if len(_MEMO) >= _MEMO_SIZE:
            _MEMO.pop(next(iter(_MEMO)))
        _MEMO[key] = _calibrate(design, base, noise(draws, design.shape[0], seed, shape), alpha, alpha_outlier, lam,
                                k, clip, min_size)
    return _MEMO[key]


@lru_cache(maxsize=8)
def _normal(draws: int, n: int, seed: int) -> np.ndarray:
    """Normal in-control noise (read-only): every design of the same length reuses it."""
    out = np.random.default_rng(seed).standard_normal((draws, n))
    out.flags.writeable = False
    return out


def noise(draws: int, n: int, seed: int, shape: np.ndarray | None) -> np.ndarray:
    """In-control noise for ``draws`` campaigns of ``n`` runs: normal, or a smoothed bootstrap of ``shape``
    (values standardised to mean 0 and variance 1, resampled, plus normal noise of bandwidth
    h = 0.9*n_s^(-1/5) (Silverman's rule for unit variance), rescaled to unit variance). Only the law's shape
    matters: the scores are invariant to its location and scale."""
    if shape is None:
        return _normal(draws, n, seed)
    u = shape[np.isfinite(shape)]
    u = (u - u.mean()) / u.std()
    h = 0.9 * u.size ** -0.2
    rng = np.random.default_rng(seed)
    return (rng.choice(u, (draws, n)) + h * rng.standard_normal((draws, n))) / np.sqrt(1.0 + h * h)


def _calibrate(design: np.ndarray, base: np.ndarray, e: np.ndarray, alpha: float, alpha_outlier: float, lam: float,
               k: float, clip: float, min_size: int) -> Limits:
    draws = e.shape[0]
    z, _, _ = standardise(e, design, base)
    zc = clipped(z, base, clip)
    mon = ~base
    q = 1.0 - alpha
    ewma = cusum = np.inf
    if mon.any():
        w, sd = ewma_paths(zc[:, mon], lam)
        ewma = float(np.quantile(np.max(np.abs(w) / sd, axis=1), q))
        hi, lo = cusum_paths(zc[:, mon], k)
        cusum = float(np.quantile(np.maximum(hi.max(axis=1), lo.max(axis=1)), q))
    gain = split_gain(zc, min_size)
    penalty = float(np.quantile(gain, q)) if np.isfinite(gain).all() else np.inf
    outlier = float(np.quantile(np.max(np.abs(z), axis=1), 1.0 - alpha_outlier))
    return Limits(ewma, cusum, penalty, outlier, alpha, alpha_outlier, draws)
