"""Drawing helpers shared by the figures: engineering units for axes (small values drawn in mrad, mN*m, mm or
micro-units instead of a bare SI unit with a ``1e-3`` multiplier in the corner, which a reader misses), plain
tick numbers, and gaps drawn as gaps. Drawing only: the numbers the analyses report stay SI.
"""

from __future__ import annotations

import numpy as np

#: (largest |value| below which the prefix applies, factor, prefix), smallest first
_PREFIXES = ((1e-4, 1e6, "µ"), (0.1, 1e3, "m"))


def engineering(unit: str, values) -> tuple[float, str]:
    """``(factor, unit)`` to draw ``values`` (in ``unit``) with: ``factor * values`` in the returned unit, e.g.
    ``(1000.0, 'mrad')`` for positions below 0.1 rad. The prefix goes on the first factor of a compound unit
    (``N*m`` -> ``mN*m``, ``rad/s`` -> ``mrad/s``). Units that already carry a prefix or are dimensionless
    (``1``, ``%``, ``Hz``, ``s``) are left alone (s: a time axis reads in seconds everywhere)."""
    v = np.asarray(values, float)
    v = np.abs(v[np.isfinite(v)])
    if not v.size or not unit or unit[0] not in "rNm" or unit.startswith("mm") or unit.startswith("mN"):
        return 1.0, unit
    if unit.startswith("mrad"):
        return 1.0, unit
    peak = float(v.max())
    if peak == 0.0:
        return 1.0, unit
    for below, factor, prefix in _PREFIXES:
        if peak < below:
            return factor, prefix + unit
    return 1.0, unit


def plain_numbers(ax) -> None:
    """No offset (``+1.2e3``) or multiplier (``1e-3``) text on a linear axis of ``ax``: the tick labels carry
    the whole value."""
    for axis in ("x", "y"):
        try:
            ax.ticklabel_format(axis=axis, style="plain", useOffset=False)
        except AttributeError:  # a log or categorical axis has no ScalarFormatter
            pass


def with_gaps(x: np.ndarray, *ys: np.ndarray, factor: float = 1.8, log: bool = True) -> list[np.ndarray]:
    """``x`` and ``ys`` with a NaN row inserted wherever a step of ``x`` exceeds ``factor`` times the median step
    (of log x when ``log``), so a line through binned points breaks where bins are missing (e.g. between the
    amplitude ranges of two runs) instead of joining them with a straight segment. ``x`` sorted ascending."""
    x = np.asarray(x, float)
    ys = tuple(np.asarray(y, float) for y in ys)
    if x.size < 3:
        return [x, *ys]
    step = np.diff(np.log(x) if log else x)
    gaps = np.flatnonzero(step > factor * np.median(step)) + 1
    return [np.insert(x, gaps, np.nan), *[np.insert(y, gaps, np.nan) for y in ys]]


def scaled_axis(axis, unit: str, values) -> str:
    """Label the ticks of a matplotlib ``axis`` (``ax.xaxis``/``ax.yaxis``) drawn in ``unit`` in the engineering
    unit :func:`engineering` picks for ``values``; returns that unit for the axis label. The data stay as they
    are: only the tick texts are scaled (no offset or multiplier text)."""
    from matplotlib.ticker import FuncFormatter

    factor, shown = engineering(unit, values)
    axis.set_major_formatter(FuncFormatter(lambda value, _pos: f"{value * factor:.6g}"))
    return shown
