"""PNG plots of an identification: virgin curve and elements, measured vs predicted torque and
position, residual histograms. Matplotlib (Agg), one file per figure, units on every axis."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hilbench.analysis.identification.identify import Identification
from hilbench.analysis.models.friction_model import AXES


def write_plots(result: Identification, directory: str | Path) -> list[Path]:
    """Write the figures into ``directory`` (created); returns the file paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    m = result.model
    u = AXES[m.axis]
    paths = []

    lo = float(m.ms_delta.min()) / 10 if m.ms_delta.size else 1e-6
    hi = float(m.ms_delta.max()) * 3 if m.ms_delta.size else 1.0
    x = np.geomspace(lo, hi, 400)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.semilogx(x, m.virgin_curve(x), "k", lw=2, label="virgin curve")
    for i, curve in enumerate(m.element_curves(x).T):
        ax.semilogx(x, curve, lw=0.8, label="elements" if i == 0 else None)
    ax.set_xlabel(f"displacement from reversal / 2 ({u['position']})")
    ax.set_ylabel(f"friction ({u['torque']})")
    ax.set_title(f"Identified virgin curve ({m.ms_delta.size} elements, {result.method})")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    paths.append(out / "virgin_curve.png")
    fig.savefig(paths[-1], dpi=110, bbox_inches="tight")
    plt.close(fig)

    for prefix, c in result.curves.items():
        fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
        axes[0].plot(c["t_rows"], c["torque_filtered"], "k", lw=0.8, label="measured (filtered)")
        axes[0].plot(c["t_rows"], c["torque_predicted"], "r", lw=0.6, label="predicted")
        axes[0].set_ylabel(f"torque ({u['torque']})")
        axes[0].legend(loc="upper right")
        axes[1].plot(c["t"], c["position"], "k", lw=0.8, label="measured")
        axes[1].plot(c["t"], c["position_sim"], "r", lw=0.6, label="simulated")
        axes[1].set_ylabel(f"position ({u['position']})")
        axes[1].set_xlabel("time (s)")
        axes[1].legend(loc="upper right")
        axes[0].set_title(f"{prefix} run: equation error (top), simulation error (bottom)")
        paths.append(out / f"{prefix}_fit.png")
        fig.savefig(paths[-1], dpi=110, bbox_inches="tight")
        plt.close(fig)

        fig, axes = plt.subplots(1, 2, figsize=(9, 3.5))
        axes[0].hist(c["torque_filtered"] - c["torque_predicted"], bins=80, color="0.3")
        axes[0].set_xlabel(f"torque residual ({u['torque']})")
        axes[1].hist(c["position"] - c["position_sim"], bins=80, color="0.3")
        axes[1].set_xlabel(f"position residual ({u['position']})")
        for a in axes:
            a.set_ylabel("count")
        fig.suptitle(f"{prefix} residuals")
        paths.append(out / f"{prefix}_residuals.png")
        fig.savefig(paths[-1], dpi=110, bbox_inches="tight")
        plt.close(fig)
    return paths
