"""Plots of a family comparison: hysteresis (friction against position) and time traces, one panel per family."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hilbench.analysis.figure_style import engineering, plain_numbers
from hilbench.analysis.models.compare import Comparison


def _key():
    """Legend entries of both figures: the model's colour is its panel's, so its entry is grey."""
    from matplotlib.lines import Line2D

    return [Line2D([], [], color="0.15", lw=1.6, label="measured"),
            Line2D([], [], color="0.5", lw=1.2, ls="--", label="model (in the colour of its panel title)")]


def write_plots(result: Comparison, outdir: str | Path, window_s: float = 2.0, loop_s: float = 0.3) -> list[Path]:
    """Write ``compare_hysteresis.png`` and ``compare_time.png`` into ``outdir`` (created); returns the paths.

    Both show the validation run where its velocity changes sign most often. The hysteresis plot shows the
    friction against L[theta] over ``loop_s`` seconds. The time plot shows the position (measured and segmented
    simulation) and the torque over ``window_s`` seconds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    val = result.validation
    fitted = [r for r in result.rows if r.error is None]  # a failed family has no curves
    if not fitted:
        return []
    u = {"rotary": ("rad", "N*m", "torque"), "linear": ("m", "N", "force")}[val.axis]
    rows_idx = val.data.rows
    n_win = max(2, int(window_s * val.fs))
    n_loop = max(2, int(loop_s * val.fs))
    # the window with the most velocity sign changes: where the models differ most
    flips = np.cumsum(np.r_[0, np.abs(np.diff(np.sign(val.v))) > 0])
    if val.x.size > n_win:
        start = int(np.argmax(flips[n_win:] - flips[:-n_win]))
    else:
        start = 0
    sel = (rows_idx >= start) & (rows_idx < start + n_win)
    t = np.arange(val.x.size) / val.fs

    # friction loops around the busiest reversal: measured friction is L[tau] - J*L[theta''] - c0 with the J and
    # c0 of the first fitted row; each model's is its own friction along the measured path. One panel per family
    # (small multiples): seven overlaid lines hide each other.
    flip = int(np.argmax(flips[n_loop:] - flips[:-n_loop])) if val.x.size > n_loop else 0
    near = (rows_idx >= flip) & (rows_idx < flip + n_loop)
    xf, xu = engineering(u[0], val.data.position[near])
    measured = fitted[0].curves["friction_measured"][near]
    ff, fu = engineering(u[1], np.concatenate([measured, *[r.curves["friction_predicted"][near] for r in fitted]]))
    cols = min(4, len(fitted))
    rows = -(-len(fitted) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.7 * rows + 0.9), sharex=True, sharey=True,
                             squeeze=False, layout="constrained")
    for i, (ax, r) in enumerate(zip(axes.flat, fitted, strict=False)):
        colour = f"C{i % 10}"
        ax.plot(xf * val.data.position[near], ff * measured, color="0.15", lw=1.6, label="measured")
        ax.plot(xf * val.data.position[near], ff * r.curves["friction_predicted"][near], color=colour, lw=1.2,
                ls="--", label="model")
        ax.set_title(r.name, fontsize=10, color=colour)
        ax.grid(True, alpha=0.3)
        plain_numbers(ax)
    for ax in axes.flat[len(fitted):]:
        ax.set_visible(False)
    for ax in axes[-1, :]:
        ax.set_xlabel(f"filtered position ({xu})")
    for ax in axes[:, 0]:
        ax.set_ylabel(f"friction {u[2]} ({fu})")
    fig.legend(handles=_key(), loc="outside lower center", ncol=2, frameon=False,
               title=f"measured: L[{u[2]}] - J L[x''] - c0 with J, c0 of {fitted[0].name}; model: each family's "
                     "friction along the measured path")
    fig.suptitle(f"{val.name} (validation): friction against position, t = {t[flip]:.2f} … "
                 f"{t[min(flip + n_loop, t.size - 1)]:.2f} s (the window with the most reversals)")
    p1 = out / "compare_hysteresis.png"
    fig.savefig(p1, dpi=110)
    plt.close(fig)

    # time traces: the measured run on top, then one row per family: its position error (the segmented
    # simulation minus the measurement, where the families differ) and its torque against the measured one
    w = slice(start, start + n_win)
    tw, tr = t[w], t[rows_idx[sel]]
    xf, xu = engineering(u[0], val.x[w])
    ef, eu = engineering(u[0], np.concatenate([r.curves["position_simulated"][w] - val.x[w] for r in fitted]))
    tf, tu = engineering(u[1], val.data.torque[sel])
    fig, axes = plt.subplots(len(fitted) + 1, 2, figsize=(11, 1.45 * (len(fitted) + 1) + 0.9), sharex=True,
                             squeeze=False, layout="constrained")
    axes[0, 0].plot(tw, xf * val.x[w], color="0.15", lw=1.4)
    axes[0, 0].set_ylabel(f"position ({xu})")
    axes[0, 0].set_title("measured position", fontsize=9)
    axes[0, 1].plot(tr, tf * val.data.torque[sel], color="0.15", lw=1.4)
    axes[0, 1].set_ylabel(f"{u[2]} ({tu})")
    axes[0, 1].set_title(f"measured {u[2]} (filtered)", fontsize=9)
    for i, r in enumerate(fitted):
        colour = f"C{i % 10}"
        a1, a2 = axes[i + 1]
        a1.axhline(0.0, color="0.6", lw=0.6)
        a1.plot(tw, ef * (r.curves["position_simulated"][w] - val.x[w]), color=colour, lw=1.2)
        a1.set_ylabel(f"error ({eu})")
        a1.set_title(f"{r.name}: simulated - measured position", fontsize=9, color=colour)
        a2.plot(tr, tf * val.data.torque[sel], color="0.15", lw=1.4, label="measured")
        a2.plot(tr, tf * r.curves["torque_predicted"][sel], color=colour, lw=1.0, ls="--", label="model")
        a2.set_ylabel(f"{u[2]} ({tu})")
        a2.set_title(f"{r.name}: {u[2]}, measured and model", fontsize=9, color=colour)
        a1.sharey(axes[1, 0])
        a2.sharey(axes[0, 1])
    for a in axes.flat:
        a.grid(True, alpha=0.3)
        plain_numbers(a)
    for a in axes[-1]:
        a.set_xlabel("time (s)")
    fig.legend(handles=_key(), loc="outside lower center", ncol=2, frameon=False)
    fig.suptitle(f"{val.name} (validation): segmented simulation (restart every {result.segment_s:g} s) and "
                 f"{u[2]}, the {window_s:g} s with the most reversals")
    p2 = out / "compare_time.png"
    fig.savefig(p2, dpi=110)
    plt.close(fig)
    return [p1, p2]


def report(result: Comparison, out_dir: str | Path) -> list[Path]:
    """The comparison's report (:func:`hilbench.analysis.models.compare.analyse` is its front door): its figures,
    ``compare_hysteresis.png`` and ``compare_time.png``, in ``out_dir``."""
    return write_plots(result, out_dir)
