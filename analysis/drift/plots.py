"""Figures of a drift result: each parameter against run time, cumulative distance and temperature, and its
control charts (matplotlib, Agg; units on every axis)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from hilbench.analysis.drift.monitor import DriftReport, DriftResult
from hilbench.common.units import axis_unit

#: axis labels of the covariates the monitor knows (name -> label with unit)
COVARIATE_LABELS = {"temperature_mean": "winding temperature (degC)", "load": "load (kg)"}


def time_axis(hours: np.ndarray) -> tuple[np.ndarray, str]:
    """Run start times in the unit that reads best over their span: s, min, h or days (values, axis label)."""
    span = float(np.nanmax(hours)) if np.size(hours) else 0.0
    for limit, factor, unit in ((2 / 60, 3600.0, "s"), (2.0, 60.0, "min"), (72.0, 1.0, "h")):
        if span < limit:
            return np.asarray(hours) * factor, f"run start ({unit} since the first run)"
    return np.asarray(hours) / 24.0, "run start (days since the first run)"


def _shade(ax, x: np.ndarray, base: np.ndarray) -> None:
    if base.any():
        ax.axvspan(np.nanmin(x[base]), np.nanmax(x[base]), color="0.9", zorder=0, label="baseline")


def drift_figure(result: DriftResult, name: str, unit: str):
    """Parameter +- standard error against run time, cumulative sliding distance and temperature."""
    import matplotlib.pyplot as plt

    s = result.series[name]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), constrained_layout=True)
    xs = [time_axis(result.hours),
          (result.distance, f"cumulative sliding distance ({axis_unit('position', result.axis)})")]
    temp = result.covariate_values.get("temperature_mean")
    if temp is not None and np.all(np.isfinite(temp)):
        xs.append((temp, COVARIATE_LABELS["temperature_mean"]))
    for ax, (x, label) in zip(axes, xs, strict=False):
        against_time = label != COVARIATE_LABELS["temperature_mean"]
        if against_time:
            _shade(ax, x, result.baseline)
        ax.errorbar(x, s.value, yerr=np.nan_to_num(s.se), fmt=".", ms=3, lw=0.6, color="C0", ecolor="0.6",
                    label=f"{s.parameter} +- standard error")
        for i in s.change_points if against_time else []:
            ax.axvline(x[i], color="C3", lw=1, ls="--", label="change point")
        ax.set_xlabel(label)
        ax.set_ylabel(f"{s.parameter} ({unit})")
    if len(xs) == 3:
        t = xs[2][0]
        order = np.argsort(t)
        ax = axes[2]
        c = s.covariates.get("temperature_mean", {})
        if "coefficient" in c:
            mean_b = float(np.mean(s.value[result.baseline]))
            ax.plot(t[order], mean_b + c["coefficient"] * (t[order] - c["centre"]), color="C1",
                    label=f"baseline fit {c['coefficient']:.3g} +- {c['se']:.2g} {unit}/K")
    else:
        axes[2].set_visible(False)
    for ax in axes:
        handles, labels = ax.get_legend_handles_labels()
        uniq = dict(zip(labels, handles, strict=True))
        if uniq:
            ax.legend(uniq.values(), uniq.keys(), fontsize=7, loc="best")
    fig.suptitle(f"{name} over {len(result.runs)} runs")
    return fig


def charts_figure(result: DriftResult, name: str):
    """Standardised residual with change points, EWMA with its limits, CUSUM with its decision interval."""
    import matplotlib.pyplot as plt

    s = result.series[name]
    st = result.settings
    n = np.arange(len(result.runs))
    fig, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True, constrained_layout=True)
    ax = axes[0]
    _shade(ax, n, result.baseline)
    ax.plot(n, s.z, ".", ms=3, color="C0", label="score (residual / its standard error)")
    for j, i in enumerate(s.outliers):
        ax.plot(i, s.z[i], "o", mfc="none", color="C3", ms=7,
                label=None if j else f"outlier (|z| > {s.limits.outlier:.2g})")
    for i in s.change_points:
        ax.axvline(i, color="C3", ls="--", lw=1, label=f"change point at {result.runs[i]}")
    ax.set_ylabel(f"z (1 = {s.sigma:.3g})")
    ax.legend(fontsize=7, loc="upper left")
    ax = axes[1]
    ax.plot(n, s.ewma, color="C0", label=f"EWMA (lambda {st.ewma_lambda:g})")
    ax.plot(n, s.ewma_limit, color="C3", lw=0.8, label=f"+-{s.limits.ewma:.3g} sigma limits (calibrated)")
    ax.plot(n, -s.ewma_limit, color="C3", lw=0.8)
    for i in s.ewma_alarms:
        ax.plot(i, s.ewma[i], "v", color="C3")
    ax.set_ylabel("EWMA of z (1)")
    ax.legend(fontsize=7, loc="upper left")
    ax = axes[2]
    ax.plot(n, s.cusum_hi, color="C0", label=f"C+ (k {st.cusum_k:g})")
    ax.plot(n, s.cusum_lo, color="C2", label="C-")
    ax.axhline(s.cusum_h, color="C3", lw=0.8, label=f"h = {s.cusum_h:.3g} (calibrated)")
    for i in s.cusum_alarms:
        ax.plot(i, max(s.cusum_hi[i], s.cusum_lo[i]), "v", color="C3")
    ax.set_ylabel("CUSUM of z (1)")
    ax.set_xlabel("run (start-time order)")
    ax.legend(fontsize=7, loc="upper left")
    fig.suptitle(f"{name}: control charts on the residual after the covariate fit (false alarms per campaign "
                 f"<= {100 * st.false_alarm:g} %)")
    return fig


def _file_part(label: str) -> str:
    """A series label as a file-name part: each run of other characters than letters, digits and ``_`` is one
    ``-`` (``breakaway [identification]`` -> ``breakaway-identification``)."""
    return re.sub(r"\W+", "-", label).strip("-")


def write_figures(report: DriftReport, units: dict[str, dict[str, str]], out: Path, save) -> list[Path]:
    """Both figures of every series as PNG into ``out`` via ``save(fig, path)``; returns the paths. ``units``: axis
    (``rotary``, ``linear``) -> column -> unit (the results table's metadata on that axis,
    hilbench.common.units.schema_units); each series reads the units of its runs' axis."""
    import matplotlib.pyplot as plt

    paths = []
    for result in report.groups:
        for name, s in result.series.items():
            unit = units[result.axis].get(s.parameter, "")
            for kind, fig in (("drift", drift_figure(result, name, unit)),
                              ("charts", charts_figure(result, name))):
                path = out / f"{kind}-{_file_part(name)}.png"
                save(fig, path)
                plt.close(fig)
                paths.append(path)
    return paths
