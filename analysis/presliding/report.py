"""The presliding analysis as a document and a summary (schema hilbench-presliding 3, docs/presliding.md): what
``hilbench presliding`` writes and what the GUI's run browser shows, built in one place."""

from __future__ import annotations

import math
from pathlib import Path

from hilbench.analysis.errors import AnalysisError


def protocol_inertia(params: dict, path: str) -> float:
    """J (kg*m^2 or kg) the run's protocol recorded to subtract J*x'' (0 when none), or a one-line AnalysisError."""
    inertia = float(params.get("inertia", 0.0) or 0.0)
    if not (math.isfinite(inertia) and inertia >= 0):
        raise AnalysisError(f"{path}: the run file's protocol inertia must be finite and >= 0, got {inertia}")
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
    if doc.get("incomplete"):
        lines.append(f"INCOMPLETE RECORD: {doc['incomplete']} (analysed with --allow-incomplete)")
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
