"""Parametric virgin curve of rolling friction, fitted beside the model-free NNLS:

    phi(s) = h*[1 - (d/(d+|s|))^p]*sign(s)

h (N*m or N) is the level as |s| -> inf, d (rad or m) a characteristic presliding distance, p the shape exponent;
the slope at 0 is p*h/d. p = 2 is Al-Bender and Symens' rolling-friction shape (the default, the measured
baseline); a free p (``exponent=None``) also covers a hyperbolic approach (p = 1) and, as p and d grow with d/p
fixed, Dahl's exponential h*(1 - exp(-p*s/d)). The fit uses the virgin ramp, F = c0 + b*x' + phi(x - x0), and the
first branch after the first reversal (x_r, F_r) while Masing's rule alone holds (travel up to twice the ramp's):
F = F_r + 2*phi((x - x_r)/2) + b*x', with F_r = c0 + phi(x_r - x0). Solved by scipy.optimize.least_squares in
(log h, log d, c0, b, log p); the standard uncertainties come from the Jacobian covariance s^2*(J^T J)^-1
(independent residuals assumed: it sees noise, not a wrong shape or quantisation bias). Derived: K_0 = p*h/d,
x_p(f) = d*((1 - f)^(-1/p) - 1), and h as an extrapolated break-away (beyond the measured travel: phi reaches h
only as s -> inf).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hilbench.analysis.errors import AnalysisError

#: a free exponent is searched in exp(+-MAX_LOG_EXPONENT); at the upper bound the shape is the exponential limit,
#: (d/(d+s))^p -> exp(-p*s/d), and the fit is repeated with p held there (d/p is then what is determined)
MAX_LOG_EXPONENT = 10.0
EXPONENTIAL_LIMIT = math.exp(MAX_LOG_EXPONENT)


def rolling_virgin(s: np.ndarray, h: float, d: float, p: float = 2.0) -> np.ndarray:
    """phi(s) = h*[1 - (d/(d+|s|))^p]*sign(s) (N*m or N) at s (rad or m), any shape."""
    s = np.asarray(s, float)
    return -h * np.expm1(-p * np.log1p(np.abs(s) / d)) * np.sign(s)  # log space: p and d may both be large


@dataclass
class RollingFit:
    """The fitted shape. ``cov``: covariance of (log h, log d, c0, b, log p, x0, x_r), zero rows for what was held
    fixed; ``exponent``: p (2 unless fitted free); ``travel``: the virgin ramp's travel (rad or m); ``rms_error``:
    rms residual of the fit (N*m or N); ``samples``: samples fitted."""

    h: float
    d: float
    offset: float
    viscous: float
    cov: np.ndarray
    travel: float
    rms_error: float
    samples: int
    slope_rms: float = 0.0  # rms of the fitted curve's slope dF/dx over the fitted samples (N*m/rad or N/m)
    exponent: float = 2.0
    exponent_free: bool = False
    origin: float | None = None  # fitted x0 - x[0] (rad or m); None: x0 = x[0] was assumed
    turn: float | None = None  # fitted x_r - x[r0] (rad or m); None: x_r = x[r0] was taken as exact
    origin_uncertainty: dict[str, float] = field(default_factory=dict)  # type-B part of an assumed x0

    def expected_error(self, step: float, noise: float) -> float:
        """The rms residual quantisation (step, rad or m, uniform error) and force noise alone would leave."""
        return math.sqrt((self.slope_rms * step) ** 2 / 12 + noise ** 2)

    def virgin_curve(self, s: np.ndarray) -> np.ndarray:
        return rolling_virgin(s, self.h, self.d, self.exponent)

    @property
    def shape(self) -> str:
        """The fitted shape as a formula."""
        if self.exponent_free:
            return "h*(1-(d/(d+|x|))^p)*sign(x)"
        if self.exponent >= EXPONENTIAL_LIMIT:
            return "h*(1-exp(-p*|x|/d))*sign(x) (the exponential limit of the free exponent)"
        return f"h*(1-(d/(d+|x|))^{self.exponent:g})*sign(x)"

    def origin_text(self, step: float, unit: str) -> str:
        """How the relaxed position (and the first turn) entered the fit, for the summary."""
        if self.origin is None:
            extra = " (its type-B uncertainty is included)" if self.origin_uncertainty else ""
            return f"relaxed position assumed at the rest count{extra}"
        text = f"relaxed position fitted at {self.origin / step:+.3f} steps from the rest count"
        if self.turn is not None:
            text += f", first turn {self.turn / step:+.3f} steps from its count's centre"
        return text + f" (step {step:.3g} {unit})"

    def exponent_text(self, fraction: float = 0.9) -> str:
        """'p = 1.76 +- 0.34' when fitted, 'p = 2 (held)' when not."""
        if not self.exponent_free:
            return f"p = {self.exponent:g} (held)"
        return f"p = {self.exponent:.3g} +- {self.uncertainties(fraction)['exponent']:.2g}"

    def quantities(self, fraction: float) -> dict[str, float]:
        """{"breakaway_extrapolated": h, "initial_stiffness": p*h/d, "presliding_distance": x_p(fraction)}."""
        p = self.exponent
        return {"breakaway_extrapolated": self.h, "initial_stiffness": p * self.h / self.d,
                "presliding_distance": self.d * ((1 - fraction) ** (-1 / p) - 1)}

    def uncertainties(self, fraction: float) -> dict[str, float]:
        """Standard uncertainties of :meth:`quantities` (and of p) from the Jacobian covariance, first order in
        (log h, log d, log p)."""
        c = self.cov[np.ix_([0, 1, 4], [0, 1, 4])]
        q = self.quantities(fraction)
        p, lnf = self.exponent, math.log(1 - fraction)
        g = math.exp(-lnf / p)  # (1-f)^(-1/p)
        grads = {"breakaway_extrapolated": np.array([1.0, 0.0, 0.0]),
                 "initial_stiffness": np.array([1.0, -1.0, 1.0]),  # log K_0 = log p + log h - log d
                 "presliding_distance": np.array([0.0, 1.0, g * (lnf / p) / (g - 1)])}
        def sd(var: float) -> float:  # an undetermined fit (inf or nan in cov) is unbounded, not 0
            return math.sqrt(max(var, 0.0)) if math.isfinite(var) else math.inf

        with np.errstate(invalid="ignore"):
            out = {name: math.hypot(q[name] * sd(float(v @ c @ v)), self.origin_uncertainty.get(name, 0.0))
                   for name, v in grads.items()}
        out["exponent"] = p * sd(float(c[2, 2]))
        return out

    def level_reached(self) -> float:
        """phi(travel)/h: the fraction of h the virgin ramp reaches."""
        return float(rolling_virgin(self.travel, 1.0, self.d, self.exponent))


def fit_rolling(x: np.ndarray, force: np.ndarray, fs: float, reversals: np.ndarray, viscous: bool = True,
                exponent: float | None = 2.0, origin_range: float = 0.0,
                turn_range: float = 0.0) -> RollingFit:
    """Fit phi to the virgin ramp and the first Masing branch of a presliding record.

    Args:
        x: displacement, shape (n,), rad or m, relaxed at x[0]; force: shape (n,), N*m or N; fs: Hz.
        reversals: turning-point indices (at least one: the end of the virgin ramp).
        viscous: fit b*x' too; False for points without a velocity (the dwells of edges.py), b is then 0.
        exponent: the shape exponent p held fixed (2: the rolling-friction shape), or None to fit it.
        origin_range: > 0 (rad or m): the relaxed position x0 is not x[0] but somewhere in x[0] +- origin_range/2,
            fitted (an encoder count at rest says only which step the contact is in). It is determined only with
            the first branch, whose turning point x_r is known: then phi is seen from both ends.
        turn_range: > 0 (rad or m): the first turning point x_r is somewhere in x[r0] +- turn_range/2, fitted (the
            contact turned inside a step, not at an edge). With origin_range or turn_range set, the turning point's
            own force is left out: it is a dwell's mean over the end of the ramp and the start of the unloading.
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
    turned = turn_range > 0
    if origin_range > 0 or turned:
        ramp = ramp[:-1]
    v = np.gradient(x) * fs if viscous else np.zeros_like(x)
    y = np.concatenate([force[ramp], force[branch]])
    scale = float(np.ptp(force[ramp])) or 1.0
    vs = float(np.max(np.abs(v))) or 1.0
    free = exponent is None
    if not free and not (math.isfinite(exponent) and exponent > 0):
        raise AnalysisError(f"the shape exponent must be finite and > 0, got {exponent}")
    moved = origin_range > 0
    # parameter vector: log h, log d, c0/scale, [b*vs/scale], [log p], [u: x0 = x[0] + origin_range/2*tanh(u)],
    # [w: x_r = x[r0] + turn_range/2*tanh(w)]; idx maps them onto the 7 of cov (log h, log d, c0, b, log p, x0, x_r)
    idx = [0, 1, 2] + ([3] if viscous else []) + ([4] if free else []) + ([5] if moved else []) \
        + ([6] if turned else [])
    n_par = len(idx)

    def unpack(p):
        h, d = (math.exp(min(max(v, -60.0), 60.0)) for v in p[:2])  # a diverging step stays finite
        pw = math.exp(min(max(p[idx.index(4)], -MAX_LOG_EXPONENT), MAX_LOG_EXPONENT)) if free else exponent
        x0 = x[0] + 0.5 * origin_range * math.tanh(p[idx.index(5)]) if moved else x[0]
        xr = x[r0] + 0.5 * turn_range * math.tanh(p[-1]) if turned else x[r0]
        return h, d, p[2] * scale, (p[3] * scale / vs if viscous else 0.0), pw, x0, xr

    def model(p):
        h, d, c0, b, pw, x0, xr = unpack(p)
        fr = c0 + rolling_virgin(xr - x0, h, d, pw)
        s = x[ramp] - x0
        s[0] = 0.0  # the first point is the contact at rest: at x0, wherever x0 lies in its step
        return np.concatenate([c0 + rolling_virgin(s, h, d, pw) + b * v[ramp],
                               fr + 2 * rolling_virgin((x[branch] - xr) / 2, h, d, pw) + b * v[branch]])

    rise = np.abs(force[ramp] - force[0])
    half = np.abs(x[ramp] - x[0])[np.argmax(rise >= 0.5 * rise.max())]
    d0 = max(half / 0.414, travel * 1e-3) * (1.0 if free else exponent / 2)  # the same initial slope for any p
    p0 = [math.log(1.2 * rise.max() or 1.0), math.log(d0), force[0] / scale] + ([0.0] if viscous else []) \
        + ([math.log(2.0)] if free else []) + ([0.0] if moved else []) + ([0.0] if turned else [])
    try:
        sol = least_squares(lambda p: model(p) - y, p0, x_scale="jac", method="lm")
    except ValueError as exc:  # non-finite residuals
        raise AnalysisError(f"the parametric virgin-curve fit failed: {exc}") from None
    if not sol.success or not np.all(np.isfinite(sol.x)) or abs(sol.x[0]) >= 60 or abs(sol.x[1]) >= 60 \
            or (free and sol.x[idx.index(4)] <= -MAX_LOG_EXPONENT + 0.01):
        raise AnalysisError("the parametric virgin-curve fit found no finite h and d: the ramp does not determine "
                            f"the shape ({sol.message})")
    if free and sol.x[idx.index(4)] >= MAX_LOG_EXPONENT - 0.01:  # Dahl's exponential: p and d grow together
        return fit_rolling(x, force, fs, reversals, viscous, EXPONENTIAL_LIMIT, origin_range, turn_range)
    resid = sol.fun
    dof = max(y.size - n_par, 1)
    s2 = float(resid @ resid) / dof
    cov = np.zeros((7, 7))
    try:
        cov[np.ix_(idx, idx)] = np.linalg.inv(sol.jac.T @ sol.jac) * s2
    except np.linalg.LinAlgError:
        cov[np.ix_(idx, idx)] = np.inf
    dx0 = 0.5 * origin_range * (1 - math.tanh(sol.x[idx.index(5)]) ** 2) if moved else 0.0
    dxr = 0.5 * turn_range * (1 - math.tanh(sol.x[-1]) ** 2) if turned else 0.0
    units = np.array([1.0, 1.0, scale, scale / vs, 1.0, dx0, dxr])  # back from the scaled parameters
    cov *= np.outer(units, units)
    h, d, c0, b, pw, x0, xr = unpack(sol.x)
    s = np.concatenate([np.abs(x[ramp] - x0), np.abs(x[branch] - xr) / 2])
    slope = pw * h / (d + s) * np.exp(-pw * np.log1p(s / d))  # phi'(s); a Masing branch's at half the travel
    return RollingFit(h, d, c0, b, cov, float(travel), math.sqrt(float(resid @ resid) / y.size), int(y.size),
                      float(np.sqrt(np.mean(slope ** 2))), pw, free, float(x0 - x[0]) if moved else None,
                      float(xr - x[r0]) if turned else None)


def origin_uncertainty(fit: RollingFit, x: np.ndarray, refit: Callable[[np.ndarray], RollingFit], step: float,
                       fraction: float = 0.9, nodes: int = 8) -> RollingFit:
    """``fit`` (of a virgin ramp alone at positions ``x``, rad or m, the contact at rest at x[0]) with the
    uncertainty its assumed origin adds (GUM type B). An encoder count at rest says only that the relaxed position
    lies somewhere in the step (rad or m), uniformly. For shifts a at the midpoints of ``nodes`` equal parts of the
    step, the fitted curve is sampled as if the contact had rested at x[0] + a, c0 + phi(x - x[0] - a), and
    ``refit(force)`` fits it again with x0 at x[0]; each quantity's contribution is its standard deviation over the
    shifts (the distribution integrated numerically: the response is far from linear as x0 nears the first edge).
    A refit that fails leaves the quantities unbounded (inf)."""
    x = np.asarray(x, float)
    values = []
    try:
        for a in (np.arange(nodes) + 0.5) / nodes * step - 0.5 * step:
            s = x - x[0] - a
            s[0] = 0.0
            values.append(refit(fit.offset + fit.virgin_curve(s)).quantities(fraction))
        fit.origin_uncertainty = {k: float(np.std([v[k] for v in values])) for k in values[0]}
    except AnalysisError:
        fit.origin_uncertainty = {k: math.inf for k in fit.quantities(fraction)}
    return fit
