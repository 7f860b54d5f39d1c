"""The compensation matrix report: a Markdown table, a JSON document and error plots around reversals.

Schema of the JSON: ``hilbench.compensation/1`` (docs/compensation.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hilbench.analysis.compensation.metrics import Metrics
from hilbench.analysis.compensation.references import Reference

SCHEMA = "hilbench.compensation/1"


@dataclass
class CaseResult:
    """One run of the matrix: a compensator against a reference."""

    reference: Reference
    compensator: str
    metrics: Metrics
    error: np.ndarray      # rad, q_ref - q
    clipped: int           # feed-forward samples clipped to the current limit
    run_file: str = ""


def _f(value: float, scale: float = 1.0) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{value * scale:.3g}"


def markdown_table(results: list[CaseResult]) -> str:
    """One row per run; ``glitch reduction vs none`` (``vs coulomb``) is the mean glitch of ``none``
    (``coulomb``) on the same reference divided by this row's (a factor > 1 means a smaller glitch)."""
    base = {(r.reference.kind, r.compensator): r.metrics.glitch_mean for r in results}
    lines = ["| reference | feed-forward | rms error (mrad) | max error (mrad) | reversals | glitch mean (mrad) | "
             "glitch max (mrad) | glitch reduction vs none (x) | vs coulomb (x) | settling max (s) | "
             "effort rms (A) | feed-forward samples clipped |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        m = r.metrics
        kind = r.reference.kind
        ratio = [base.get((kind, b), math.nan) / m.glitch_mean if m.glitch_mean > 0 else math.nan
                 for b in ("none", "coulomb")]
        settle = "–" if not m.settling.size else ("not settled" if np.isnan(m.settling).any()
                                                  else _f(m.settling_max))
        lines.append(f"| {kind} | {r.compensator} | {_f(m.rms_error, 1e3)} | {_f(m.max_error, 1e3)} | "
                     f"{m.glitch.size} | {_f(m.glitch_mean, 1e3)} | {_f(m.glitch_max, 1e3)} | {_f(ratio[0])} | "
                     f"{_f(ratio[1])} | {settle} | {_f(m.effort_rms)} | {r.clipped} |")
    return "\n".join(lines) + "\n"


def section_glitch(result: CaseResult) -> dict[str, float]:
    """Mean glitch (rad) of the reversals inside each section of the reference (the sine's amplitudes)."""
    out = {}
    idx = result.metrics.reversal_index
    for label, start, stop in result.reference.sections:
        inside = (idx >= start) & (idx < stop)
        out[label] = float(np.mean(result.metrics.glitch[inside])) if inside.any() else math.nan
    return out


def section_table(results: list[CaseResult]) -> str:
    """Mean glitch (mrad) per section (sine amplitude) and feed-forward, with the reduction against none."""
    rows = [r for r in results if r.reference.sections]
    if not rows:
        return ""
    labels = [s[0] for s in rows[0].reference.sections]
    base = section_glitch(next((r for r in rows if r.compensator == "none"), rows[0]))
    lines = [f"Mean reversal glitch by {rows[0].reference.kind} amplitude, mrad (reduction against none, x):", "",
             "| feed-forward | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    for r in rows:
        g = section_glitch(r)
        cells = [f"{_f(g[lab], 1e3)} ({_f(base[lab] / g[lab] if g[lab] > 0 else math.nan)})" for lab in labels]
        lines.append(f"| {r.compensator} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


#: the figures :func:`reduction` compares, as attributes of :class:`Metrics`
REDUCED = ("rms_error", "max_error", "glitch_mean")


def reduction(result: CaseResult, baseline: CaseResult) -> dict[str, float]:
    """``baseline``'s figure divided by ``result``'s for each of :data:`REDUCED` (a factor, x: > 1 means the
    feed-forward of ``result`` made it smaller); NaN where ``result``'s figure is 0 or undefined."""
    out = {}
    for name in REDUCED:
        this, base = getattr(result.metrics, name), getattr(baseline.metrics, name)
        out[f"{name}_x"] = base / this if this > 0 and math.isfinite(base) else math.nan
    return out


def document(results: list[CaseResult], settings: dict) -> dict:
    """The JSON-able report: settings and, per run, the reference parameters and every metric; with a ``none``
    run of the same reference, ``reduction_vs_none`` (:func:`reduction`)."""
    base = {r.reference.kind: r for r in results if r.compensator == "none"}
    return {"schema": SCHEMA, "settings": settings,
            "runs": [{"reference": r.reference.kind, "reference_parameters": r.reference.params,
                      "feedforward": r.compensator, "run_file": r.run_file, "feedforward_clipped": r.clipped,
                      "glitch_mean_by_section_rad": section_glitch(r), **r.metrics.summary(),
                      **({"reduction_vs_none": reduction(r, base[r.reference.kind])}
                         if r.reference.kind in base else {})} for r in results]}


def draw_reversals(ax, rows: list[CaseResult], *, before: float = 0.02, styles: dict | None = None,
                   unit: tuple[float, str] = (1e3, "mrad")) -> None:
    """Draw on ``ax`` the error of each of ``rows`` around every reversal, aligned at the reversal and signed so
    that lagging behind the new direction is positive (``unit`` = (factor from rad, name), default mrad, against
    ms), one colour per feed-forward (or ``styles[name]``, keyword arguments of ``ax.plot``); reversals closer
    than ``before`` s to the start or three glitch windows to the end are left out."""
    for colour, r in enumerate(rows):
        ref, m = r.reference, r.metrics
        n0 = int(round(before * ref.fs))
        n1 = int(round(3 * m.window_s * ref.fs))
        t_ms = np.arange(-n0, n1) / ref.fs * 1e3
        label = r.compensator
        style = (styles or {}).get(r.compensator, {"color": f"C{colour}"})
        for k in m.reversal_index:
            if k - n0 < 0 or k + n1 > ref.n:
                continue
            direction = np.sign(ref.velocity[k])
            ax.plot(t_ms, direction * r.error[k - n0:k + n1] * unit[0], lw=0.8, alpha=0.6, label=label, **style)
            label = None
    ax.axvline(0, color="k", lw=0.5)
    ax.set_xlabel("time after reversal (ms)")
    ax.set_ylabel(f"tracking error along the new direction ({unit[1]})")
    ax.grid(alpha=0.3)


def write_plots(results: list[CaseResult], out: Path, *, before: float = 0.02, save=None) -> list[Path]:
    """``compensation_<reference>.png``: the error around every reversal (:func:`draw_reversals`), one colour
    per feed-forward. ``save(fig, path)`` writes a figure (default ``fig.savefig(path, dpi=110)``; the bench
    passes its atomic, input-checked writer)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for kind in dict.fromkeys(r.reference.kind for r in results):
        rows = [r for r in results if r.reference.kind == kind]
        fig, ax = plt.subplots(figsize=(8, 4.5))
        draw_reversals(ax, rows, before=before)
        ax.set_title(f"{kind}: error around every reversal")
        ax.legend(title="feed-forward")
        fig.tight_layout()
        path = out / f"compensation_{kind}.png"
        if save is None:
            fig.savefig(path, dpi=110)
        else:
            save(fig, path)
        plt.close(fig)
        paths.append(path)
    return paths
