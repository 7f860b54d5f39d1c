"""Analyses the run browser offers: every entry of the analysis registry (hilbench.analysis.protocol.ANALYSES)
that analyses one run, run file in, numbers and curves out.

:func:`run_analysis` reads the run through the entry's ``read`` (the GUI's memory budget: the CLI's ``--memory
auto``), analyses it through its ``analyse`` with the settings the browser's options give (:func:`settings_for`),
and lays the result out as an :class:`AnalysisResult` (a table of numbers with units and a few figures of curves):
by the presentation of :data:`ANALYSES` where the GUI has one, else the entry's report summary as a table. So the
GUI reads, refuses and computes as the CLI and the campaign steps do; the browser runs it off the GUI thread.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hilbench.bench.errors import BenchError


class AnalysisUnavailable(BenchError):
    """The analysis package does not (yet) provide the entry point an analysis needs."""


@dataclass
class Figure:
    """One plot: title, axis labels with units, and named curves ``(name, x, y)``."""

    title: str
    xlabel: str
    ylabel: str
    curves: list[tuple[str, np.ndarray, np.ndarray]] = field(default_factory=list)
    scatter: bool = False


@dataclass
class AnalysisResult:
    title: str
    numbers: list[tuple[str, str, str]]  # (quantity, value, unit)
    figures: list[Figure]
    warnings: list[str] = field(default_factory=list)
    #: an identification's model file document (``hilbench identify``'s JSON), for "Save model..."
    model_document: dict | None = None
    #: the registry entry's report summary (figures unrounded: fractions, SI), as campaign rows hold them
    summary: dict = field(default_factory=dict)


def _gui_names() -> list[str]:
    """The registry's analyses of one run (an analysis that needs a validation run is the CLI's)."""
    from hilbench.analysis.protocol import entries

    return [n for n, e in entries().items() if not e.needs_validation]




def availability(name: str) -> str:
    """"" when analysis ``name`` can run, else why not (one line)."""
    from hilbench.analysis.protocol import ANALYSES

    if name not in ANALYSES:
        return f"not available: no analysis {name!r} in this installation"
    module, attr = ANALYSES[name]
    try:
        mod = importlib.import_module(module)
    except ImportError:
        return f"not available: {module} is not part of this installation yet"
    if not hasattr(mod, attr):
        return f"not available: {module}.{attr} does not exist yet"
    return ""


def settings_for(name: str, options: dict) -> object:
    """The analysis settings the browser's ``options`` give (None: the entry's defaults): the skeleton's mass
    (``inertia``, empty: the run's declared inertia, as ``hilbench skeleton`` without --mass) and method, the
    residual loop's start model file, the presliding bootstrap's replicates (default 8)."""
    if name == "skeleton":
        from hilbench.analysis.skeleton import SkeletonSettings

        inertia = options.get("inertia")
        return SkeletonSettings(mass=float(inertia) if inertia else None, method=options.get("method", "cwt"))
    if name == "residual" and options.get("start_model"):
        from hilbench.analysis.models.model_file import read_model
        from hilbench.analysis.residual import ResidualSettings

        model, document = read_model(options["start_model"])
        return ResidualSettings(start=(), start_model=model, start_model_document=document)
    if name == "presliding":
        from hilbench.analysis.presliding.entry import PreslidingAnalysis

        return PreslidingAnalysis(replicates=int(options.get("replicates", 8)))
    return None


def run_analysis(name: str, path: str | Path, options: dict | None = None) -> AnalysisResult:
    """Analysis ``name`` of the run file ``path`` through its registry entry (module docstring); the incomplete
    record's line first among the warnings."""
    from hilbench.analysis.protocol import ReadOptions, entry
    from hilbench.bench.analysis_input import memory_budget

    why = availability(name)
    if why:
        raise AnalysisUnavailable(f"{name}: {why}")
    options = options or {}
    analysis = entry(name)
    inputs = analysis.read([path], ReadOptions(memory=memory_budget("auto"),
                                               allow_incomplete=bool(options.get("allow_incomplete", False))))
    result = analysis.analyse(inputs, settings_for(name, options))
    shown = ANALYSES.get(name, summary_table)(result, options)
    shown.summary = analysis.report(result)[1]
    line = inputs.record.incomplete_line()
    if line and line not in shown.warnings:
        shown.warnings.insert(0, line)
    return shown


def summary_table(result, options: dict | None = None) -> AnalysisResult:
    """Any registered analysis: its report summary's figures as the table, no figures."""
    from hilbench.analysis.protocol import entry
    from hilbench.common.metrics import UNIT, is_fraction, percent

    analysis = entry(result.name)
    summary = analysis.report(result)[1]
    numbers = [(k, f"{percent(v):.4g}", UNIT) if isinstance(v, float) and is_fraction(k) else
               (k, f"{v:.6g}" if isinstance(v, float) else str(v), analysis.columns.get(k, ("", ""))[1])
               for k, v in summary.items() if isinstance(v, int | float | str) and not isinstance(v, bool)]
    return AnalysisResult(analysis.title, numbers, [])


def _thin(x: np.ndarray, *ys: np.ndarray, n: int = 20000) -> list[np.ndarray]:
    step = max(1, x.size // n)
    return [x[::step], *[y[::step] for y in ys]]


def identification(result, options: dict | None = None) -> AnalysisResult:
    """Maxwell-slip identification (the registry's ``identify``, as ``hilbench identify``), so both report the
    same numbers (docs/metrics.md)."""
    from hilbench.analysis.identification.entry import document
    from hilbench.common.metrics import percent

    run, res = result.inputs.record, result.value
    position = run.position
    fit = res.lip
    m = res.model
    d = m.to_dict()
    u = d["units"]
    numbers = [
        ("inertia J", f"{m.inertia:.6g}", u["inertia"]),
        ("viscous coefficient b", f"{m.viscous:.6g}", u["viscous"]),
        ("Coulomb level Fc", f"{m.coulomb:.6g}", u["coulomb"]),
        ("offset c0", f"{m.offset:.6g}", u["offset"]),
        ("spring K", f"{m.spring:.6g}", u["spring"]),
        ("Maxwell-slip elements N", str(m.ms_stiffness.size), ""),
        ("break-away torque (sum W_i + Fc)", f"{m.breakaway:.6g}", u["coulomb"]),
        ("train torque NRMSE", f"{percent(res.figures['train_torque_nrmse']):.3g}", "%"),
        ("filter cut-off", f"{fit.cutoff:.4g}", "Hz"),
    ]
    for i, (k, delta) in enumerate(zip(m.ms_stiffness, m.ms_delta, strict=True)):
        numbers.append((f"element {i + 1}: k_i, Delta_i", f"{k:.4g}, {delta:.4g}",
                        f"{u['ms_stiffness']}, {u['ms_delta']}"))
    t_rows = fit.rows / run.sample_rate
    span = float(np.ptp(position)) / 2 if position is not None and position.size else 1.0
    x = np.linspace(-span, span, 401)
    figures = [
        Figure("filtered torque: measured and model", "t (s)", f"torque ({u['coulomb']})",
               [("measured", *_thin(t_rows, fit.measured)), ("model", *_thin(t_rows, fit.predicted))]),
        Figure("virgin curve", f"displacement ({u['ms_delta']})", f"friction ({u['coulomb']})",
               [("sum k_i clip(x, Delta_i)", x, m.virgin_curve(x))]),
    ]
    # the model file `hilbench identify RUN --json` writes: the same document and provenance builder
    return AnalysisResult(_title(result), numbers, figures, list(fit.warnings), model_document=document(result))


def _title(result) -> str:
    from hilbench.analysis.protocol import entry

    return entry(result.name).title


def save_model(document: dict, target: str, inputs: list[str]) -> str:
    """Write ``document`` (:func:`identification_document`) to ``target`` as ``hilbench identify --json`` does
    (indented, strict JSON, replaced atomically); refuses to write over one of ``inputs`` (the run file).
    Returns the path written."""
    from pathlib import Path

    from hilbench.bench.storage import outputs

    target = str(target).strip()
    if not target:
        raise BenchError("choose a model file name (.json)")
    if any(Path(target).resolve() == Path(i).resolve() for i in inputs if i):
        raise BenchError(f"{target} is the run file being analysed; choose another name for the model")
    outputs.write_json(target, document, indent=2, allow_nan=False)
    return target


def skeleton(result, options: dict | None = None) -> AnalysisResult:
    """The skeleton (the registry's ``skeleton``, as ``hilbench skeleton``); ``options['inertia']`` in kg*m^2
    (rotary) or kg (linear), empty: the run's declared inertia; ``options['method']`` (``cwt``, the default, or
    ``hilbert``). The result carries the analysis's warnings (a run that is no chirp, a narrow amplitude range, a
    stiffness that cannot be)."""
    run, res = result.inputs.record, result.value
    c = res.curves
    if c.amplitude.size == 0:
        raise BenchError("ForceVib found no valid samples in this run (is it a chirp or a sine run?)")
    pos_unit = run.unit("position")
    tq_unit = run.unit("torque")
    per_run = res.per_run[0] if res.per_run else {}
    numbers = [
        ("valid samples", str(per_run.get("valid_samples", "")), ""),
        ("amplitude range", f"{c.amplitude.min():.4g} .. {c.amplitude.max():.4g}", pos_unit),
        ("median k_eq", f"{np.median(c.stiffness):.6g}", f"{tq_unit}/{pos_unit}"),
        ("median c_eq", f"{np.median(c.damping):.6g}" if c.damping.size else "n/a", f"{tq_unit}*s/{pos_unit}"),
    ]
    figures = [
        Figure("restoring force skeleton", f"amplitude A ({pos_unit})", f"F_k ({tq_unit})",
               [("(k_eq - k_lin) A", c.amplitude, c.restoring_force)], scatter=True),
        Figure("damping force skeleton", f"velocity amplitude V ({pos_unit}/s)", f"F_d ({tq_unit})",
               [("c_eq V", c.velocity, c.damping_force)], scatter=True),
    ]
    return AnalysisResult(_title(result), numbers, figures, list(res.warnings))


def afrf(result, options: dict | None = None) -> AnalysisResult:
    """AFRF (the registry's ``afrf``, as ``hilbench afrf RUN``) of a stepped-sine run: |c_k| of the position per
    step."""
    run, res = result.inputs.record, result.value
    mags = res.magnitudes
    numbers = []
    for i, a in enumerate(res.amplitudes):
        for j, f in enumerate(res.frequencies):
            c1 = mags[i, j, 0]
            ratio = mags[i, j, 2] / c1 if res.n_harmonics >= 3 and c1 > 0 else float("nan")
            numbers.append((f"G {a:.4g} {res.amplitude_unit}, f {f:.4g} Hz: |c1|, |c3|/|c1|",
                            f"{c1:.4g}, {ratio:.3g}", f"{res.displacement_unit}, 1"))
    figures = []
    for k in range(res.n_harmonics):
        fig = Figure(f"AFRF, harmonic {k + 1}", "frequency (Hz)", f"|c{k + 1}| ({res.displacement_unit})")
        for i, a in enumerate(res.amplitudes):
            fig.curves.append((f"G = {a:.4g} {res.amplitude_unit}", res.frequencies, mags[i, :, k]))
        figures.append(fig)
    why = res.settings.get("incomplete")
    name = os.path.basename(run.path)
    warnings = [f"INCOMPLETE RECORD {name}: {why} (analysed with --allow-incomplete)"] if why else []
    return AnalysisResult(_title(result), numbers, figures, warnings + list(res.warnings))


def residual(result, options: dict | None = None) -> AnalysisResult:
    """Residual loop (the registry's ``residual``, as ``hilbench residual``), blocked cross-validation (no separate
    validation run). ``options['start_model']``: a model file (``hilbench identify`` or compare's maxwell_slip) to
    start from, unrefitted, as ``residual --start MODEL.json`` does; its own figure is shown as identify reports
    it."""
    from hilbench.common.metrics import percent

    run, analysed = result.inputs.record, result.value
    res = analysed.loop
    numbers = [("verdict", str(res.verdict), ""), ("validation", str(res.validation_mode), ""),
               ("start model", ", ".join(res.start), ""),
               ("effects added", ", ".join(res.names_added) or "none", "")]
    if (figure := analysed.start_figure()) is not None:  # the start model's own figure, as identify reports it
        where, value = figure
        numbers.append((f"start model ({analysed.start_model['source']}): {where} torque NRMSE",
                        f"{percent(value):.3g}", "%"))
    for label, errors in (("start model", res.error_before), ("final model", res.error_after)):
        v = errors.get("validation") or {}
        if v.get("torque_nrmse") is not None:
            numbers.append((f"{res.validation_mode} torque NRMSE, {label}", f"{percent(v['torque_nrmse']):.3g}", "%"))
    tq = run.unit("torque")
    sb, sa = res.signals_before, res.signals_after
    figures = [Figure("residual over time", "t (s)", f"residual ({tq})",
                      [("before", *_thin(sb.time, sb.residual)), ("after", *_thin(sa.time, sa.residual))]),
               Figure("residual against velocity", f"velocity ({run.unit('position')}/s)", f"residual ({tq})",
                      [("after", *_thin(sa.velocity, sa.residual))], scatter=True)]
    return AnalysisResult(_title(result), numbers, figures)


def presliding(result, options: dict | None = None) -> AnalysisResult:
    """The presliding analysis (the registry's ``presliding``, as ``hilbench presliding``, with its record checks:
    a displacement-driven run, a force channel) with the numbers the command writes: the quantities with their
    uncertainties, the edge-pinned sum(k), the memory checks, the reversal forces; the resolution verdicts as
    warnings. ``options['replicates']``: bootstrap replicates (default 8)."""
    from hilbench.analysis.presliding.entry import document

    res, doc = result.value, document(result)
    resolved = doc["resolution"]["resolved"]
    numbers = [(f"{name.replace('_', ' ')} (NNLS, model-free)" + ("" if resolved.get(name, True) else
                                                                 ", NOT resolved"),
                f"{q['value']:.5g} +- {q['std_uncertainty']:.2g}", q["unit"]) for name, q in doc["quantities"].items()]
    edge = doc["edge_pinned"]
    for key, label in (("parametric_ramp", "p free"), ("parametric_ramp_exponent_2", "p = 2, baseline")):
        pr = edge.get(key, {"error": ""})
        if "error" not in pr:
            k0 = pr["quantities"]["initial_stiffness"]
            numbers.append((f"initial stiffness sum(k) (edge points, {label})",
                            f"{k0['value']:.5g} +- {k0['std_uncertainty']:.2g}", k0["unit"]))
            numbers.append((f"shape exponent p (edge points, {label})",
                            f"{pr['exponent']:.4g} +- {pr['exponent_std_uncertainty']:.2g}", "1"))
    c, v = doc["checks"], doc["validation"]
    # the departures are fractions of the largest virgin force: said in the quantity, so the unit column stays narrow
    numbers += [("model force rms error (force from displacement)", f"{v['force_rms_error']:.4g}", v["unit"]),
                ("Masing rule departure, max (of the largest virgin force)", f"{c['masing_max']:.3g}", "1"),
                ("wiping-out departure, max (of the largest virgin force)", f"{c['wiping_out_max']:.3g}", "1"),
                ("loop closure departure, max (of the largest virgin force)", f"{c['closure_max']:.3g}", "1")]
    pos, tq = res.units["position"], res.units["torque"]
    for row in doc["reversals"]:
        numbers.append((f"reversal {row['n']}: x, extreme force", f"{row['x']:.5g}, {row['force_extreme']:.5g}",
                        f"{pos}, {tq}"))
    loops = Figure("force against displacement", f"displacement ({pos})", f"force ({tq})",
                   [("measured", *_thin(res.x, res.force)), ("model: force from the displacement",
                                                            *_thin(res.x, res.fit.simulated))])
    virgin = Figure("virgin curve", f"travel from rest ({pos})", f"force change ({tq})")
    grid = np.linspace(0.0, float(res.travels[0]) if res.travels.size else 0.0, 400)
    virgin.curves.append(("NNLS on the samples", grid, res.fit.model.virgin_curve(grid)))
    if res.edge_fit is not None:
        virgin.curves.append(("NNLS on the edge points", grid, res.edge_fit.model.virgin_curve(grid)))
    if res.edge_rolling is not None:
        virgin.curves.append((f"parametric on the edge points ({res.edge_rolling.exponent_text()})", grid,
                              res.edge_rolling.virgin_curve(grid)))
    # res.warnings: the span of a long record analysed (analysis/presliding/span.py), fewer than 4 reversals
    return AnalysisResult(_title(result), numbers, [loops, virgin], list(res.resolution.lines) + list(res.warnings))


#: the GUI's own presentation of a registry analysis (result, options) -> AnalysisResult; any other registered
#: analysis of one run is shown by :func:`summary_table`
ANALYSES: dict[str, Callable] = {"identify": identification, "skeleton": skeleton, "afrf": afrf,
                                 "residual": residual, "presliding": presliding}


def titles() -> dict[str, str]:
    """name -> title of every analysis the browser offers, in the registry's order."""
    from hilbench.analysis.protocol import entry

    return {name: entry(name).title for name in _gui_names()}
