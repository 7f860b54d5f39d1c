"""Report of a residual loop: the JSON document, diagnostic figures (PNG) and a Markdown summary.

JSON keys are documented in docs/residual-report.md.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hilbench.analysis.residual.diagnostics import Diagnostic, Signals, _jsonable
from hilbench.analysis.residual.selection import LoopResult
from hilbench.common.metrics import (
    FORCE_NRMSE,
    POSITION_NRMSE,
    RELATIVE_ERROR,
    SEGMENTED_POSITION_NRMSE,
    TORQUE_NRMSE,
    UNIT,
    percent,
)


def report_dict(result: LoopResult, inputs: dict | None = None) -> dict:
    """The JSON report (plain types; NaN/inf become null)."""
    out = result.to_dict()
    if inputs:
        out = {"inputs": inputs, **out}
    return _jsonable(out)


def write_json(result: LoopResult, path: str | Path, inputs: dict | None = None) -> None:
    Path(path).write_text(json.dumps(report_dict(result, inputs), indent=2, allow_nan=False) + "\n")


def _binned(x: np.ndarray, y: np.ndarray, bins: int = 30) -> tuple[np.ndarray, np.ndarray]:
    from scipy.stats import binned_statistic

    if np.ptp(x) == 0:
        return np.array([x[0]]), np.array([np.mean(y)])
    m, edges, _ = binned_statistic(x, y, "mean", bins=bins)
    return 0.5 * (edges[1:] + edges[:-1]), m


def plot_diagnostics(s: Signals, diags: dict[str, Diagnostic], title: str, path: str | Path,
                     units: dict[str, str]) -> None:
    """3x3 figure: residual against time, position, velocity, acceleration and command; the angle-domain
    and time-domain spectra; direction dependence; cross-correlation with the input."""
    import matplotlib

    matplotlib.use("Agg")
    import textwrap

    import matplotlib.pyplot as plt

    from hilbench.analysis.figure_style import scaled_axis

    e = s.residual
    tu, pu = units["torque"], units["position"]
    fig, ax = plt.subplots(3, 3, figsize=(14, 10))

    def wrapped(text: str) -> str:  # a long diagnostic title on two lines, never cut mid-sentence
        return "\n".join(textwrap.wrap(text, 70)[:2])
    scatter = dict(s=2, alpha=0.3, color="tab:blue", rasterized=True)

    def panel(a, x, label, diag):
        a.scatter(x, e, **scatter)
        bx, by = _binned(x, e)
        a.plot(bx, by, color="tab:red", lw=1.5, label="bin mean")
        a.set_xlabel(label)
        a.set_ylabel(f"residual ({scaled_axis(a.yaxis, tu, e)})")  # mN*m for small residuals
        if diag is not None:
            d = diags[diag]
            a.set_title(f"{diag}: F={d.statistic:.3g}, p={d.p_value:.2g}, effect {100 * d.effect:.1f} %", fontsize=8)

    panel(ax[0, 0], s.time, "time (s)", "mean_trend")
    panel(ax[0, 1], s.position, f"position ({pu})", "position")
    panel(ax[0, 2], s.velocity, f"velocity ({pu}/s)", "velocity")
    panel(ax[1, 0], s.acceleration, f"acceleration ({pu}/s^2)", "acceleration")
    panel(ax[1, 1], s.command, f"command torque ({tu})", "command")
    a = ax[1, 2]
    spec = diags["angle_spectrum"].detail.get("spectrum")
    if spec is not None:
        k = np.asarray(spec["wavenumber"])
        x = k if s.axis == "rotary" else k / (2 * np.pi)
        a.plot(x, 100 * np.asarray(spec["effect"]), lw=0.8)
        a.set_xlabel("order (cycles/rev)" if s.axis == "rotary" else "spatial frequency (1/m)")
    a.set_ylabel("variance explained (%)")
    d = diags["angle_spectrum"]
    a.set_title(wrapped(f"angle spectrum: {d.description}"), fontsize=8)
    a = ax[2, 0]
    spec = diags["time_spectrum"].detail.get("spectrum")
    if spec is not None:
        a.semilogy(spec["frequency_hz"], spec["psd"], lw=0.8, label="PSD")
        a.semilogy(spec["frequency_hz"], spec["background"], lw=0.8, label="background")
        a.legend(fontsize=7)
    a.set_xlabel("frequency (Hz)")
    a.set_ylabel(f"PSD ({tu}^2/Hz)")
    a.set_title(wrapped(f"time spectrum: {diags['time_spectrum'].description}"), fontsize=8)
    a = ax[2, 1]
    for mask, lab in ((s.velocity_fast > 0, "v > 0"), (s.velocity_fast < 0, "v < 0")):
        if mask.sum() > 10:
            bx, by = _binned(np.abs(s.velocity[mask]), e[mask])
            a.plot(bx, by, marker=".", label=lab)
    a.legend(fontsize=7)
    a.set_xlabel(f"speed |v| ({pu}/s)")
    a.set_ylabel(f"mean residual ({scaled_axis(a.yaxis, tu, e)})")
    d = diags["direction"]
    a.set_title(f"direction: F={d.statistic:.3g}, p={d.p_value:.2g}", fontsize=8)
    a = ax[2, 2]
    d = diags["input_xcorr"]
    if "lags_s" in d.detail:
        a.plot(1e3 * np.asarray(d.detail["lags_s"]), d.detail["rho"], marker=".")
    a.set_xlabel("lag, > 0: input earlier (ms)")
    a.set_ylabel("correlation (1)")
    a.set_title(f"input_xcorr: rho={d.statistic:+.2f}, p={d.p_value:.2g}", fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def plot_force(result: LoopResult, path: str | Path, units: dict[str, str]) -> None:
    """Displacement-driven records: measured force and the force the model computes from the measured
    displacement (filtered rows), against displacement and against time, before and after."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tu, pu = units["torque"], units["position"]
    fig, ax = plt.subplots(2, 2, figsize=(12, 8))
    for row, (fit, sig, label) in enumerate(((result.fit_before, result.signals_before, "before"),
                                              (result.fit_after, result.signals_after, "after"))):
        sim = fit.y - fit.residual
        e = fit.residual
        rel = 100 * float(np.linalg.norm(e) / np.linalg.norm(fit.y))
        a = ax[row, 0]
        a.plot(sig.position, fit.y, lw=0.6, color="0.3", label="measured")
        a.plot(sig.position, sim, lw=0.6, color="tab:red", label="simulated from the measured displacement")
        a.set_xlabel(f"displacement ({pu})")
        a.set_ylabel(f"force ({tu})")
        a.set_title(f"{label}: force error {rel:.3g} % (100·|F - F_sim|/|F|)", fontsize=9)
        a.legend(fontsize=7)
        a = ax[row, 1]
        a.plot(sig.time, fit.y, lw=0.6, color="0.3", label="measured")
        a.plot(sig.time, sim, lw=0.6, color="tab:red", label="simulated")
        a.plot(sig.time, e, lw=0.6, color="tab:blue", label="error")
        a.set_xlabel("time (s)")
        a.set_ylabel(f"force ({tu})")
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


#: the glossary's names of the error keys (docs/metrics.md)
_NAMES = {"torque_nrmse": TORQUE_NRMSE, "force_nrmse": FORCE_NRMSE, "position_nrmse": POSITION_NRMSE,
          "position_nrmse_segmented": SEGMENTED_POSITION_NRMSE}


def _metric_name(key: str) -> str:
    """The glossary's name of an error key (docs/metrics.md): ``torque_nrmse`` -> ``torque NRMSE``."""
    if key.endswith("_rel_pct"):
        return f"{key.removesuffix('_rel_pct')} {RELATIVE_ERROR}"
    return _NAMES.get(key, f"{key.removesuffix('_nrmse')} NRMSE")


def _pct(key: str, value) -> str:
    """An error figure in percent: ``*_nrmse`` keys hold fractions, ``*_pct`` keys percent already."""
    if value is None or key.endswith("_pct"):
        return _fmt(value)
    return _fmt(percent(value))


def markdown_summary(result: LoopResult, title: str = "Residual loop", notes: list[str] | None = None) -> str:
    d = report_dict(result)
    lines = [f"# {title}", "", f"**Verdict:** {d['verdict']}", "",
             f"Starting model: `{', '.join(d['start'])}`. Held-out error from: {d['validation_mode']}.", ""]
    if d.get("presliding_check"):  # the loop changed the start's presliding law (selection._presliding_check)
        lines += [f"Presliding check: {d['presliding_check']['note']}.", ""]
    lines += ["## Error before and after", "", "| set | metric | before | after |", "|---|---|---|---|"]
    for part in ("train", "validation"):
        keys = (("force_rel_pct", "force_nrmse") if d.get("record") == "displacement-driven" else
                ("torque_rel_pct", "torque_nrmse", "position_nrmse", "position_nrmse_segmented", "velocity_nrmse"))
        for key in keys:
            lines.append(f"| {part} | {_metric_name(key)} ({UNIT}) | {_pct(key, d['error_before'][part].get(key))} | "
                         f"{_pct(key, d['error_after'][part].get(key))} |")
    pm = d.get("published_metric")
    if pm:
        lines += ["", f"Published metric: {pm['metric']} ({pm['reference']}).", "",
                  "| set | published | before | after |", "|---|---|---|---|"]
        for part in ("train", "validation"):
            lines.append(f"| {part} | {_fmt(pm['published'][part])} | {_fmt(pm['before'][part])} | "
                         f"{_fmt(pm['after'][part])} |")
    lines += ["", "## Effects added (in order)", ""]
    if not d["effects_added"]:
        lines.append("None.")
    for i, e in enumerate(d["effects_added"], 1):
        p = {k: v for k, v in e["parameters"].items() if k != "units" and not isinstance(v, (list, dict))}
        u = e["uncertainty"]
        units = e["parameters"].get("units", {})
        par = ", ".join(f"{k} = {_fmt(v)}" + (f" ± {_fmt(u.get(k))}" if u.get(k) is not None else "")
                        + (f" {units[k]}" if k in units else "") for k, v in p.items())
        lines.append(f"{i}. **{e['name']}** — {e['physics']}. {par}. Held-out MSE reduced by "
                     f"{100 * e['validation_gain']:.1f} % (p = {e['p_value']:.2g}); validation torque "
                     f"{RELATIVE_ERROR} {_fmt(e['error_after']['validation']['torque_rel_pct'])} {UNIT}.")
    lines += ["", "## Unexplained structure", ""]
    lines += [f"- {u['description']} (effect {100 * u['effect']:.1f} % of the residual variance, "
              f"p = {u['p_value']:.2g})" for u in d["unexplained"]] or ["None."]
    lines += ["", "## Candidates per round", ""]
    for i, rd in enumerate(d["rounds"], 1):
        lines.append(f"Round {i}: " + "; ".join(
            f"{c['name']} (gain {_fmt(c['validation_gain'])}, p {_fmt(c['p_value'])}{', kept' if c['kept'] else ''})"
            if c["validation_gain"] is not None else f"{c['name']} (not fitted: {c['note']})"
            for c in rd["candidates"]))
    if notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in notes]
    figs = "`diagnostics_before.png`, `diagnostics_after.png`"
    if d.get("record") == "displacement-driven":
        figs += (", `force.png` (displacement-driven record: measured force and the force simulated from the "
                 "measured displacement)")
    lines += ["", f"Figures: {figs}.", ""]
    return "\n".join(lines)


def write_report(result: LoopResult, directory: str | Path, title: str = "Residual loop",
                 notes: list[str] | None = None) -> list[Path]:
    """Write diagnostics_before.png, diagnostics_after.png and summary.md into ``directory`` (and force.png
    for a displacement-driven record)."""
    from hilbench.common.units import AXIS_UNITS as AXES

    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    axis = result.signals_before.axis
    units = {"torque": AXES[axis]["torque"], "position": AXES[axis]["position"]}
    paths = [out / "diagnostics_before.png", out / "diagnostics_after.png", out / "summary.md"]
    plot_diagnostics(result.signals_before, result.diagnostics_before, f"{title}: before ({', '.join(result.start)})",
                     paths[0], units)
    after = ", ".join(result.names_added) or "nothing added"
    plot_diagnostics(result.signals_after, result.diagnostics_after, f"{title}: after ({after})", paths[1], units)
    paths[2].write_text(markdown_summary(result, title, notes))
    if result.record == "displacement-driven":
        paths.append(out / "force.png")
        plot_force(result, paths[-1], units)
    return paths
