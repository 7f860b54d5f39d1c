"""One compensated run against its baseline, the same reference played with no feed-forward (docs/compensation.md,
"One run and its baseline"). The figures are the matrix's (:mod:`metrics`, :func:`report.reduction`); this module
only lays them out for one run: a summary line and a figure of the tracking error against time with the reversals
marked, and the error around every reversal.
"""

from __future__ import annotations

import math

import numpy as np

from hilbench.analysis.compensation.report import CaseResult, draw_reversals, reduction
from hilbench.analysis.figure_style import engineering, plain_numbers

#: line style of a run by its feed-forward: the baseline (none) grey and behind, the feed-forward in front
STYLES = {"none": {"color": "0.55", "zorder": 1}}
FEEDFORWARD_STYLE = {"color": "C0", "zorder": 2}


def _style(result: CaseResult) -> dict:
    return STYLES.get(result.compensator, FEEDFORWARD_STYLE)


def _mrad(value: float) -> str:
    return "–" if not math.isfinite(value) else f"{value * 1e3:.4g}"


def _factor(x: float) -> str:
    """A reduction factor (baseline / run) in words: '6.1x smaller' or, below 1, '1.7x larger'."""
    if not (math.isfinite(x) and x > 0):
        return "no factor"
    return f"{x:.3g}x smaller" if x >= 1 else f"{1 / x:.3g}x larger"


def summary_line(run: CaseResult, baseline: CaseResult | None) -> str:
    """One line: rms and max tracking error and mean reversal glitch of ``run`` (mrad), against ``baseline`` with
    the reduction factor (baseline / run) when there is one."""
    m = run.metrics
    head = f"{run.reference.kind} / {run.compensator}"
    if baseline is None:
        return (f"{head}: rms error {_mrad(m.rms_error)} mrad, max error {_mrad(m.max_error)} mrad, glitch mean "
                f"{_mrad(m.glitch_mean)} mrad over {m.glitch.size} reversals (no baseline)")
    b, x = baseline.metrics, reduction(run, baseline)
    parts = [f"{label} {_mrad(getattr(m, name))} vs {_mrad(getattr(b, name))} mrad ({_factor(x[name + '_x'])})"
             for name, label in (("rms_error", "rms error"), ("max_error", "max error"),
                                 ("glitch_mean", "glitch mean"))]
    return f"{head} against none: " + ", ".join(parts) + f" over {m.glitch.size} reversals"


def run_figure(run: CaseResult, baseline: CaseResult | None, title: str):
    """The figure of one run (and its baseline): above, the tracking error q_ref - q against time with every
    reversal of the reference marked; below, the error around every reversal (:func:`report.draw_reversals`)
    with the glitch window shaded. Errors in the engineering unit of the larger run (mrad or µrad)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in (baseline, run) if r is not None]  # the baseline first: the feed-forward is drawn on top
    factor, unit = engineering("rad", np.concatenate([r.error for r in rows]))
    fig, (top, zoom) = plt.subplots(2, 1, figsize=(10, 7.5), layout="constrained")
    ref = run.reference
    for r in rows:
        top.plot(ref.t, r.error * factor, lw=0.8, label=f"feed-forward {r.compensator}", **_style(r))
    for i, k in enumerate(run.metrics.reversal_index):
        top.axvline(ref.t[k], color="C3", lw=0.6, ls=":", zorder=0, label="reversal of the reference" if i == 0
                    else None)
    top.set_xlabel("time (s)")
    top.set_ylabel(f"tracking error q_ref - q ({unit})")
    top.set_title("whole run")
    top.grid(alpha=0.3)
    plain_numbers(top)
    draw_reversals(zoom, rows, styles={r.compensator: _style(r) for r in rows}, unit=(factor, unit))
    zoom.axvspan(0, run.metrics.window_s * 1e3, color="C3", alpha=0.08, lw=0)
    zoom.set_title(f"around every reversal (shaded: the {run.metrics.window_s * 1e3:g} ms glitch window)")
    plain_numbers(zoom)
    handles, labels = top.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels))
    fig.suptitle(title)
    return fig
