"""PNG plots of an identification: virgin curve and elements, measured against model torque and position, the
friction-displacement hysteresis, residual histograms. Matplotlib (Agg canvas, no pyplot state), one file per
figure, a unit on every axis, each file replaced atomically.

The hysteresis figure (:func:`hysteresis_figure`) is shared with ``hilbench residual``: friction against
displacement, measured against model, over the whole record (left) and over the window with the most
reversals (right), where presliding loops are visible.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from hilbench.analysis.identification.identify import Identification
from hilbench.analysis.models.friction_model import AXES

MEASURED = {"color": "0.15", "lw": 1.4}
MODEL_STYLES = ({"color": "tab:orange", "lw": 1.0, "ls": "--"}, {"color": "tab:blue", "lw": 1.0, "ls": ":"})


def _figure(width: float, height: float, rows: int = 1, cols: int = 1, **kw):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    return fig, fig.subplots(rows, cols, squeeze=False, **kw)


def _save(fig, path: Path, paths: list[Path], dpi: int = 110) -> None:
    from hilbench.analysis.output_files import save_figure

    save_figure(fig, path, dpi=dpi, bbox_inches="tight")
    paths.append(path)


def busiest_window(t: np.ndarray, x: np.ndarray, length: float) -> tuple[int, int]:
    """Index range [i0, i1) of the ``length``-second window of ``t`` with the most direction reversals of
    ``x`` (steps of the grid of a quarter window); the whole record if it is shorter."""
    t = np.asarray(t, float)
    x = np.asarray(x, float)
    if t.size < 3 or t[-1] - t[0] <= length:
        return 0, t.size
    dx = np.diff(x)
    moving = np.flatnonzero(dx != 0)
    rev = np.zeros(t.size, int)
    if moving.size > 1:
        s = np.sign(dx[moving])
        rev[moving[1:][s[1:] != s[:-1]]] = 1
    cum = np.concatenate([[0], np.cumsum(rev)])
    starts = np.arange(t[0], t[-1] - length, length / 4)
    i0 = np.searchsorted(t, starts)
    i1 = np.searchsorted(t, starts + length)
    best = int(np.argmax(cum[i1] - cum[i0]))
    return int(i0[best]), int(i1[best])


def hysteresis_figure(position: np.ndarray, measured: np.ndarray, models: Sequence[tuple[str, np.ndarray]],
                      units: dict, title: str, path: str | Path, t: np.ndarray | None = None,
                      window: float = 1.0) -> Path:
    """Friction (``units['torque']``) against displacement (``units['position']``), measured against one or two
    models, all shape (n,) on the same rows; ``t`` (s) picks the zoom window (:func:`busiest_window`)."""
    x = np.asarray(position, float)
    fig, ax = _figure(12, 4.6, 1, 2)
    ax = ax[0]
    t = np.arange(x.size, dtype=float) if t is None else np.asarray(t, float)
    i0, i1 = busiest_window(t, x, window)
    for a, sl, what, lw in ((ax[0], slice(None), "whole record", 0.5),
                            (ax[1], slice(i0, i1), f"t = {t[i0]:.3g} .. {t[i1 - 1]:.3g} s (most reversals)", 1.0)):
        a.plot(x[sl], np.asarray(measured, float)[sl], label="measured (torque - J*acceleration)",
               **{**MEASURED, "lw": 1.4 * lw})
        for (label, y), style in zip(models, MODEL_STYLES, strict=False):
            a.plot(x[sl], np.asarray(y, float)[sl], label=label, **{**style, "lw": lw})
        a.set_xlabel(f"displacement ({units['position']})")
        a.set_ylabel(f"friction ({units['torque']})")
        a.set_title(what, fontsize=10)
        a.grid(True, alpha=0.3)
    handles, labels = ax[1].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=9, frameon=False)
    fig.subplots_adjust(bottom=0.2)
    fig.suptitle(title)
    paths: list[Path] = []
    _save(fig, Path(path), paths)
    return paths[0]


def _identification_hysteresis(result: Identification, c: dict, u: dict, title: str, path: Path) -> Path:
    from hilbench.analysis.identification.regressors import filtered_data

    m, lip = result.model, result.lip
    t = np.asarray(c["t"], float)
    fs = (t.size - 1) / (t[-1] - t[0])
    data = filtered_data(np.asarray(c["position"], float), np.zeros(t.size), fs, lip.cutoff,
                         order=lip.settings.order, decimation=lip.decimation, timing=lip.settings.timing)
    if data.rows.size != np.asarray(c["t_rows"]).size:  # the same filter on the same record gives the same rows
        raise ValueError("hysteresis rows do not match the fit rows")
    not_friction = m.inertia * data.acceleration + m.spring * data.position + m.offset
    measured = np.asarray(c["torque_filtered"]) - not_friction
    model = np.asarray(c["torque_predicted"]) - not_friction
    return hysteresis_figure(data.position, measured, [(f"model ({result.method})", model)], u, title, path,
                             t=np.asarray(c["t_rows"], float))


def write_plots(result: Identification, directory: str | Path) -> list[Path]:
    """Write the figures into ``directory`` (created); returns the file paths."""
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    m = result.model
    u = AXES[m.axis]
    paths: list[Path] = []

    lo = float(m.ms_delta.min()) / 10 if m.ms_delta.size else 1e-6
    hi = float(m.ms_delta.max()) * 3 if m.ms_delta.size else 1.0
    x = np.geomspace(lo, hi, 400)
    fig, ax = _figure(7, 4.5)
    ax = ax[0, 0]
    ax.semilogx(x, m.virgin_curve(x), "k", lw=2, label="virgin curve")
    for i, curve in enumerate(m.element_curves(x).T):
        ax.semilogx(x, curve, lw=0.8, label=f"{m.ms_delta.size} elements" if i == 0 else None)
    ax.set_xlabel(f"displacement from reversal / 2 ({u['position']})")
    ax.set_ylabel(f"friction ({u['torque']})")
    ax.set_title(f"Identified virgin curve ({m.ms_delta.size} elements, {result.method})")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    _save(fig, out / "virgin_curve.png", paths)

    for prefix, c in result.curves.items():
        t_rows = np.asarray(c["t_rows"], float)
        meas, pred = np.asarray(c["torque_filtered"]), np.asarray(c["torque_predicted"])
        i0, i1 = busiest_window(t_rows, np.asarray(c["position"])[np.searchsorted(c["t"], t_rows)], 2.0)
        fig, axes = _figure(10, 8.5, 3, 1)
        axes = axes[:, 0]
        zoom = slice(i0, i1)
        axes[0].plot(t_rows[zoom], meas[zoom], label="measured (filtered)", **MEASURED)
        axes[0].plot(t_rows[zoom], pred[zoom], label="model", **MODEL_STYLES[0])
        axes[0].set_ylabel(f"torque ({u['torque']})")
        axes[0].set_title(f"{prefix} run: torque, {t_rows[i0]:.3g} .. {t_rows[i1 - 1]:.3g} s (the window with the "
                          "most reversals)", fontsize=10)
        err = meas - pred
        rms = float(np.sqrt(np.mean(err**2)))
        axes[1].plot(t_rows, err, color="0.35", lw=0.5, label="measured - model")
        axes[1].axhline(rms, color="tab:red", lw=0.8, ls="--", label=f"+-rms {rms:.3g} {u['torque']}")
        axes[1].axhline(-rms, color="tab:red", lw=0.8, ls="--")
        axes[1].axvspan(t_rows[i0], t_rows[i1 - 1], color="tab:orange", alpha=0.12)
        axes[1].set_ylabel(f"torque error ({u['torque']})")
        axes[1].set_title("equation error over the whole run (shaded: the window above)", fontsize=10)
        axes[2].plot(c["t"], c["position"], label="measured", **MEASURED)
        axes[2].plot(c["t"], c["position_sim"], label="simulated (open loop)", **MODEL_STYLES[0])
        axes[2].set_ylabel(f"position ({u['position']})")
        axes[2].set_title("simulation error: the model driven by the measured torque", fontsize=10)
        for a in axes:
            a.set_xlabel("time (s)")
            a.legend(loc="upper right", fontsize=8)
            a.grid(True, alpha=0.3)
        fig.tight_layout()
        _save(fig, out / f"{prefix}_fit.png", paths)

        fig, axes = _figure(9, 3.5, 1, 2)
        axes = axes[0]
        axes[0].hist(err, bins=80, color="0.3")
        axes[0].set_xlabel(f"torque residual ({u['torque']})")
        axes[1].hist(np.asarray(c["position"]) - np.asarray(c["position_sim"]), bins=80, color="0.3")
        axes[1].set_xlabel(f"position residual ({u['position']})")
        for a in axes:
            a.set_ylabel("count (samples)")
        fig.suptitle(f"{prefix} residuals")
        _save(fig, out / f"{prefix}_residuals.png", paths)

        paths.append(_identification_hysteresis(
            result, c, u, f"{prefix} run: friction against displacement, measured and model",
            out / f"{prefix}_hysteresis.png"))
    return paths
