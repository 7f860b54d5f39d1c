"""Plots of a family comparison: overlaid hysteresis (torque against position) and time traces."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hilbench.analysis.models.compare import Comparison


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
    # c0 of the first fitted row; each model's is its own friction along the measured path
    flip = int(np.argmax(flips[n_loop:] - flips[:-n_loop])) if val.x.size > n_loop else 0
    near = (rows_idx >= flip) & (rows_idx < flip + n_loop)
    fig, ax = plt.subplots(figsize=(7, 5))
    ax.plot(val.data.position[near], fitted[0].curves["friction_measured"][near], "k", lw=2,
            label=f"measured (J, c0 of {fitted[0].name})")
    for r in fitted:
        ax.plot(val.data.position[near], r.curves["friction_predicted"][near], lw=1, label=r.name)
    ax.set_xlabel(f"filtered position ({u[0]})")
    ax.set_ylabel(f"filtered friction {u[2]} ({u[1]})")
    ax.set_title(f"{val.name}: friction against position, t = {t[flip]:.2f} … "
                 f"{t[min(flip + n_loop, t.size - 1)]:.2f} s")
    ax.legend(fontsize=7)
    fig.tight_layout()
    p1 = out / "compare_hysteresis.png"
    fig.savefig(p1, dpi=110)
    plt.close(fig)

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    w = slice(start, start + n_win)
    a1.plot(t[w], val.x[w], "k", lw=2, label="measured")
    a2.plot(t[rows_idx[sel]], val.data.torque[sel], "k", lw=2, label="measured")
    for r in fitted:
        a1.plot(t[w], r.curves["position_simulated"][w], lw=1, label=r.name)
        a2.plot(t[rows_idx[sel]], r.curves["torque_predicted"][sel], lw=1, label=r.name)
    a1.set_ylabel(f"position ({u[0]})")
    a1.set_title(f"{val.name}: segmented simulation (restart every {result.segment_s:g} s) and {u[2]}")
    a2.set_ylabel(f"filtered {u[2]} ({u[1]})")
    a2.set_xlabel("time (s)")
    a1.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    p2 = out / "compare_time.png"
    fig.savefig(p2, dpi=110)
    plt.close(fig)
    return [p1, p2]


def report(result: Comparison, out_dir: str | Path) -> list[Path]:
    """The comparison's report (:func:`hilbench.analysis.models.compare.analyse` is its front door): its figures,
    ``compare_hysteresis.png`` and ``compare_time.png``, in ``out_dir``."""
    return write_plots(result, out_dir)
