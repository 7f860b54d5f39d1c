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
from hilbench.common.units import AXIS_UNITS as AXES

MEASURED = {"color": "0.15", "lw": 1.4}
#: dots per model in the whole-record panel of the hysteresis figure
MAX_DOTS = 3000
MODEL_STYLES = ({"color": "tab:orange", "lw": 1.0, "ls": "--"}, {"color": "tab:blue", "lw": 1.0, "ls": ":"})


def _figure(width: float, height: float, rows: int = 1, cols: int = 1, layout: str | None = None, **kw):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout=layout)
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
    models, all shape (n,) on the same rows; ``t`` (s) picks the zoom window (:func:`busiest_window`).

    Left, the whole record: thousands of overlaid cycles drawn as lines are a solid blot, so the measured friction
    is drawn as a sample density (grey, log scale) and each model as dots of at most MAX_DOTS samples, evenly
    spaced. Right, the window with the most reversals, every sample as lines."""
    from matplotlib.colors import LogNorm

    from hilbench.analysis.figure_style import engineering, plain_numbers

    x = np.asarray(position, float)
    y = np.asarray(measured, float)
    fx, xu = engineering(units["position"], x)
    fy, yu = engineering(units["torque"], np.r_[y, *[np.asarray(m, float) for _, m in models]])
    fig, ax = _figure(12, 5.0, 1, 2)
    ax = ax[0]
    t = np.arange(x.size, dtype=float) if t is None else np.asarray(t, float)
    i0, i1 = busiest_window(t, x, window)
    finite = np.isfinite(x) & np.isfinite(y)
    if finite.sum() > 1 and np.ptp(x[finite]) > 0 and np.ptp(y[finite]) > 0:
        ax[0].hist2d(fx * x[finite], fy * y[finite], bins=(100, 60), cmap="Greys", norm=LogNorm(), rasterized=True)
        ax[0].plot([], [], ls="none", marker="s", ms=7, color="0.45", label="measured: samples per cell (log)")
    # the models as dots of every step-th sample (at most MAX_DOTS): lines through thousands of cycles are a blot
    step = max(1, x.size // MAX_DOTS)
    for (label, m), style in zip(models, MODEL_STYLES, strict=False):
        ax[0].plot(fx * x[::step], fy * np.asarray(m, float)[::step], ls="none", marker=".", ms=1.5, alpha=0.35,
                   color=style["color"], rasterized=True, label=f"{label}, one sample in {step}" if step > 1 else
                   label)
    ax[0].set_title("whole record: measured as sample density (grey, log scale), model as dots", fontsize=9)
    sl = slice(i0, i1)
    ax[1].plot(fx * x[sl], fy * y[sl], label="measured (torque - J*acceleration)", **MEASURED)
    for (label, m), style in zip(models, MODEL_STYLES, strict=False):
        ax[1].plot(fx * x[sl], fy * np.asarray(m, float)[sl], label=label, **style)
    ax[1].set_title(f"t = {t[i0]:.3g} .. {t[i1 - 1]:.3g} s (the {window:g} s with the most reversals), every sample",
                    fontsize=9)
    for a in ax:
        a.set_xlabel(f"displacement ({xu})")
        a.set_ylabel(f"friction ({yu})")
        a.grid(True, alpha=0.3)
        plain_numbers(a)
        a.locator_params(axis="x", nbins=6)  # at most 7 ticks: signed labels such as "−0.75" touched at 9
    handles, labels = [], []
    for a in ax:
        h, lab = a.get_legend_handles_labels()
        handles += h
        labels += lab
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=9, frameon=False)
    fig.subplots_adjust(bottom=0.24, wspace=0.25)
    fig.suptitle(title)
    paths: list[Path] = []
    _save(fig, Path(path), paths)
    return paths[0]


def _identification_hysteresis(result: Identification, c: dict, u: dict, title: str, path: Path) -> Path:
    from hilbench.analysis.identification.regressors import filtered_data

    m, lip = result.model, result.lip
    t = np.asarray(c["t"], float)
    fs = (t.size - 1) / (t[-1] - t[0])
    # a held-out span was scored filtered together with the run before it (its lead): filter the same samples
    lead = np.asarray(c.get("lead_position", np.empty(0)), float)
    x = np.concatenate([lead, np.asarray(c["position"], float)])
    data = filtered_data(x, np.zeros(x.size), fs, lip.cutoff, order=lip.settings.order, decimation=lip.decimation,
                         timing=lip.settings.timing)
    span = data.rows >= lead.size
    position, acceleration = data.position[span], data.acceleration[span]
    if position.size != np.asarray(c["t_rows"]).size:  # the same filter on the same record gives the same rows
        raise ValueError("hysteresis rows do not match the fit rows")
    not_friction = m.inertia * acceleration + m.spring * position + m.offset
    measured = np.asarray(c["torque_filtered"]) - not_friction
    model = np.asarray(c["torque_predicted"]) - not_friction
    return hysteresis_figure(position, measured, [(f"model ({result.method})", model)], u, title, path,
                             t=np.asarray(c["t_rows"], float))


#: the figures of each run (``<role>_<figure>.png``) and of the model
RUN_FIGURES = ("fit", "residuals", "hysteresis")
MODEL_FIGURES = ("virgin_curve",)


def plot_files(directory: str | Path, roles: Sequence[str]) -> list[Path]:
    """Every file :func:`write_plots` writes into ``directory`` for runs of ``roles`` ("train", "validation"):
    known before the identification runs, so a command can refuse existing ones first."""
    out = Path(directory)
    return [out / f"{name}.png" for name in MODEL_FIGURES] + [out / f"{role}_{name}.png" for role in roles
                                                              for name in RUN_FIGURES]


def run_label(role: str, runs: dict[str, str | Path] | None) -> str:
    """How a figure title names a run: its file name and its role, ``id.h5 (train run)``; the role alone when
    the file is not known."""
    file = (runs or {}).get(role)
    return f"{Path(file).name} ({role} run)" if file else f"{role} run"


def write_plots(result: Identification, directory: str | Path, runs: dict[str, str | Path] | None = None) -> list[Path]:
    """Write the figures into ``directory`` (created); returns the file paths (:func:`plot_files`). ``runs``
    maps each role ("train", "validation") to its run file, which the titles name. Small values are drawn in
    engineering units (mrad, mN*m), legends sit outside the data."""
    from hilbench.analysis.figure_style import engineering, plain_numbers

    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    files = {p.stem: p for p in plot_files(out, list(result.curves))}
    m = result.model
    u = AXES[m.axis]
    paths: list[Path] = []

    lo = float(m.ms_delta.min()) / 10 if m.ms_delta.size else 1e-6
    hi = float(m.ms_delta.max()) * 3 if m.ms_delta.size else 1.0
    x = np.geomspace(lo, hi, 400)
    fx, xu = engineering(u["position"], x)
    fy, yu = engineering(u["torque"], m.virgin_curve(x))
    fig, ax = _figure(7, 4.5)
    ax = ax[0, 0]
    ax.semilogx(fx * x, fy * m.virgin_curve(x), "k", lw=2, label="virgin curve")
    for i, curve in enumerate(m.element_curves(x).T):
        ax.semilogx(fx * x, fy * curve, lw=0.8, label=f"{m.ms_delta.size} elements" if i == 0 else None)
    ax.set_xlabel(f"displacement from reversal / 2 ({xu})")
    ax.set_ylabel(f"friction ({yu})")
    ax.set_title(f"Identified virgin curve ({m.ms_delta.size} elements, {result.method}), from "
                 f"{run_label('train', runs)}")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    _save(fig, files["virgin_curve"], paths)

    for prefix, c in result.curves.items():
        label = run_label(prefix, runs)
        t_rows = np.asarray(c["t_rows"], float)
        meas, pred = np.asarray(c["torque_filtered"]), np.asarray(c["torque_predicted"])
        i0, i1 = busiest_window(t_rows, np.asarray(c["position"])[np.searchsorted(c["t"], t_rows)], 2.0)
        ft, tu = engineering(u["torque"], meas)
        fp, pu = engineering(u["position"], c["position"])
        fig, axes = _figure(11, 8.5, 3, 1)
        axes = axes[:, 0]
        zoom = slice(i0, i1)
        axes[0].plot(t_rows[zoom], ft * meas[zoom], label="measured (filtered)", **MEASURED)
        axes[0].plot(t_rows[zoom], ft * pred[zoom], label="model", **MODEL_STYLES[0])
        axes[0].set_ylabel(f"torque ({tu})")
        axes[0].set_title(f"{label}: torque, {t_rows[i0]:.3g} .. {t_rows[i1 - 1]:.3g} s (the window with the "
                          "most reversals)", fontsize=10)
        err = meas - pred
        fe, eu = engineering(u["torque"], err)
        rms = float(np.sqrt(np.mean(err**2)))
        axes[1].plot(t_rows, fe * err, color="0.35", lw=0.5, label="measured - model")
        axes[1].axhline(fe * rms, color="tab:red", lw=0.8, ls="--", label=f"+-rms {fe * rms:.3g} {eu}")
        axes[1].axhline(-fe * rms, color="tab:red", lw=0.8, ls="--")
        axes[1].axvspan(t_rows[i0], t_rows[i1 - 1], color="tab:orange", alpha=0.12)
        axes[1].set_ylabel(f"torque error ({eu})")
        axes[1].set_title("equation error over the whole run (shaded: the window above)", fontsize=10)
        axes[2].plot(c["t"], fp * np.asarray(c["position"]), label="measured", **MEASURED)
        axes[2].plot(c["t"], fp * np.asarray(c["position_sim"]), label="simulated (open loop)", **MODEL_STYLES[0])
        axes[2].set_ylabel(f"position ({pu})")
        axes[2].set_title("simulation error: the model driven by the measured torque", fontsize=10)
        for a in axes:
            a.set_xlabel("time (s)")
            a.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
            a.grid(True, alpha=0.3)
            plain_numbers(a)
        fig.tight_layout()
        _save(fig, files[f"{prefix}_fit"], paths)

        # constrained layout: the right panel's y label keeps clear of the left panel's ticks
        fig, axes = _figure(10, 3.8, 1, 2, layout="constrained")
        axes = axes[0]
        axes[0].hist(fe * err, bins=80, color="0.3")
        axes[0].set_xlabel(f"torque residual, measured - model ({eu})")
        perr = np.asarray(c["position"]) - np.asarray(c["position_sim"])
        fq, qu = engineering(u["position"], perr)
        axes[1].hist(fq * perr, bins=80, color="0.3")
        axes[1].set_xlabel(f"position residual, measured - simulated ({qu})")
        for a in axes:
            a.set_ylabel("count (samples)")
            plain_numbers(a)
        fig.suptitle(f"{label}: residual histograms")
        _save(fig, files[f"{prefix}_residuals"], paths)

        paths.append(_identification_hysteresis(
            result, c, u, f"{label}: friction against displacement, measured and model",
            files[f"{prefix}_hysteresis"]))
    return paths
