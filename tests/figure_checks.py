"""Readability checks on every matplotlib figure a command saves: each axis that shows tick labels has a
label naming a unit in parentheses, e.g. ``torque (N*m)`` or ``count (samples)``; no legend is empty; no two
tick labels of one axis overlap; no axis carries a matplotlib offset or multiplier text (``1e-3``, ``+0.2``):
the values are scaled to an engineering unit instead (mrad, mN*m); a legend inside an axes covers few of its
data points (:func:`legend_cover`).

Use :func:`recording_figures` around a command: it wraps ``Figure.savefig``, lets the figure draw, then checks
the drawn figure (tick labels exist only after a draw)."""

from __future__ import annotations

import contextlib
import re
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

UNIT = re.compile(r"\(([^()]+)\)\s*$|\[([^\[\]]+)\]\s*$")


def _has_data(ax) -> bool:
    return bool(ax.lines or ax.collections or ax.images or ax.patches or ax.containers)


def _shows_ticks(labels) -> bool:
    return any(t.get_visible() and t.get_text().strip() for t in labels)


def _overlapping(labels, axis: str) -> list[tuple[str, str]]:
    """Pairs of visible, non-empty tick labels whose drawn boxes overlap (by more than one pixel)."""
    boxes = [(t.get_text(), t.get_window_extent()) for t in labels if t.get_visible() and t.get_text().strip()]
    pairs = []
    for i, (ta, a) in enumerate(boxes):
        for tb, b in boxes[i + 1:]:
            dx = min(a.x1, b.x1) - max(a.x0, b.x0)
            dy = min(a.y1, b.y1) - max(a.y0, b.y0)
            if dx > 1 and dy > 1:
                pairs.append((ta, tb))
    return pairs


def tick_label_overlaps(ax) -> list[str]:
    """Overlapping tick labels of ``ax`` (major and minor together), as 'x: 'a' and 'b'' lines."""
    out = []
    for name, axis in (("x", ax.xaxis), ("y", ax.yaxis)):
        labels = [*axis.get_ticklabels(which="major"), *axis.get_ticklabels(which="minor")]
        out += [f"{name}: tick labels {a!r} and {b!r} overlap" for a, b in _overlapping(labels, name)]
    return out


def legend_cover(ax) -> float:
    """Fraction of the finite line and scatter points of ``ax`` (inside its view) that its legend box covers."""
    leg = ax.get_legend()
    if leg is None or not leg.get_visible():
        return 0.0
    box = leg.get_window_extent()
    points = [line.get_xydata() for line in ax.get_lines() if line.get_visible()]
    points += [c.get_offsets() for c in ax.collections if c.get_visible() and len(c.get_offsets())]
    if not points:
        return 0.0
    xy = np.concatenate([np.asarray(p, float).reshape(-1, 2) for p in points])
    xy = xy[np.isfinite(xy).all(axis=1)]
    (x0, x1), (y0, y1) = sorted(ax.get_xlim()), sorted(ax.get_ylim())
    xy = xy[(xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)]
    if not xy.size:
        return 0.0
    d = ax.transData.transform(xy)
    inside = (d[:, 0] >= box.x0) & (d[:, 0] <= box.x1) & (d[:, 1] >= box.y0) & (d[:, 1] <= box.y1)
    return float(inside.mean())


#: a legend inside the axes may cover at most this fraction of the data points
LEGEND_COVER = 0.02


def figure_problems(fig: Figure) -> list[str]:
    """What is unreadable in a drawn ``fig``: unlabeled axes, labels without a unit, empty legends, overlapping
    tick labels, offset/multiplier texts, legends over the data."""
    problems = []
    for i, ax in enumerate(fig.axes):
        if not ax.get_visible() or not ax.axison:
            continue
        where = f"axes {i} ({ax.get_title() or 'untitled'})"
        colorbar = ax.get_label() == "<colorbar>"
        if not colorbar and not _has_data(ax) and not ax.texts:
            continue
        for name, axis, label, ticks in (("x", ax.xaxis, ax.get_xlabel(), ax.get_xticklabels()),
                                         ("y", ax.yaxis, ax.get_ylabel(), ax.get_yticklabels())):
            if not axis.get_visible() or not _shows_ticks(ticks):  # e.g. the hidden x axis of a twinx
                continue
            if not label.strip():
                problems.append(f"{where}: {name} axis has tick labels but no label")
            elif not UNIT.search(label.strip()):
                problems.append(f"{where}: {name} label {label!r} names no unit in parentheses")
        problems += [f"{where}: {p}" for p in tick_label_overlaps(ax)]
        for name, axis in (("x", ax.xaxis), ("y", ax.yaxis)):
            offset = axis.get_offset_text()
            if axis.get_visible() and offset.get_visible() and offset.get_text().strip():
                problems.append(f"{where}: {name} axis shows the offset/multiplier {offset.get_text()!r}; "
                                "scale the values to an engineering unit instead")
        cover = legend_cover(ax)
        if cover > LEGEND_COVER:
            problems.append(f"{where}: the legend covers {100 * cover:.0f} % of the data points")
        legends = [ax.get_legend()] if ax.get_legend() is not None else []
        for leg in legends:
            texts = [t.get_text().strip() for t in leg.get_texts()]
            if not texts or not all(texts):
                problems.append(f"{where}: empty legend or legend entry {texts}")
    for leg in fig.legends:
        texts = [t.get_text().strip() for t in leg.get_texts()]
        if not texts or not all(texts):
            problems.append(f"figure legend: empty legend or entry {texts}")
    return problems


@contextlib.contextmanager
def recording_figures(figures: dict | None = None):
    """Yield a dict file name -> problems, filled by every ``Figure.savefig`` inside the block; ``figures``, when
    given, receives file name -> the Figure itself (for checks of its content)."""
    seen: dict[str, list[str]] = {}
    original = Figure.savefig

    def savefig(self, fname, *args, **kwargs):
        result = original(self, fname, *args, **kwargs)
        name = Path(str(fname)).name
        # bench.storage.outputs writes through a temporary '.<name>.<random>.tmp.png'; report the real name
        match = re.match(r"^\.(.+?)\.[^.]+\.tmp\.[a-z]+$", name)
        key = match.group(1) if match else name
        seen[key] = figure_problems(self)
        if figures is not None:
            figures[key] = self
        return result

    Figure.savefig = savefig
    try:
        yield seen
    finally:
        Figure.savefig = original
