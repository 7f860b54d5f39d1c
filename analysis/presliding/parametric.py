"""Parametric virgin curve of rolling friction (Al-Bender and Symens' shape), fitted beside the model-free NNLS:

    phi(s) = h*[1 - (d/(d+|s|))^2]*sign(s)

h (N*m or N) is the level as |s| -> inf, d (rad or m) the characteristic presliding distance; the slope at 0 is
2h/d. The fit uses the virgin ramp, F = c0 + b*x' + phi(x - x0), and the first branch after the first reversal
(x_r, F_r) while Masing's rule alone holds (travel up to twice the ramp's): F = F_r + 2*phi((x - x_r)/2) + b*x',
with F_r = c0 + phi(x_r - x0). Solved by scipy.optimize.least_squares in (log h, log d, c0, b); the standard
uncertainties come from the Jacobian covariance s^2*(J^T J)^-1 (independent residuals assumed: it sees noise, not
a wrong shape or quantisation bias). Derived: K_0 = 2h/d, x_p(f) = d*(1/sqrt(1 - f) - 1), and h as an
extrapolated break-away (beyond the measured travel: phi reaches h only as s -> inf).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hilbench.analysis.errors import AnalysisError


def rolling_virgin(s: np.ndarray, h: float, d: float) -> np.ndarray:
    """phi(s) = h*[1 - (d/(d+|s|))^2]*sign(s) (N*m or N) at s (rad or m), any shape."""
    s = np.asarray(s, float)
    return h * (1.0 - (d / (d + np.abs(s))) ** 2) * np.sign(s)


@dataclass
class RollingFit:
    """The fitted shape. ``cov``: covariance of (log h, log d, c0, b); ``travel``: the virgin ramp's travel
    (rad or m); ``rms_error``: rms residual of the fit (N*m or N); ``samples``: samples fitted."""

    h: float
    d: float
    offset: float
    viscous: float
    cov: np.ndarray
    travel: float
    rms_error: float
    samples: int
    slope_rms: float = 0.0  # rms of the fitted curve's slope dF/dx over the fitted samples (N*m/rad or N/m)

    def expected_error(self, step: float, noise: float) -> float:
        """The rms residual quantisation (step, rad or m, uniform error) and force noise alone would leave."""
        return math.sqrt((self.slope_rms * step) ** 2 / 12 + noise ** 2)

    def virgin_curve(self, s: np.ndarray) -> np.ndarray:
        return rolling_virgin(s, self.h, self.d)

    def quantities(self, fraction: float) -> dict[str, float]:
        """{"breakaway_extrapolated": h, "initial_stiffness": 2h/d, "presliding_distance": x_p(fraction)}."""
        return {"breakaway_extrapolated": self.h, "initial_stiffness": 2 * self.h / self.d,
                "presliding_distance": self.d * (1 / math.sqrt(1 - fraction) - 1)}

    def uncertainties(self, fraction: float) -> dict[str, float]:
        """Standard uncertainties of :meth:`quantities` from the Jacobian covariance (first order)."""
        c = self.cov
        q = self.quantities(fraction)
        var_k = c[0, 0] + c[1, 1] - 2 * c[0, 1]  # log K_0 = log 2 + log h - log d
        return {"breakaway_extrapolated": self.h * math.sqrt(max(c[0, 0], 0.0)),
                "initial_stiffness": q["initial_stiffness"] * math.sqrt(max(var_k, 0.0)),
                "presliding_distance": q["presliding_distance"] * math.sqrt(max(c[1, 1], 0.0))}

    def level_reached(self) -> float:
        """phi(travel)/h: the fraction of h the virgin ramp reaches."""
        return float(rolling_virgin(self.travel, 1.0, self.d))


def fit_rolling(x: np.ndarray, force: np.ndarray, fs: float, reversals: np.ndarray, viscous: bool = True) -> RollingFit:
    """Fit phi to the virgin ramp and the first Masing branch of a presliding record.

    Args:
        x: displacement, shape (n,), rad or m, relaxed at x[0]; force: shape (n,), N*m or N; fs: Hz.
        reversals: turning-point indices (at least one: the end of the virgin ramp).
        viscous: fit b*x' too; False for points without a velocity (the dwells of edges.py), b is then 0.
    Returns:
        :class:`RollingFit`; AnalysisError when the ramp is too short or the fit fails.
    """
    from scipy.optimize import least_squares

    x, force = np.asarray(x, float), np.asarray(force, float)
    if reversals.size == 0:
        raise AnalysisError("the parametric fit needs a virgin ramp ending in a reversal")
    r0 = int(reversals[0])
    r1 = int(reversals[1]) if reversals.size > 1 else x.size - 1
    if r0 < 10:
        raise AnalysisError(f"the virgin ramp has {r0 + 1} samples: too short for the parametric fit")
    travel = abs(x[r0] - x[0])
    branch = np.arange(r0 + 1, r1 + 1)
    branch = branch[np.abs(x[branch] - x[r0]) <= 2 * travel]  # beyond, the branch joins the mirrored virgin curve
    ramp = np.arange(0, r0 + 1)
    v = np.gradient(x) * fs if viscous else np.zeros_like(x)
    y = np.concatenate([force[ramp], force[branch]])
    scale = float(np.ptp(force[ramp])) or 1.0
    vs = float(np.max(np.abs(v))) or 1.0
    n_par = 4 if viscous else 3

    def model(p):
        h, d = (math.exp(min(max(v, -60.0), 60.0)) for v in p[:2])  # a diverging step stays finite
        c0, b = p[2] * scale, (p[3] * scale / vs if viscous else 0.0)
        fr = c0 + rolling_virgin(x[r0] - x[0], h, d)
        return np.concatenate([c0 + rolling_virgin(x[ramp] - x[0], h, d) + b * v[ramp],
                               fr + 2 * rolling_virgin((x[branch] - x[r0]) / 2, h, d) + b * v[branch]])

    rise = np.abs(force[ramp] - force[0])
    half = np.abs(x[ramp] - x[0])[np.argmax(rise >= 0.5 * rise.max())]
    d0 = max(half / 0.414, travel * 1e-3)
    p0 = [math.log(1.2 * rise.max() or 1.0), math.log(d0), force[0] / scale, 0.0][:n_par]
    try:
        sol = least_squares(lambda p: model(p) - y, p0, x_scale="jac", method="lm")
    except ValueError as exc:  # non-finite residuals
        raise AnalysisError(f"the parametric virgin-curve fit failed: {exc}") from None
    if not sol.success or not np.all(np.isfinite(sol.x)) or abs(sol.x[0]) >= 60 or abs(sol.x[1]) >= 60:
        raise AnalysisError("the parametric virgin-curve fit found no finite h and d: the ramp does not determine "
                            f"the shape ({sol.message})")
    resid = sol.fun
    dof = max(y.size - n_par, 1)
    s2 = float(resid @ resid) / dof
    cov = np.zeros((4, 4))
    try:
        cov[:n_par, :n_par] = np.linalg.inv(sol.jac.T @ sol.jac) * s2
    except np.linalg.LinAlgError:
        cov[:n_par, :n_par] = np.inf
    cov[2:, :] *= scale
    cov[:, 2:] *= scale
    cov[3, :] /= vs
    cov[:, 3] /= vs
    p = sol.x
    h, d = math.exp(p[0]), math.exp(p[1])
    s = np.concatenate([np.abs(x[ramp] - x[0]), np.abs(x[branch] - x[r0]) / 2])
    slope = 2 * h * d ** 2 / (d + s) ** 3  # phi'(s); Masing's branch has the same slope at half the travel
    return RollingFit(h, d, p[2] * scale, p[3] * scale / vs if viscous else 0.0, cov, float(travel),
                      math.sqrt(float(resid @ resid) / y.size), int(y.size), float(np.sqrt(np.mean(slope ** 2))))
