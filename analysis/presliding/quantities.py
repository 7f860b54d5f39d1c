"""The friction engineer's derived quantities of an identified presliding model, their uncertainties, and what the
position resolution and the force noise no longer resolve.

- break-away force F_b = sum W_i + Fc (N or N*m): the force once every element slips;
- initial stiffness K_0 = sum k_i (N/m or N*m/rad): the slope of the virgin curve at x = 0;
- presliding distance x_p(f): the smallest x where the virgin curve sum_i k_i*min(x, Delta_i) reaches the fraction f
  of its sliding level sum W_i (m or rad). The curve is piecewise linear with breakpoints Delta_i, so x_p is exact.

Uncertainty: a moving-block residual bootstrap. The residual F - F_model(x) is cut into blocks of consecutive
samples (``blocks_per_branch`` per branch between reversals, so each block keeps the residual's correlation), blocks
are drawn with replacement onto the model's force, the model is refitted on the same threshold grid, and the standard
deviation of each quantity over the replicates is its standard uncertainty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.regressors import position_resolution
from hilbench.analysis.models.friction_model import FrictionModel
from hilbench.analysis.presliding.identify import PreslidingFit, fit_presliding
from hilbench.analysis.presliding.parametric import RollingFit
from hilbench.common.units import AXIS_UNITS

#: default fraction of the sliding level that defines the presliding distance (see docs/presliding.md)
DEFAULT_FRACTION = 0.9
#: a displacement is resolved when it spans at least this many position steps
MIN_COUNTS = 5.0
#: F_b is resolved when the elements at the top of the threshold grid (still sticking at the largest travel) hold at
#: most this fraction of it
TOP_SHARE = 0.02
#: the parametric sum(k) is usable when its standard uncertainty is at most this fraction of it ...
PARAMETRIC_REL = 0.1
#: ... and the rolling-friction shape fits the data within this fraction of h (rms residual)
PARAMETRIC_FIT = 0.01
#: ... or within this factor of the residual the quantisation and the force noise alone leave
PARAMETRIC_EXCESS = 2.0


def presliding_distance(model: FrictionModel, fraction: float = DEFAULT_FRACTION) -> float:
    """x_p: the smallest x >= 0 with sum_i k_i*min(x, Delta_i) = fraction*sum_i W_i (m or rad)."""
    if not 0 < fraction < 1:
        raise AnalysisError(f"the presliding fraction must be in (0, 1), got {fraction}")
    nodes = np.concatenate([[0.0], model.ms_delta])
    curve = model.virgin_curve(nodes)
    return float(np.interp(fraction * curve[-1], curve, nodes))


def quantities(model: FrictionModel, fraction: float = DEFAULT_FRACTION) -> dict[str, float]:
    """{"breakaway": F_b, "initial_stiffness": K_0, "presliding_distance": x_p(fraction)} in SI units."""
    return {"breakaway": model.breakaway, "initial_stiffness": float(np.sum(model.ms_stiffness)),
            "presliding_distance": presliding_distance(model, fraction)}


def bootstrap(fit: PreslidingFit, x: np.ndarray, force: np.ndarray, fs: float, reversals: np.ndarray,
              replicates: int = 20, blocks_per_branch: int = 4, fraction: float = DEFAULT_FRACTION,
              seed: int = 0) -> dict[str, float]:
    """Standard uncertainties of :func:`quantities` by the moving-block residual bootstrap (module docstring).

    Args:
        fit: the fit of ``force`` against ``x``; x (m or rad), force (N or N*m), shape (n,); fs in Hz.
        reversals: turning-point indices (sets the block length: n/((len+1)*blocks_per_branch) samples).
    Returns:
        name -> standard deviation over the replicates, same units as :func:`quantities`.
    """
    if replicates < 2:
        raise AnalysisError(f"the bootstrap needs at least 2 replicates, got {replicates}")
    x = np.asarray(x, float)
    resid = np.asarray(force, float) - fit.simulated
    n = x.size
    block = max(1, n // ((reversals.size + 1) * blocks_per_branch))
    rng = np.random.default_rng(seed)
    draws: dict[str, list[float]] = {}
    for _ in range(replicates):
        starts = rng.integers(0, n, size=math.ceil(n / block))
        idx = (starts[:, None] + np.arange(block)[None, :]).ravel()[:n] % n
        rep = fit_presliding(x, fit.simulated + resid[idx], fs, fit.model.axis, fit.settings, grid=fit.grid)
        for name, value in quantities(rep.model, fraction).items():
            draws.setdefault(name, []).append(value)
    return {name: float(np.std(v, ddof=1)) for name, v in draws.items()}


@dataclass
class Resolution:
    """What the record resolves. ``step``: position step (m or rad), ``step_source``: where it comes from;
    ``force_noise``: rms force noise (N or N*m); ``lines``: one sentence per quantity; ``resolved``: name -> bool."""

    step: float
    step_source: str
    force_noise: float
    lines: list[str]
    resolved: dict[str, bool]


def encoder_step(axis: str, counts_per_rev: float | None) -> float | None:
    """The position step (rad) of a rotary encoder of ``counts_per_rev`` counts per revolution (the run file's
    calibration), None when unknown or on a linear axis. The step comes from the calibration, not from the samples:
    a host-clocked drive's record is resampled (a spline through the counts), which takes it off the count grid."""
    return 2 * math.pi / float(counts_per_rev) if counts_per_rev and axis == "rotary" else None


def resolution(fit: PreslidingFit, x: np.ndarray, force: np.ndarray, loop_travels: np.ndarray,
               counts_per_rev: float | None = None, fraction: float = DEFAULT_FRACTION,
               step: float | None = None, rolling: RollingFit | None = None,
               edge_rolling: RollingFit | None = None, edge_fixed: RollingFit | None = None) -> Resolution:
    """Which quantities the position step and the force noise still resolve (docs/presliding.md, "Resolution").

    Args:
        fit: the identified model of ``force`` (N or N*m) against ``x`` (m or rad).
        loop_travels: travel between successive reversals (m or rad), one per branch.
        counts_per_rev: encoder counts per revolution (rotary; from the run file's calibration); None: the step
            is ``step`` (m or rad), else measured from x (smallest nonzero increment, or the noise level if larger).
    Rules: x_p needs >= MIN_COUNTS steps; K_0 needs the fitted curve straight (its first breakpoint) over at
    least MIN_COUNTS steps (else the slope at 0 is not seen and K_0 is a lower bound) and a force step K_0*step
    above 3x the force noise; F_b needs a travel of 2*x_p + MIN_COUNTS steps, F_b above 10x the noise
    and at most TOP_SHARE of it in elements at the grid's top;
    a loop's reversal force and memory checks need its travel >= MIN_COUNTS steps.
    ``rolling``: the parametric fit beside the NNLS, ``edge_rolling`` the shape with a free exponent on the
    edge-pinned virgin ramp (edges.py), ``edge_fixed`` the same with p = 2; one more line says which virgin curve
    and sum(k) to trust (:func:`trust_line`).
    """
    if encoder_step(fit.model.axis, counts_per_rev):
        step, source = encoder_step(fit.model.axis, counts_per_rev), f"{counts_per_rev:.0f} counts/rev"
    else:
        step = position_resolution(x) if step is None else step
        source = "measured from the displacement"
    noise = position_resolution(force)  # the larger of the force quantum and its white-noise level
    q = quantities(fit.model, fraction)
    u = AXIS_UNITS[fit.model.axis]
    unit, funit, kunit = u["position"], u["torque"], u["stiffness"]
    lines, ok = [], {}
    xp = q["presliding_distance"]
    ok["presliding_distance"] = xp >= MIN_COUNTS * step
    lines.append(f"presliding distance x_p({fraction:g}) = {xp:.4g} {unit}: "
                 + ("resolved" if ok["presliding_distance"] else "NOT resolved")
                 + f" ({xp / step:.3g} position steps of {step:.3g} {unit}; needs >= {MIN_COUNTS:g})")
    first = float(fit.model.ms_delta[0])
    k0 = q["initial_stiffness"]
    short = first < MIN_COUNTS * step
    ok["initial_stiffness"] = not short and k0 * step >= 3 * noise
    why = (f"the fitted virgin curve is straight only up to its first breakpoint {first:.3g} {unit} = "
           f"{first / step:.2g} position steps, fewer than {MIN_COUNTS:g}: the slope at 0 is not seen, K_0 is a "
           "lower bound" if short else
           f"straight over {first / step:.3g} steps; one step moves the force by {k0 * step:.3g} {funit} against "
           f"noise {noise:.3g} {funit}")
    lines.append(f"initial stiffness sum(k) = {k0:.4g} {kunit}: "
                 + ("resolved" if ok["initial_stiffness"] else "NOT resolved") + f" ({why})")
    travel = float(np.max(loop_travels)) if loop_travels.size else 0.0
    fb = q["breakaway"]
    need = 2 * xp + MIN_COUNTS * step  # a branch rises over 2*x_p (Masing), then slides over MIN_COUNTS steps
    # elements on the grid's top still stick at the end of the largest travel: the curve is still rising there
    top_share = float(np.sum(fit.model.ms_slip[fit.model.ms_delta >= fit.grid[-3] * (1 - 1e-9)])) / fb
    ok["breakaway"] = travel >= need and fb >= 10 * noise and top_share <= TOP_SHARE
    lines.append(f"break-away force F_b = {fb:.4g} {funit}: " + ("resolved" if ok["breakaway"] else "NOT resolved")
                 + f" (largest travel {travel:.3g} {unit}, needs 2*x_p + {MIN_COUNTS:g} steps = {need:.3g} {unit}; "
                   f"{100 * top_share:.2g} % of F_b still rising at half the largest travel, allowed "
                   f"{100 * TOP_SHARE:g} %; noise {noise:.3g} {funit})")
    if not ok["breakaway"]:
        lines[0] += "; measured against the level the record reaches, not a resolved F_b"
    small = int(np.sum(loop_travels < MIN_COUNTS * step))
    ok["reversal_forces"] = small == 0
    lines.append(f"reversal forces and memory checks: {loop_travels.size - small} of {loop_travels.size} branches "
                 f"resolved" + (f"; {small} travel less than {MIN_COUNTS:g} steps ({MIN_COUNTS * step:.3g} {unit})"
                                if small else ""))
    line, ok["parametric"] = trust_line(rolling, ok["initial_stiffness"], step, noise, fraction, unit, kunit,
                                        edge_rolling)
    lines.append(line)
    return Resolution(step, source, noise, lines, {k: bool(v) for k, v in ok.items()})


def trust_line(rolling: RollingFit | None, nnls_k0_resolved: bool, step: float, noise: float, fraction: float,
               unit: str, kunit: str, edge_rolling: RollingFit | None = None,
               edge_fixed: RollingFit | None = None) -> tuple[str, bool]:
    """(sentence, parametric usable): which estimate of the virgin curve and sum(k) to trust. The parametric one
    is usable when its virgin ramp spans >= MIN_COUNTS steps (step: rad or m), sum(k) is within PARAMETRIC_REL of
    itself (Jacobian uncertainty) and the shape fits: rms residual within PARAMETRIC_FIT of h, or within
    PARAMETRIC_EXCESS times what the quantisation and the force noise (N*m or N) alone leave. ``edge_rolling``
    (positions exact at count edges, so no quantisation error) is preferred when its sum(k) is within
    PARAMETRIC_REL of itself and its rms residual within PARAMETRIC_FIT of h: with its exponent free first, then
    ``edge_fixed`` (p = 2) when the free exponent leaves sum(k) too uncertain."""
    for edge in (edge_rolling, edge_fixed):
        if edge is None or nnls_k0_resolved:
            continue
        eq, ee = edge.quantities(fraction), edge.uncertainties(fraction)
        ek0, eu = eq["initial_stiffness"], ee["initial_stiffness"]
        share = edge.rms_error / edge.h
        if eu <= PARAMETRIC_REL * ek0 and share <= PARAMETRIC_FIT:
            where = "virgin ramp and first branch" if edge.origin is not None else "virgin ramp"
            return (f"virgin curve and sum(k): trust the parametric estimate on the edge-pinned {where} "
                    f"({edge.samples} points at count edges, positions exact; it assumes the shape {edge.shape}, "
                    f"extrapolated below the first edge; {edge.origin_text(step, unit)}); the NNLS sum(k) is a lower "
                    f"bound below one position step (sum(k) = p*h/d = {ek0:.4g} +- {eu:.2g} {kunit}, "
                    f"{edge.exponent_text(fraction)}, d = {edge.d:.3g} {unit}; rms residual {100 * share:.2g} % "
                    f"of h)"), True
    if rolling is None:
        return ("virgin curve and sum(k): no parametric fit; the NNLS estimate is the only one"
                + ("" if nnls_k0_resolved else " and its sum(k) is a lower bound")), False
    q, e = rolling.quantities(fraction), rolling.uncertainties(fraction)
    k0, u = q["initial_stiffness"], e["initial_stiffness"]
    fit_share = rolling.rms_error / rolling.h
    span = rolling.travel / step
    expected = rolling.expected_error(step, noise)
    fits = fit_share <= PARAMETRIC_FIT or rolling.rms_error <= PARAMETRIC_EXCESS * expected
    usable = span >= MIN_COUNTS and u <= PARAMETRIC_REL * k0 and fits
    facts = (f"parametric sum(k) = 2h/d = {k0:.4g} +- {u:.2g} {kunit}, d = {rolling.d:.3g} {unit}; the virgin ramp "
             f"spans {span:.3g} position steps; rms residual {100 * fit_share:.2g} % of h, "
             f"{rolling.rms_error / expected:.2g}x what quantisation and noise alone leave")
    if nnls_k0_resolved:
        verdict = "trust the NNLS (model-free, resolved); the parametric one assumes the rolling-friction shape"
    elif usable:
        verdict = ("trust the parametric estimate (it assumes the rolling-friction shape h(1-(d/(d+x))^2)); the "
                   "NNLS sum(k) is a lower bound below one position step")
    else:
        verdict = "NEITHER resolves sum(k): the NNLS value is a lower bound and the parametric one is not determined"
    return f"virgin curve and sum(k): {verdict} ({facts})", usable

