"""``hilbench presliding RUN.h5 -o DIR``: presliding analysis of a displacement-driven record (docs/presliding.md):
reversal-point table, Masing and wiping-out checks, the Maxwell-slip force model, x_p, sum(k), F_b with
uncertainties, what the resolution no longer resolves, and the figures."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

OUTPUT_FILES = ("presliding.json", "summary.md", "reversals.csv", "loops.png", "virgin.png")
#: run-file channels that hold no force: refused as --torque-channel
NOT_FORCE = ("t", "sample_index", "position", "position_cmd", "velocity", "velocity_cmd", "counts")


def register(subparsers: argparse._SubParsersAction) -> None:
    from hilbench.bench.analysis_input import whole_number

    parser = subparsers.add_parser(
        "presliding",
        help="presliding analysis of a displacement-driven record (force against imposed displacement)",
        description="Reversal points, the Masing and wiping-out checks on the measured data, force-from-"
        "displacement identification (Maxwell-slip by NNLS), presliding distance, initial stiffness and "
        "break-away force with bootstrap uncertainties, and which of them the encoder resolution no longer "
        "resolves. Writes " + ", ".join(OUTPUT_FILES) + " into DIR (docs/presliding.md).",
    )
    parser.add_argument("run", metavar="RUN.h5", help="a displacement-driven run file (root attribute record)")
    parser.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the outputs")
    parser.add_argument("--overwrite", action="store_true", help="replace outputs that exist in DIR")
    parser.add_argument("--fraction", type=float, default=0.9,
                        help="presliding distance: where the virgin curve reaches this fraction of its sliding "
                             "level (default 0.9)")
    parser.add_argument("--inertia", type=float, default=None, metavar="J",
                        help="known inertia (kg*m^2, or kg on a linear axis) whose J*x'' is subtracted (default: the "
                             "presliding protocol's inertia parameter in the run file, else 0)")
    parser.add_argument("--coulomb", action="store_true", help="add a Coulomb term Fc*sign(x')")
    parser.add_argument("--no-viscous", action="store_true", help="no viscous term b*x'")
    parser.add_argument("--thresholds", type=whole_number, default=48,
                        help="candidate Maxwell-slip thresholds (default 48, 1 to 400)")
    parser.add_argument("--hysteresis", type=float, default=None, metavar="X",
                        help="smallest travel counted as a reversal, m or rad (default 1.5 position steps)")
    parser.add_argument("--replicates", type=whole_number, default=20,
                        help="bootstrap replicates for the uncertainties (default 20, 2 to 1000)")
    parser.add_argument("--counts-per-rev", type=float, default=None, metavar="N",
                        help="encoder counts per revolution (default: the run file's calibration, else the "
                             "step measured from the data)")
    parser.add_argument("--torque-channel", default=None, metavar="NAME", help="force channel (default torque)")
    parser.set_defaults(func=run)


def _check(args) -> None:
    from hilbench.bench.analysis_input import check_count
    from hilbench.bench.errors import BenchError

    if not (math.isfinite(args.fraction) and 0 < args.fraction < 1):
        raise BenchError(f"--fraction must be in (0, 1), got {args.fraction}")
    if args.inertia is not None and not (math.isfinite(args.inertia) and args.inertia >= 0):
        raise BenchError(f"--inertia must be finite and >= 0, got {args.inertia}")
    if args.hysteresis is not None and not (math.isfinite(args.hysteresis) and args.hysteresis >= 0):
        raise BenchError(f"--hysteresis must be finite and >= 0, got {args.hysteresis}")
    if args.counts_per_rev is not None and not (math.isfinite(args.counts_per_rev) and args.counts_per_rev > 0):
        raise BenchError(f"--counts-per-rev must be finite and > 0, got {args.counts_per_rev}")
    check_count(args.thresholds, "--thresholds", 1, 400, "each threshold is one stop-operator column")
    check_count(args.replicates, "--replicates", 2, 1000, "each replicate is one refit")


def run(args: argparse.Namespace) -> int:
    from hilbench.analysis.presliding.analyse import analyse, figures, table_csv, table_markdown
    from hilbench.analysis.presliding.identify import PreslidingSettings
    from hilbench.analysis.run_file import read_run_file
    from hilbench.bench import outputs
    from hilbench.bench.analysis_input import numeric, torque_channel
    from hilbench.bench.errors import BenchError

    _check(args)
    out = Path(args.output)
    targets = {name: out / name for name in OUTPUT_FILES}
    outputs.refuse_inputs({f"-o {p}": p for p in targets.values()}, [args.run])
    present = [p.name for p in targets.values() if p.exists()]
    if present and not args.overwrite:
        raise BenchError(f"{out} holds {', '.join(present)} already; use --overwrite or another folder")
    rf = read_run_file(args.run)
    if rf.record != "displacement-driven":
        raise BenchError(f"{args.run}: a {rf.record} record; presliding needs a displacement-driven one "
                         "(hilbench import ... --record displacement-driven, or a presliding protocol run)")
    name = torque_channel(rf.channels, args.torque_channel, args.run, rf.axis)
    if name in NOT_FORCE:  # a position taken as the force overflowed the fit (issue 30 item 12)
        raise BenchError(f"--torque-channel {args.torque_channel}: {name!r} is not a force or torque channel")
    x = numeric(rf.channel("position"), "position", args.run)
    force = numeric(rf.channels[name], name, args.run)
    cpr = args.counts_per_rev if args.counts_per_rev is not None else rf.calibration.get("counts_per_rev")
    inertia = args.inertia if args.inertia is not None else protocol_inertia(rf.protocol_params, args.run)
    settings = PreslidingSettings(inertia=inertia, viscous=not args.no_viscous, coulomb=args.coulomb,
                                  n_thresholds=args.thresholds)
    res = analyse(rf.t, x, force, rf.sample_rate, rf.axis, settings, counts_per_rev=cpr,
                  hysteresis=args.hysteresis, fraction=args.fraction, replicates=args.replicates)
    doc = report(res, args.run, name)
    out.mkdir(parents=True, exist_ok=True)
    outputs.write_json(targets["presliding.json"], doc, indent=2)  # strict JSON: a NaN is written as null
    outputs.write_text(targets["reversals.csv"], table_csv(res))
    outputs.write_text(targets["summary.md"], summary_markdown(doc, table_markdown(res)))
    for key, fig in figures(res).items():
        outputs.save_figure(fig, targets[f"{key}.png"], dpi=110)
    for line in summary_lines(doc):
        outputs.say(line)
    outputs.say(f"-> {out}/ ({', '.join(OUTPUT_FILES)})")
    return 0


def protocol_inertia(params: dict, path: str) -> float:
    """J (kg*m^2 or kg) the run's protocol recorded to subtract J*x'' (0 when none), or a one-line BenchError."""
    from hilbench.bench.errors import BenchError

    inertia = float(params.get("inertia", 0.0) or 0.0)
    if not (math.isfinite(inertia) and inertia >= 0):
        raise BenchError(f"{path}: the run file's protocol inertia must be finite and >= 0, got {inertia}")
    return inertia


def report(res, path: str, channel: str) -> dict:
    """The JSON document (schema hilbench-presliding 3, docs/presliding.md)."""
    u = res.units
    q, e = res.quantities, res.uncertainties
    units = {"breakaway": u["torque"], "initial_stiffness": u["stiffness"], "presliding_distance": u["position"]}
    m = res.fit.model
    return {
        "schema": "hilbench-presliding", "schema_version": 3, "run": str(Path(path).resolve()),
        "force_channel": channel, "axis": res.axis, "fraction": res.fraction, "samples_averaged": res.block,
        "quantities": {k: {"value": q[k], "std_uncertainty": e[k], "unit": units[k]} for k in q},
        "uncertainty_method": "moving-block residual bootstrap, refit on the same threshold grid",
        "model": {"ms_stiffness": m.ms_stiffness.tolist(), "ms_delta": m.ms_delta.tolist(),
                  "viscous": m.viscous, "coulomb": m.coulomb, "offset": m.offset, "inertia": m.inertia,
                  "units": {"ms_stiffness": u["stiffness"], "ms_delta": u["position"], "viscous": u["viscous"],
                            "coulomb": u["torque"], "offset": u["torque"], "inertia": u["inertia"]}},
        "validation": {"force_rms_error": res.fit.rms_error, "force_rms_error_relative": res.fit.relative_rms,
                       "unit": u["torque"],
                       "what": "force simulated from the measured displacement against the measured force; "
                               "relative to the model's sliding level"},
        "parametric": _parametric(res, units),
        "edge_pinned": _edge_pinned(res, units),
        "checks": res.checks(),
        "resolution": {"step": res.resolution.step, "step_unit": u["position"], "step_source":
                       res.resolution.step_source, "force_noise": res.resolution.force_noise,
                       "resolved": res.resolution.resolved, "lines": res.resolution.lines},
        "reversals": res.table(),
    }


def _parametric(res, units: dict) -> dict:
    """The rolling-friction fit beside the NNLS (analysis/presliding/parametric.py), or why there is none."""
    r = res.parametric
    if r is None:
        return {"error": res.parametric_error}
    q, e = r.quantities(res.fraction), r.uncertainties(res.fraction)
    units = {**units, "breakaway_extrapolated": units["breakaway"]}
    u = res.units
    return {"shape": r.shape, "h": r.h, "d": r.d, "offset": r.offset, "viscous": r.viscous,
            "units": {"h": u["torque"], "d": u["position"], "offset": u["torque"], "viscous": u["viscous"]},
            "quantities": {k: {"value": q[k], "std_uncertainty": e[k], "unit": units[k]} for k in q},
            "uncertainty_method": "Jacobian covariance of scipy.optimize.least_squares (independent residuals)"
                                  + ("; plus the type-B term of the relaxed position assumed at the first sample of a "
                                     "quantised record" if r.origin_uncertainty else ""),
            "virgin_travel": r.travel, "level_reached": r.level_reached(), "fit_rms_error": r.rms_error,
            "samples": r.samples}


def _edge_pinned(res, units: dict) -> dict:
    """The force model on the dwells at count edges (analysis/presliding/edges.py), or why there is none."""
    f = res.edge_fit
    if f is None:
        doc = {"error": res.edge_error}
        if res.edge_rolling is not None or res.edge_rolling_fixed is not None:  # the shape fitted all the same
            doc.update(parametric_ramp=_rolling_doc(res.edge_rolling, res, units),
                       parametric_ramp_exponent_2=_rolling_doc(res.edge_rolling_fixed, res, units))
        return doc
    from hilbench.analysis.presliding.quantities import quantities

    u, m = res.units, f.model
    q = quantities(m, res.fraction)
    return {"points": res.edges.size, "crossings": int(res.edges.crossings.sum()),
            "ms_stiffness": m.ms_stiffness.tolist(), "ms_delta": m.ms_delta.tolist(), "offset": m.offset,
            "units": {"ms_stiffness": u["stiffness"], "ms_delta": u["position"], "offset": u["torque"]},
            "quantities": {k: {"value": q[k], "unit": units[k]} for k in q},
            "force_rms_error": f.rms_error, "force_rms_error_relative": f.relative_rms,
            "parametric_ramp": _rolling_doc(res.edge_rolling, res, units),
            "parametric_ramp_exponent_2": _rolling_doc(res.edge_rolling_fixed, res, units)}


def _rolling_doc(r, res, units: dict) -> dict:
    if r is None:
        return {"error": "the parametric virgin curve found no finite h, d and p on the edge-pinned virgin ramp"}
    q, e = r.quantities(res.fraction), r.uncertainties(res.fraction)
    u = res.units
    return {"shape": r.shape, "h": r.h, "d": r.d, "exponent": r.exponent,
            "exponent_std_uncertainty": e["exponent"], "offset": r.offset,
            "units": {"h": u["torque"], "d": u["position"], "exponent": "1", "offset": u["torque"]},
            "quantities": {k: {"value": q[k], "std_uncertainty": e[k],
                               "unit": {**units, "breakaway_extrapolated": units["breakaway"]}[k]} for k in q},
            "origin": {"fitted": r.origin is not None, "value": r.origin, "unit": u["position"],
                       "meaning": "relaxed position minus the rest count's position (None: assumed 0; its type-B "
                                  "uncertainty is then in the quantities' uncertainties)"},
            "turn": {"fitted": r.turn is not None, "value": r.turn, "unit": u["position"],
                     "meaning": "first turning point minus its count's centre, when the turn was an excursion "
                                "into a count (None: a dwell at an edge, exact, or no branch fitted)"},
            "fit_rms_error": r.rms_error, "points": r.samples}


def summary_lines(doc: dict) -> list[str]:
    """The human summary: quantities with uncertainties, the checks, the resolution verdicts."""
    lines = []
    for name, q in doc["quantities"].items():
        lines.append(f"{name.replace('_', ' ')} (NNLS, model-free): {q['value']:.5g} +- {q['std_uncertainty']:.2g} "
                     f"{q['unit']}")
    p = doc["parametric"]
    if "error" in p:
        lines.append(f"parametric virgin curve: not fitted ({p['error']})")
    else:
        for name, q in p["quantities"].items():
            lines.append(f"{name.replace('_', ' ')} (parametric, h(1-(d/(d+x))^2)): {q['value']:.5g} +- "
                         f"{q['std_uncertainty']:.2g} {q['unit']}")
        lines[-3] += (f" (h, extrapolated beyond the measured travel {p['virgin_travel']:.3g} "
                      f"{p['units']['d']}, where the curve reaches {100 * p['level_reached']:.3g} % of it)")
    e = doc.get("edge_pinned", {"error": "not made"})
    if "error" in e:
        lines.append(f"edge-pinned virgin curve: not fitted ({e['error']})")
    else:
        for name, q in e["quantities"].items():
            bound = " (a lower bound: no edge lies inside the first half step)" if name == "initial_stiffness" else ""
            lines.append(f"{name.replace('_', ' ')} (edge-pinned NNLS, {e['points']} dwells at count edges): "
                         f"{q['value']:.5g} {q['unit']}{bound}")
    for key in ("parametric_ramp", "parametric_ramp_exponent_2"):
        pr = e.get(key, {"error": ""})
        if "error" not in pr:
            k0 = pr["quantities"]["initial_stiffness"]
            p = (f"p = {pr['exponent']:.3g} +- {pr['exponent_std_uncertainty']:.2g}"
                 if pr["exponent_std_uncertainty"] else f"p = {pr['exponent']:g} (held)")
            where = ("virgin ramp and first branch, relaxed position fitted" if pr["origin"]["fitted"]
                     else "virgin ramp, relaxed position assumed")
            lines.append(f"initial stiffness (edge-pinned {where}, {pr['shape']}, {p}, {pr['points']} points): "
                         f"{k0['value']:.5g} +- {k0['std_uncertainty']:.2g} {k0['unit']}")
    c, v = doc["checks"], doc["validation"]
    lines.append(f"model: force simulated from the measured displacement, rms error {v['force_rms_error']:.3g} "
                 f"{v['unit']} ({100 * v['force_rms_error_relative']:.3g} % of the sliding level)")
    lines.append(f"Masing rule: departure max {c['masing_max']:.3g}, rms {c['masing_rms']:.3g}; wiping-out: "
                 f"max {c['wiping_out_max']:.3g}, rms {c['wiping_out_rms']:.3g}, loop closure {c['closure_max']:.3g} "
                 f"over {c['closed_loops']} closed loops (fractions of the largest virgin force "
                 f"{c['scale']:.4g} {v['unit']}; force noise {c['force_noise_relative']:.2g})")
    ext = [r["force_extreme"] for r in doc["reversals"]]
    unit = v["unit"]
    lines.append("reversal forces (each branch's extreme, 10 ms moving average): "
                 + ", ".join(f"{f:.4g}" for f in ext) + f" {unit}")
    lines.append(f"reversal forces: by the memory rules within {c['reversal_rules_max']:.3g}, by the model within "
                 f"{c['reversal_model_max']:.3g} (fractions of the largest virgin force)")
    lines += [f"resolution: {line}" for line in doc["resolution"]["lines"]]
    return lines


def summary_markdown(doc: dict, table: str) -> str:
    items = "\n".join(f"- {line}" for line in summary_lines(doc))
    return (f"# Presliding analysis of {Path(doc['run']).name}\n\n{items}\n\n## Reversal points\n\n{table}\n"
            "![nested loops](loops.png)\n\n![virgin curve](virgin.png)\n")
