"""One presliding analysis of a displacement-driven record: reversal points and their table, the memory-rule checks,
the force model, derived quantities with uncertainties, the resolution verdicts and the figures.
The caller writes the outputs (plain data and matplotlib figures here; analysis writes no files)."""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field, replace

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.regressors import position_resolution
from hilbench.analysis.presliding.edges import EdgePoints, edge_points
from hilbench.analysis.presliding.identify import PreslidingFit, PreslidingSettings, fit_presliding
from hilbench.analysis.presliding.parametric import RollingFit, fit_rolling, origin_uncertainty
from hilbench.analysis.presliding.quantities import (
    DEFAULT_FRACTION,
    Resolution,
    bootstrap,
    encoder_step,
    quantities,
    resolution,
)
from hilbench.analysis.presliding.reversals import MemoryCheck, extreme_forces, find_reversals, memory_check
from hilbench.analysis.presliding.span import plan_span, x_means
from hilbench.common.units import AXIS_UNITS as AXES

#: the reversal hysteresis, in position steps, when none is given
HYSTERESIS_STEPS = 1.5
#: count edges the virgin ramp must cross before the edge-pinned fit is made
MIN_EDGE_RAMP = 5
#: records longer than this are averaged in blocks first (samples); a long record of many repeats of the path is
#: cut to the first repeats instead (span.py)
MAX_SAMPLES = 10_000
TABLE_COLUMNS = ("n", "sample", "t_s", "x", "kind", "depth", "travel", "force_measured", "force_extreme",
                 "force_rules", "force_model")
#: the moving average (s) over which a branch's extreme force is read (reversals.extreme_forces)
EXTREME_WINDOW_S = 0.01
#: an excursion past a count edge shorter than this (s) is dither, not a turning point (edges.edge_points)
MIN_EXCURSION_S = 0.01


@dataclass
class PreslidingResult:
    """Everything :func:`analyse` finds (units: the axis's, see ``units``)."""

    t: np.ndarray
    x: np.ndarray
    force: np.ndarray
    axis: str
    fit: PreslidingFit
    reversals: np.ndarray
    travels: np.ndarray  # travel into each reversal (m or rad)
    check: MemoryCheck
    quantities: dict[str, float]
    uncertainties: dict[str, float]
    resolution: Resolution
    fraction: float
    block: int = 1  # samples averaged into one (block_means)
    parametric: RollingFit | None = None  # the rolling-friction shape fitted beside the NNLS (parametric.py)
    parametric_error: str = ""  # why there is no parametric fit
    edges: EdgePoints | None = None  # dwells at count edges of a quantised record (edges.py)
    edge_fit: PreslidingFit | None = None  # the force model fitted on the edge-pinned path
    edge_error: str = ""  # why there is no edge-pinned fit
    extremes: np.ndarray | None = None  # each turning point's extreme force (reversals.extreme_forces)
    edge_rolling: RollingFit | None = None  # the shape with a free exponent fitted to the edge-pinned virgin ramp
    edge_rolling_fixed: RollingFit | None = None  # the same with the rolling-friction exponent 2 (the baseline)
    warnings: list[str] = field(default_factory=list)  # what the input cannot support (one line each)

    @property
    def units(self) -> dict[str, str]:
        return AXES[self.axis]

    def table(self) -> list[dict]:
        """The reversal-point table: one row per turning point (columns :data:`TABLE_COLUMNS`)."""
        rows = []
        for n, (i, travel) in enumerate(zip(self.reversals, self.travels, strict=True)):
            rows.append({"n": n + 1, "sample": int(i), "t_s": float(self.t[i]), "x": float(self.x[i]),
                         "kind": "max" if self.x[i] > self.x[self.reversals[n - 1] if n else 0] else "min",
                         "depth": int(self.check.depth[n]), "travel": float(travel),
                         "force_measured": float(self.force[i]),
                         "force_extreme": float(self.extremes[n]) if self.extremes is not None else float("nan"),
                         "force_rules": float(self.check.reversal_rules[n]),
                         "force_model": float(self.fit.simulated[i])})
        return rows

    def checks(self) -> dict[str, float | int]:
        """Departures (fractions of the largest virgin force) of the memory rules and of the model."""
        m_max, m_rms, m_n = self.check.departure(self.force, 1)
        w_max, w_rms, w_n = self.check.departure(self.force, 2)
        rows = self.table()[1:]
        scale = self.check.scale
        rules = [abs(r["force_rules"] - r["force_measured"]) / scale for r in rows if np.isfinite(r["force_rules"])]
        model = [abs(r["force_model"] - r["force_measured"]) / scale for r in rows]
        return {"masing_max": m_max, "masing_rms": m_rms, "masing_samples": m_n,
                "wiping_out_max": w_max, "wiping_out_rms": w_rms, "wiping_out_samples": w_n,
                "closure_max": self.check.closure_departure, "closed_loops": len(self.check.closures),
                "reversal_rules_max": max(rules, default=float("nan")),
                "reversal_model_max": max(model, default=float("nan")),
                "force_noise_relative": self.resolution.force_noise / scale, "scale": scale}


def analyse(t: np.ndarray, x: np.ndarray, force: np.ndarray, fs: float, axis: str = "rotary",
            settings: PreslidingSettings | None = None, counts_per_rev: float | None = None,
            hysteresis: float | None = None, fraction: float = DEFAULT_FRACTION, replicates: int = 20,
            seed: int = 0, max_samples: int = MAX_SAMPLES) -> PreslidingResult:
    """Run the whole presliding analysis on arrays t (s), x (m or rad), force (N or N*m), each shape (n,).

    ``hysteresis`` (m or rad): the smallest travel counted as a reversal, default HYSTERESIS_STEPS position
    steps. ``replicates``: bootstrap replicates for the uncertainties. A record longer than ``max_samples`` is
    first averaged in blocks (:func:`block_means`); when those blocks would be too long for the path, only the
    first whole repeats of it are analysed, and a warning says so (:mod:`~.span`). AnalysisError for unusable input
    (e.g. no reversal)."""
    x = np.asarray(x, float)
    options = {"counts_per_rev": counts_per_rev, "hysteresis": hysteresis, "fraction": fraction,
               "replicates": replicates, "seed": seed, "max_samples": max_samples}
    # of the samples as recorded, before any averaging; the calibration's encoder step when known (a resampled
    # host-clocked record's smallest increment is a spline's, far below one count)
    step = encoder_step(axis, counts_per_rev) or position_resolution(x)
    span = plan_span(x.size, max_samples, HYSTERESIS_STEPS * step if hysteresis is None else hysteresis,
                     lambda m, head: x_means(x, m, head), lambda a, b: x[a:b])
    if span is None:
        return _analyse_record(t, x, force, fs, axis, settings, step, **options)
    k = span.samples
    res = _analyse_record(t[:k], x[:k], force[:k], fs, axis, settings,
                          encoder_step(axis, counts_per_rev) or position_resolution(x[:k]), **options)
    res.warnings.append(span.warning(x.size, fs, max_samples))
    return res


def _analyse_record(t: np.ndarray, x: np.ndarray, force: np.ndarray, fs: float, axis: str,
                    settings: PreslidingSettings | None, step: float, *, max_samples: int, **options
                    ) -> PreslidingResult:
    """:func:`analyse` on all of the arrays given, averaged in blocks of ceil(n/max_samples)."""
    raw = np.asarray(force, float)
    edge = _edge_fit(x, raw, step, axis, settings, max(1, math.ceil(MIN_EXCURSION_S * fs)))
    window = max(1, round(EXTREME_WINDOW_S * fs))
    t, x, force, block = block_means(t, x, force, max_samples)
    return analyse_blocks(t, x, force, fs / block, block, step, axis, settings, edge,
                          lambda rev: extreme_forces(raw, rev * block + block // 2, window), **options)


def analyse_blocks(t: np.ndarray, x: np.ndarray, force: np.ndarray, fs: float, block: int, step: float, axis: str,
                   settings: PreslidingSettings | None, edge: tuple, extremes_of, *,
                   counts_per_rev: float | None = None, hysteresis: float | None = None,
                   fraction: float = DEFAULT_FRACTION, replicates: int = 20, seed: int = 0) -> PreslidingResult:
    """:func:`analyse` from the block-averaged record (t, x, force at ``fs`` = the raw rate / ``block``) and what
    it read from the raw samples: the position ``step``, ``edge`` (:func:`_edge_fit`'s tuple) and
    ``extremes_of(reversals)``, each turning point's extreme force (:func:`extreme_forces` on the raw force).
    Whole arrays (:func:`analyse`) and a record read chunk by chunk (:mod:`~.streamed`) meet here."""
    edges, edge_fit, edge_why, edge_rolling, edge_fixed = edge
    if hysteresis is None:
        hysteresis = HYSTERESIS_STEPS * step
    rev = find_reversals(x, hysteresis)
    if rev.size == 0:
        raise AnalysisError(f"no reversal in the displacement (hysteresis {hysteresis:.3g}): a presliding record "
                            "needs a virgin ramp and at least one reversal")
    fit = fit_presliding(x, force, fs, axis, settings, step=step)
    check = memory_check(x, force, rev)
    ends = np.concatenate([[0], rev, [x.size - 1]])
    travels = np.abs(np.diff(x[ends]))
    unc = bootstrap(fit, x, force, fs, rev, replicates=replicates, fraction=fraction, seed=seed)
    try:
        rolling, why = fit_rolling(x, force, fs, rev), ""
        if edges is not None:  # a quantised record: the contact rested somewhere in its first step
            rolling = _assumed_origin(rolling, x, fs, int(rev[0]), step)
    except AnalysisError as exc:
        rolling, why = None, str(exc)
    res = resolution(fit, x, force, travels, counts_per_rev, fraction, step=step, rolling=rolling,
                     edge_rolling=edge_rolling, edge_fixed=edge_fixed)
    extremes = extremes_of(rev)
    return PreslidingResult(t, x, force, axis, fit, rev, travels[:-1], check,
                            quantities(fit.model, fraction), unc, res, fraction, block, rolling, why,
                            edges, edge_fit, edge_why, extremes, edge_rolling, edge_fixed)


def _assumed_origin(fit: RollingFit, x: np.ndarray, fs: float, r0: int, step: float) -> RollingFit:
    """The sample-based fit of a quantised record takes the contact at rest at x[0], where the encoder only says
    which step it is in: ``fit`` with that assumption's type-B uncertainty (parametric.origin_uncertainty, on
    the virgin ramp x[:r0 + 1]). Without it, a 2^14-count record's sum(k) came out 42 % low at +- 0.9 %."""
    ramp = np.asarray(x[: r0 + 1], float)

    def refit(force: np.ndarray) -> RollingFit:
        return fit_rolling(ramp, force, fs, np.array([r0]), viscous=False)

    return origin_uncertainty(fit, ramp, refit, step)


def is_quantised(x: np.ndarray, step: float) -> bool:
    """True when x holds still for most samples and moves in whole steps: an encoder record, not a
    continuous (noisy) one."""
    dx = np.diff(x)
    moves = dx[dx != 0]
    if step <= 0 or moves.size == 0 or moves.size > 0.5 * dx.size:
        return False
    return bool(np.all(np.abs(moves / step - np.round(moves / step)) < 1e-3))


def _edge_fit(x: np.ndarray, force: np.ndarray, step: float, axis: str, settings: PreslidingSettings | None,
              min_excursion: int) -> tuple[EdgePoints | None, PreslidingFit | None, str, RollingFit | None,
                                           RollingFit | None]:
    """(edges, model, why not, free-exponent shape, exponent-2 shape): the force model on the edge-pinned path of a
    quantised record, or why there is none, and the parametric virgin curve fitted to the edge-pinned virgin ramp
    alone, with its exponent free and held at 2 (None where a fit fails). The dwell means carry no mean velocity or
    acceleration, so neither has a viscous or inertia term.

    Why a free exponent there: the ramp's first edge lies a whole step from rest, so sum(k) is the shape's
    extrapolated slope at 0, and a shape held at p = 2 carries its own bias into it (docs/presliding.md,
    "Initial stiffness below one count")."""
    if not is_quantised(x, step):
        return None, None, "the displacement is not quantised in whole steps", None, None
    edges = edge_points(x, force, step, min_excursion=min_excursion)
    rev = find_reversals(edges.x, HYSTERESIS_STEPS * step)
    ramp = slice(0, int(rev[0]) + 1 if rev.size else edges.size)
    ramp_edges = np.unique(edges.x[ramp][edges.crossings[ramp] > 0]).size  # edges crossed, not excursions
    if rev.size == 0 or ramp_edges < MIN_EDGE_RAMP:
        return (edges, None, f"the virgin ramp crosses {ramp_edges} count edges, fewer than {MIN_EDGE_RAMP}",
                None, None)
    s = replace(settings or PreslidingSettings(), viscous=False, inertia=0.0)
    shapes = [_edge_shape(edges, rev, step, exponent) for exponent in (None, 2.0)]
    try:
        return (edges, fit_presliding(edges.x, edges.force, 1.0, axis, s, step=step), "", *shapes)
    except AnalysisError as exc:  # e.g. a short record: too few edge points for the NNLS; the shape may still fit
        return edges, None, f"the NNLS on the edge points: {exc}", *shapes


def _edge_shape(edges: EdgePoints, rev: np.ndarray, step: float, exponent: float | None) -> RollingFit | None:
    """The parametric virgin curve on the edge-pinned points (None when the fit fails).

    The relaxed position x0 is known only to within the step the contact rests in. The ramp and the first Masing
    branch are fitted together with x0 free within that step: the ramp sees phi from x0 and the branch from the
    turning point x_r, and only the right x0 lets both agree. x_r is exact when the turn is a dwell at a count edge
    (the loop held the contact there); when it is an excursion into the next count, x_r is fitted within that count
    too. With no branch, the ramp is fitted alone, x0 at the count, and x0's own uncertainty (step/sqrt(12)) is
    carried into the quantities (parametric.origin_uncertainty). Only the monotone path is fitted
    (:func:`_envelope`): Masing's rule gives no closed form for a point on a minor loop."""
    r0 = int(rev[0])
    x, crossings = edges.x, edges.crossings
    ramp = [0, *_envelope(x, crossings, 1, r0, np.sign(x[r0] - x[0])), r0]
    end = int(rev[1]) if rev.size > 1 else x.size - 1  # the first branch runs to the next turn or the record's end
    branch = _envelope(x, crossings, r0 + 1, end + 1, np.sign(x[0] - x[r0]))
    try:
        if branch:
            idx = np.array(ramp + branch)
            xs = x[idx].copy()
            turn = len(ramp) - 1
            pinned = crossings[r0] > 0
            if not pinned:  # the count the contact turned in, after the last edge it crossed
                xs[turn] = xs[turn - 1] + 0.5 * step * np.sign(xs[turn] - xs[turn - 1])
            return fit_rolling(xs, edges.force[idx], 1.0, np.array([turn, idx.size - 1]), viscous=False,
                               exponent=exponent, origin_range=step, turn_range=0.0 if pinned else step)
        idx = np.array(ramp)

        def refit(force: np.ndarray) -> RollingFit:
            return fit_rolling(x[idx], force, 1.0, np.array([idx.size - 1]), viscous=False, exponent=exponent)
        return origin_uncertainty(refit(edges.force[idx]), x[idx], refit, step)
    except AnalysisError:
        return None


def _envelope(x: np.ndarray, crossings: np.ndarray, start: int, stop: int, sign: float) -> list[int]:
    """Indices in [start, stop) of the dwells (crossings > 0: positions exact) that go past every point before them
    in the direction ``sign``, from x[start - 1]: the monotone path. A dwell back inside the travel already made lies
    on a minor loop (dither past an edge and back), and an excursion point's position is an estimate."""
    keep, reach = [], x[start - 1]
    for i in range(start, stop):
        if crossings[i] > 0 and sign * (x[i] - reach) > 0:
            keep.append(i)
        if sign * (x[i] - reach) > 0:
            reach = x[i]
    return keep


def block_means(t: np.ndarray, x: np.ndarray, force: np.ndarray, max_samples: int = MAX_SAMPLES):
    """(t, x, force, m): each array averaged over consecutive blocks of m = ceil(n/max_samples) samples (the tail
    that does not fill a block is dropped); m = 1 returns the arrays as they are. A quasi-static record loses
    nothing by it, and the mean of an encoder position that the position loop dithers between counts resolves
    below one count (the force noise falls by sqrt(m) too)."""
    t, x, force = (np.asarray(a, float) for a in (t, x, force))
    if max_samples < 100:
        raise AnalysisError(f"max_samples must be >= 100, got {max_samples}")
    m = -(-x.size // max_samples)
    if m <= 1:
        return t, x, force, 1
    n = (x.size // m) * m
    return (*(a[:n].reshape(-1, m).mean(axis=1) for a in (t, x, force)), m)


def table_csv(result: PreslidingResult) -> str:
    """The reversal-point table as CSV, units in the header."""
    buf = io.StringIO()
    buf.write(",".join(_headers(result)) + "\n")
    for r in result.table():
        buf.write(",".join(_fmt(r[c]) for c in TABLE_COLUMNS) + "\n")
    return buf.getvalue()


def table_markdown(result: PreslidingResult) -> str:
    """The reversal-point table as a markdown table, units in the header."""
    head = _headers(result)
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(_fmt(r[c]) for c in TABLE_COLUMNS) + " |" for r in result.table()]
    return "\n".join(lines) + "\n"


def _headers(result: PreslidingResult) -> list[str]:
    u = result.units
    unit = {"t_s": "s", "x": u["position"], "travel": u["position"], "force_measured": u["torque"],
            "force_extreme": u["torque"], "force_rules": u["torque"], "force_model": u["torque"]}
    return [f"{c} ({unit[c]})" if c in unit and c != "t_s" else c for c in TABLE_COLUMNS]


def _fmt(v) -> str:
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def figures(result: PreslidingResult) -> dict:
    """matplotlib figures: ``loops`` (force against displacement: virgin curve, nested loops, model) and
    ``virgin`` (measured virgin ramp against the model's virgin curve, with x_p)."""
    from matplotlib.figure import Figure

    from hilbench.analysis.figure_style import scaled_axis

    u = result.units
    r0 = int(result.reversals[0])
    fig = Figure(figsize=(7.5, 6.2), layout="constrained")
    ax = fig.add_subplot()
    ax.plot(result.x[r0:], result.force[r0:], lw=0.6, color="0.55", label="measured: nested loops")
    ax.plot(result.x[: r0 + 1], result.force[: r0 + 1], lw=1.6, color="tab:blue", label="measured: virgin ramp")
    ax.plot(result.x, result.fit.simulated, lw=0.7, ls="--", color="tab:red",
            label="model: force simulated from the measured displacement")
    ax.plot(result.x[result.reversals], result.force[result.reversals], "k.", ms=5, label="reversal points")
    xu = scaled_axis(ax.xaxis, u["position"], result.x)
    fu = scaled_axis(ax.yaxis, u["torque"], result.force)
    ax.set(xlabel=f"displacement x ({xu})", ylabel=f"force F ({fu})", title="presliding force against displacement")
    fig.legend(*ax.get_legend_handles_labels(), fontsize=9, loc="outside lower center", ncol=2, frameon=False)
    ax.grid(alpha=0.3)
    loops = fig
    fig = Figure(figsize=(12, 6.4), layout="constrained")
    ax, zoom = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.6, 1]})
    sgn = 1.0 if result.x[r0] > result.x[0] else -1.0
    s = sgn * (result.x[: r0 + 1] - result.x[0])
    ax.plot(s, sgn * (result.force[: r0 + 1] - result.force[0]), ".", ms=2, color="tab:blue",
            label="measured virgin ramp")
    grid = np.linspace(0, float(s.max()), 400)
    ax.plot(grid, result.fit.model.virgin_curve(grid) + result.fit.model.coulomb * (grid > 0), color="tab:red",
            label="identified virgin curve (NNLS)")
    if result.edge_fit is not None:
        e, ramp = result.edges, _edge_ramp(result)
        ax.plot(sgn * (e.x[ramp] - e.x[0]), sgn * (e.force[ramp] - e.force[0]), "o", ms=3, mfc="none",
                color="tab:purple", label="dwells at count edges (position exact)")
        ax.plot(grid, result.edge_fit.model.virgin_curve(grid), color="tab:purple",
                label="identified virgin curve (edge-pinned NNLS)")
    if result.edge_rolling is not None:
        ax.plot(grid, _shape_curve(result.edge_rolling, grid, sgn), color="tab:orange", ls="-.",
                label=f"parametric virgin curve on the edge points ({result.edge_rolling.exponent_text()})")
    if result.parametric is not None:
        ax.plot(grid, result.parametric.virgin_curve(grid), color="tab:green", ls="--",
                label="parametric virgin curve h(1-(d/(d+x))^2) on the samples")
    xp = result.quantities["presliding_distance"]
    ax.axvline(xp, color="k", ls=":", label=f"x_p({result.fraction:g}) = {xp:.3g} {u['position']}")
    xu = scaled_axis(ax.xaxis, u["position"], s)
    fu = scaled_axis(ax.yaxis, u["torque"], result.force - result.force[0])
    ax.set(xlabel=f"travel from the relaxed state ({xu})", ylabel=f"force change ({fu})", title="virgin curve")
    ax.grid(alpha=0.3)
    _initial_slopes(zoom, result, s, sgn)
    zoom.set_xlabel(f"travel ({scaled_axis(zoom.xaxis, u['position'], [zoom.get_xlim()[1]])}; grey: count edges)")
    zoom.set_ylabel(f"force change ({scaled_axis(zoom.yaxis, u['torque'], result.force - result.force[0])})")
    # one legend for both panels, below them, at a readable size
    handles, labels = ax.get_legend_handles_labels()
    for h, label in zip(*zoom.get_legend_handles_labels(), strict=True):
        if label not in labels:
            handles.append(h)
            labels.append(label)
    fig.legend(handles, labels, fontsize=8.5, loc="outside lower center", ncol=2, frameon=False)
    return {"loops": loops, "virgin": fig}


def _edge_ramp(result: PreslidingResult) -> slice:
    """The edge points of the virgin ramp: up to the first reversal, found as _edge_fit finds it."""
    r = find_reversals(result.edges.x, HYSTERESIS_STEPS * result.resolution.step)
    return slice(0, int(r[0]) + 1) if r.size else slice(None)


def _shape_curve(fit: RollingFit, s: np.ndarray, sgn: float) -> np.ndarray:
    """The fitted parametric curve over travel s from the rest count (its relaxed position where it was fitted)."""
    return fit.virgin_curve(np.clip(s - sgn * (fit.origin or 0.0), 0, None))


def _initial_slopes(ax, result: PreslidingResult, s: np.ndarray, sgn: float) -> None:
    """The first few position steps of the virgin ramp, where sum(k) lives: the samples, the edge dwells, and the
    tangent sum(k)*x at 0 of each estimate."""
    u = result.units
    step = result.resolution.step
    span = min(float(s.max()), 4 * step)
    near = s <= span
    ax.plot(s[near], sgn * (result.force[: s.size][near] - result.force[0]), ".", ms=2, color="tab:blue",
            label="measured virgin ramp")
    grid = np.linspace(0, span, 200)
    slopes = [("NNLS (samples)", result.quantities["initial_stiffness"], "tab:red", None, 0.0)]
    if result.edge_fit is not None:
        e, ramp = result.edges, _edge_ramp(result)
        es, ef = sgn * (e.x[ramp] - e.x[0]), sgn * (e.force[ramp] - e.force[0])
        ax.plot(es[es <= span], ef[es <= span], "o", ms=5, mfc="none", color="tab:purple",
                label="dwells at count edges")
        slopes.append(("edge-pinned NNLS", float(np.sum(result.edge_fit.model.ms_stiffness)), "tab:purple", None,
                       0.0))
    for name, fit, color in (("edge points, p free", result.edge_rolling, "tab:orange"),
                             ("edge points, p = 2", result.edge_rolling_fixed, "tab:brown")):
        if fit is not None:
            ax.plot(grid, _shape_curve(fit, grid, sgn), color=color, lw=1, label=f"parametric, {name}")
            slopes.append((f"parametric, {name}", fit.quantities(result.fraction)["initial_stiffness"], color, ":",
                           sgn * (fit.origin or 0.0)))
    top = float(np.max(np.abs(ax.get_ylim())))
    for name, k0, color, ls, x0 in slopes:
        ax.plot(grid, k0 * np.clip(grid - x0, 0, None), color=color, ls=ls or "--", lw=0.8,
                label=f"slope at 0, {name}: {k0:.4g} {u['stiffness']}")
    for n in range(1, int(span / step) + 2):  # edges lie half a step either side of a count
        ax.axvline((n - 0.5) * step, color="0.8", lw=0.6)
    ax.set(xlim=(0, span), ylim=(0, 1.05 * top), xlabel=f"travel ({u['position']}; grey: count edges)",
           ylabel=f"force change ({u['torque']})", title="the first position steps: sum(k) is the slope at 0")
    ax.grid(alpha=0.3)
