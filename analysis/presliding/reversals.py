"""Reversal points of a displacement path and the checks of the Maxwell-slip memory rules on measured data.

Masing's rule: after a reversal at (x_r, F_r) the branch is F(x) = F_r + d*2*V(|x - x_r|/2), d = +1 moving up,
-1 moving down, V the virgin curve (measured from the first ramp). Wiping-out: once the path passes the reversal
point before the last one (the inner loop closes), both reversals are forgotten and the curve continues on the
branch it left; beyond the largest amplitude it follows the virgin curve (mirrored). Both rules together give a
prediction of the force from the measured virgin curve and the measured reversal forces only, with no model.
A Maxwell-slip system starting relaxed obeys them exactly; GMS and LuGre-type memories do not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hilbench.analysis.errors import AnalysisError


def find_reversals(x: np.ndarray, hysteresis: float) -> np.ndarray:
    """Indices of the turning points of a path: the extreme sample of each monotone run (the last one of a plateau
    there), a run ending only when the path retreats by more than ``hysteresis`` (same unit as x, m or rad).

    Args:
        x: path, shape (n,), m or rad.
        hysteresis: the smallest travel counted as a reversal (>= 0; a few position counts or noise levels).
    Returns:
        int array of the turning-point indices, increasing; the path's end is not a turning point.
    """
    x = np.asarray(x, float)
    if not hysteresis >= 0:
        raise AnalysisError(f"reversal hysteresis must be >= 0, got {hysteresis}")
    turning: list[int] = []
    start = x[0]
    direction = 0
    extreme = 0
    for i, v in enumerate(x.tolist()):
        if direction == 0:
            if abs(v - start) > hysteresis:
                direction, extreme = (1 if v > start else -1), i
        elif (v - x[extreme]) * direction >= 0:  # the last sample of a plateau: where the motion turns back
            extreme = i
        elif (x[extreme] - v) * direction > hysteresis:
            turning.append(extreme)
            direction, extreme = -direction, i
    return np.asarray(turning, dtype=int)


@dataclass
class MemoryCheck:
    """Prediction of the force by the Masing and wiping-out rules, and its departure from the measured force.

    Attributes:
        predicted: force predicted at every sample (N or N*m), NaN on the virgin ramp and where V is not measured.
        rule: per sample 0 (not checked), 1 (Masing: a fresh branch from the last reversal), 2 (after wiping-out:
            an older branch or the virgin curve, resumed after an inner loop closed).
        reversal_rules: force each reversal is predicted to have by the rules, from the previous reversals'
            measured forces (NaN for the first).
        depth: nesting depth of each reversal (number of remembered reversal points after it).
        closures: (index of the sample where an inner loop closed, force departure there) per closed loop.
        scale: the normalising force: the largest |V| measured on the virgin ramp (N or N*m).
    """

    predicted: np.ndarray
    rule: np.ndarray
    reversal_rules: np.ndarray
    depth: np.ndarray
    closures: list[tuple[int, float]]
    scale: float

    def departure(self, force: np.ndarray, rule: int) -> tuple[float, float, int]:
        """(max, rms) of |F - predicted|/scale over the samples checked by ``rule`` and their count."""
        sel = (self.rule == rule) & np.isfinite(self.predicted)
        if not np.any(sel):
            return float("nan"), float("nan"), 0
        d = np.abs(np.asarray(force, float)[sel] - self.predicted[sel]) / self.scale
        return float(d.max()), float(np.sqrt(np.mean(d**2))), int(sel.sum())

    @property
    def closure_departure(self) -> float:
        """Largest |F at the closing point - F of the remembered reversal|/scale over the closed loops."""
        return max((abs(d) for _, d in self.closures), default=float("nan")) / self.scale


def memory_check(x: np.ndarray, force: np.ndarray, reversals: np.ndarray) -> MemoryCheck:
    """Predict the force after the virgin ramp from the measured virgin curve and the measured reversal forces
    (Masing's rule on each fresh branch, wiping-out once an inner loop closes; see the module docstring).

    Args:
        x: displacement, shape (n,), m or rad; the record starts relaxed at x[0] with a virgin ramp.
        force: measured force, shape (n,), N or N*m (an offset cancels: V is measured relative to force[0]).
        reversals: turning-point indices (:func:`find_reversals`), at least one.
    Returns:
        :class:`MemoryCheck`. V between virgin samples is linearly interpolated.
    """
    x = np.asarray(x, float)
    f = np.asarray(force, float)
    if reversals.size == 0:
        raise AnalysisError("the record has no reversal: the memory rules need at least one turning point")
    r0 = int(reversals[0])
    x0, f0 = x[0], f[0]
    sgn = 1.0 if x[r0] > x0 else -1.0
    s_v = sgn * (x[: r0 + 1] - x0)
    v_v = sgn * (f[: r0 + 1] - f0)
    keep = np.concatenate([[True], s_v[1:] > np.maximum.accumulate(s_v)[:-1]])  # strictly increasing travel
    s_v, v_v = s_v[keep], v_v[keep]
    s_max = float(s_v[-1])
    scale = float(np.max(np.abs(v_v)))
    if not scale > 0:
        raise AnalysisError("the virgin ramp shows no force change: nothing to check the memory rules against")

    def virgin(s: float) -> float:
        return float(np.interp(s, s_v, v_v)) if s <= s_max * (1 + 1e-12) else float("nan")

    n = x.size
    pred = np.full(n, np.nan)
    rule = np.zeros(n, dtype=np.int8)
    rev_pred = np.full(reversals.size, np.nan)
    depth = np.zeros(reversals.size, dtype=int)
    closures: list[tuple[int, float]] = []
    stack: list[tuple[float, float]] = []  # remembered reversal points (x, F), outermost first
    wiped = False
    next_rev = 0
    for j in range(r0, n):
        if stack:
            xt, ft = stack[-1]
            d = 1.0 if x[j] > xt else -1.0 if x[j] < xt else 0.0
            # the point this branch closes on: the previous reversal, or the mirror of the first one
            partner = stack[-2][0] if len(stack) > 1 else 2 * x0 - stack[0][0]
            while stack and d != 0 and (x[j] - partner) * d > 0:
                fp = stack[-2][1] if len(stack) > 1 else f0 - (stack[0][1] - f0)
                closures.append((j, _interp_closure(x, f, j, partner) - fp))
                stack = stack[:-2] if len(stack) > 1 else []
                wiped = True
                if stack:
                    xt, ft = stack[-1]
                    partner = stack[-2][0] if len(stack) > 1 else 2 * x0 - stack[0][0]
            if stack:
                pred[j] = ft + d * 2.0 * virgin(abs(x[j] - xt) / 2.0)
            else:
                pred[j] = f0 + np.sign(x[j] - x0) * virgin(abs(x[j] - x0))
            rule[j] = 2 if wiped else 1
        if next_rev < reversals.size and j == reversals[next_rev]:
            if next_rev > 0:
                rev_pred[next_rev] = pred[j]
            stack.append((x[j], f[j]))
            depth[next_rev] = len(stack)
            next_rev += 1
            wiped = False
    rule[:r0 + 1] = 0
    pred[:r0 + 1] = np.nan
    return MemoryCheck(pred, rule, rev_pred, depth, closures, scale)


def _interp_closure(x: np.ndarray, f: np.ndarray, j: int, xc: float) -> float:
    """Force where the path crosses xc between samples j-1 and j (linear), N or N*m."""
    x1, x2 = x[j - 1], x[j]
    if x2 == x1:
        return float(f[j])
    a = (xc - x1) / (x2 - x1)
    return float(f[j - 1] + min(max(a, 0.0), 1.0) * (f[j] - f[j - 1]))


def extreme_forces(force: np.ndarray, reversals: np.ndarray, window: int) -> np.ndarray:
    """The force at each turning point, read as the branch's extreme: on a Maxwell-slip branch the force is monotone
    in the travel, so the turning point carries the largest force (into a maximum of x) or the smallest (into a
    minimum). The force is first averaged over ``window`` samples (scipy.ndimage.uniform_filter1d), and the extreme
    is searched from half-way back to the previous turning point to half-way on to the next one. Unlike the force
    at the turning sample, this needs no position: an encoder that does not resolve where the path turned, or a
    position loop that creeps back during a hold, does not move it.

    Args:
        force: shape (n,), N or N*m; reversals: turning-point indices into force (find_reversals), increasing,
        the first one the end of the virgin ramp (a maximum when the ramp rose); window: samples, >= 1.
    Returns:
        shape (reversals.size,), N or N*m.
    """
    from scipy.ndimage import uniform_filter1d

    force = np.asarray(force, float)
    smooth = uniform_filter1d(force, max(1, int(window)), mode="nearest")
    bounds = np.concatenate([[0], reversals, [force.size - 1]])
    rising = force[reversals[0]] >= force[0] if reversals.size else True
    out = np.empty(reversals.size)
    for n, r in enumerate(reversals):
        a, z = (r + bounds[n]) // 2, (r + bounds[n + 2]) // 2 + 1
        is_max = (n % 2 == 0) == rising
        out[n] = smooth[a:z].max() if is_max else smooth[a:z].min()
    return out
