"""Continuous fits of composed skeleton curves: the paper's functional forms, and a form-free monotone fit.

Paper (Tjahjowidodo 2012, eqs. 6.1-6.2; the coefficients and the digits 0/1 were lost in our copy, so the
restoring form is a reconstruction, science.md §4):

    F_k(x) = a*(1 - exp(-b*x^c)) + p / Gamma(q*x^r)          (restoring force, odd in x)
    F_d(v) = a*(1 - exp(-b*(v - v0))) * H(v - v0)             (damping force with dead-zone v0, odd in v)

1/Gamma(z) rises from 0 like z, peaks at z = 1.46 and decays, which gives the rise-and-fall of the friction
restoring force once the linear spring is subtracted.

Form-free alternative: bin the data on log-spaced abscissae, take bin medians, project them onto the monotone
sequences with ``scipy.optimize.isotonic_regression`` (weights = bin counts) and interpolate with
``scipy.interpolate.PchipInterpolator`` (shape-preserving, so the curve stays monotone). k_eq(A) decreases and
F_d(V) increases for Masing/Maxwell-slip friction, so the restoring force is fitted as k_eq(A)*A.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.optimize import curve_fit, isotonic_regression
from scipy.special import rgamma
from scipy.stats import binned_statistic

from hilbench.analysis.errors import AnalysisError


def paper_restoring_force(
    x: np.ndarray, a: float, b: float, c: float, p: float, q: float, r: float
) -> np.ndarray:
    """F_k(x) = sign(x)*[a*(1 - exp(-b*|x|^c)) + p/Gamma(q*|x|^r)]; x in m (rad), returns N (N*m)."""
    x = np.asarray(x, dtype=float)
    ax = np.abs(x)
    return np.sign(x) * (a * (1.0 - np.exp(-b * ax**c)) + p * rgamma(q * ax**r))


def paper_damping_force(v: np.ndarray, a: float, b: float, v0: float) -> np.ndarray:
    """F_d(v) = sign(v)*a*(1 - exp(-b*(|v| - v0)))*H(|v| - v0); v in m/s (rad/s), returns N (N*m)."""
    v = np.asarray(v, dtype=float)
    av = np.abs(v)
    return np.sign(v) * np.where(av > v0, a * (1.0 - np.exp(-b * (av - v0))), 0.0)


@dataclass(frozen=True)
class PaperFit:
    """Least-squares fit of one of the paper's forms.

    Attributes:
        form: "restoring" or "damping".
        params: fitted coefficients by name.
        rms: root-mean-square residual, N (N*m).
    """

    form: str
    params: dict[str, float]
    rms: float

    def __call__(self, x: np.ndarray) -> np.ndarray:
        f = paper_restoring_force if self.form == "restoring" else paper_damping_force
        return f(x, **self.params)


def _xy(x, y, name: str) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if x.shape != y.shape:
        raise AnalysisError(f"{name}: abscissa and ordinate differ in length ({x.size} vs {y.size})")
    ok = np.isfinite(x) & np.isfinite(y) & (x > 0)
    if ok.sum() < 8:
        raise AnalysisError(f"{name}: need at least 8 finite points with positive abscissa, got {ok.sum()}")
    return x[ok], y[ok]


def fit_paper_restoring(amplitude: np.ndarray, force: np.ndarray) -> PaperFit:
    """Fit F_k(x) = a*(1 - exp(-b*x^c)) + p/Gamma(q*x^r) to restoring force against amplitude.

    Args:
        amplitude: displacement amplitudes A > 0, m, shape (n,).
        force: restoring force at those amplitudes, N, shape (n,).
    Returns:
        PaperFit with params a (N), b (m^-c), c, p (N), q (m^-r), r.
    Raises:
        AnalysisError: too few points, or no start converges.
    """
    x, y = _xy(amplitude, force, "restoring fit")
    fmax = float(np.max(np.abs(y)))
    x_peak = float(x[np.argmax(y)])
    lo = [-10 * fmax, 0.0, 0.05, -10 * fmax, 1e-9, 0.05]
    hi = [10 * fmax, np.inf, 3.0, 10 * fmax, np.inf, 3.0]
    best = None
    for r0 in (1.0, 0.5, 2.0):
        for a0 in (float(y[np.argmax(x)]), 0.0):
            p0 = [a0, 1.0 / float(np.median(x)), 0.5, fmax / 1.13, 1.46 / x_peak**r0, r0]
            try:
                popt, _ = curve_fit(paper_restoring_force, x, y, p0=p0, bounds=(lo, hi), maxfev=20000)
            except (RuntimeError, ValueError):
                continue
            rms = float(np.sqrt(np.mean((paper_restoring_force(x, *popt) - y) ** 2)))
            if best is None or rms < best[1]:
                best = (popt, rms)
    if best is None:
        raise AnalysisError("restoring fit: no start converged for the paper's form")
    names = ("a", "b", "c", "p", "q", "r")
    return PaperFit("restoring", dict(zip(names, map(float, best[0]), strict=True)), best[1])


def fit_paper_damping(velocity: np.ndarray, force: np.ndarray) -> PaperFit:
    """Fit F_d(v) = a*(1 - exp(-b*(v - v0)))*H(v - v0) to damping force against velocity amplitude.

    Args:
        velocity: velocity amplitudes V > 0, m/s, shape (n,).
        force: damping force at those velocities, N, shape (n,).
    Returns:
        PaperFit with params a (N), b (s/m), v0 (m/s, the dead-zone).
    """
    v, y = _xy(velocity, force, "damping fit")
    fmax = float(np.max(y))
    if not fmax > 0:
        raise AnalysisError("damping fit: the damping force is nowhere positive")
    v_on = float(np.min(v[y > 0.05 * fmax]))
    best = None
    for scale in (1.0, 0.3, 3.0):
        p0 = [fmax, 3.0 * scale / float(np.median(v)), 0.5 * v_on]
        try:
            popt, _ = curve_fit(paper_damping_force, v, y, p0=p0,
                                bounds=([0, 0, 0], [10 * fmax, np.inf, v.max()]), maxfev=20000)
        except (RuntimeError, ValueError):
            continue
        rms = float(np.sqrt(np.mean((paper_damping_force(v, *popt) - y) ** 2)))
        if best is None or rms < best[1]:
            best = (popt, rms)
    if best is None:
        raise AnalysisError("damping fit: no start converged for the paper's form")
    return PaperFit("damping", dict(zip(("a", "b", "v0"), map(float, best[0]), strict=True)), best[1])


@dataclass(frozen=True)
class MonotoneFit:
    """Monotone PCHIP curve through isotonic bin medians; held constant beyond the end knots.

    Attributes:
        knots_x: bin medians of the abscissa, shape (m,), increasing.
        knots_y: isotonic bin values, shape (m,), monotone.
        increasing: direction of monotonicity.
    """

    knots_x: np.ndarray
    knots_y: np.ndarray
    increasing: bool

    def __call__(self, x: np.ndarray) -> np.ndarray:
        xc = np.clip(np.asarray(x, dtype=float), self.knots_x[0], self.knots_x[-1])
        if self.knots_x.size == 1:
            return np.full_like(xc, self.knots_y[0])
        return PchipInterpolator(self.knots_x, self.knots_y)(xc)


def fit_monotone(x: np.ndarray, y: np.ndarray, increasing: bool, n_knots: int = 30,
                 min_count: int = 1) -> MonotoneFit:
    """Form-free monotone smoothing of y(x): log-binned medians, isotonic regression, PCHIP.

    Args:
        x: abscissa > 0 (amplitude, m, or velocity, m/s), shape (n,).
        y: ordinate (k_eq in N/m, force in N...), shape (n,).
        increasing: True for a non-decreasing fit, False for non-increasing.
        n_knots: number of log-spaced bins (upper bound on the knots).
        min_count: bins with fewer points are dropped.
    Returns:
        MonotoneFit; call it on amplitudes to evaluate.
    """
    x, y = _xy(x, y, "monotone fit")
    edges = np.geomspace(x.min(), x.max() * (1 + 1e-12), n_knots + 1)
    count = binned_statistic(x, x, "count", bins=edges).statistic
    keep = count >= min_count
    if keep.sum() < 2:
        raise AnalysisError("monotone fit: fewer than two populated bins")
    kx = binned_statistic(x, x, "median", bins=edges).statistic[keep]
    ky = binned_statistic(x, y, "median", bins=edges).statistic[keep]
    iso = isotonic_regression(ky, weights=count[keep], increasing=increasing).x
    return MonotoneFit(kx, np.asarray(iso, dtype=float), increasing)


@dataclass(frozen=True)
class MonotoneSkeleton:
    """Form-free equivalent model: k_eq(A) non-increasing, F_d(V) non-decreasing.

    ``restoring_force(A) = stiffness(A)*A`` (N), ``damping_force(V)`` (N). ``table(...)`` gives the
    (grid, values) pairs the plant's ``restoring_table`` / ``damping_table`` accept.
    """

    stiffness: MonotoneFit
    damping_force: MonotoneFit

    def restoring_force(self, amplitude: np.ndarray) -> np.ndarray:
        a = np.asarray(amplitude, dtype=float)
        return self.stiffness(np.abs(a)) * a

    def tables(self, x_max: float, v_max: float, n: int = 200) -> tuple[tuple[np.ndarray, np.ndarray],
                                                                        tuple[np.ndarray, np.ndarray]]:
        """((x grid m, F_k N), (v grid m/s, F_d N)), each grid from 0 to its max in n points."""
        xg = np.linspace(0.0, x_max, n)
        vg = np.linspace(0.0, v_max, n)
        fd = np.where(vg > 0, self.damping_force(np.maximum(vg, 1e-300)), 0.0)
        return (xg, self.restoring_force(xg)), (vg, fd)


def fit_skeleton_monotone(amplitude: np.ndarray, stiffness: np.ndarray, velocity: np.ndarray,
                          damping_force: np.ndarray, n_knots: int = 30) -> MonotoneSkeleton:
    """Monotone equivalent model from skeleton points or bins (e.g. ``SkeletonCurves`` fields).

    Args:
        amplitude: A, m, shape (n,); stiffness: k_eq (spring subtracted or not), N/m, shape (n,).
        velocity: V, m/s, shape (m,); damping_force: c_eq*V, N, shape (m,).
    """
    return MonotoneSkeleton(fit_monotone(amplitude, stiffness, increasing=False, n_knots=n_knots),
                            fit_monotone(velocity, damping_force, increasing=True, n_knots=n_knots))
