"""Readability checks on every matplotlib figure a command saves: each axis that shows tick labels has a
label naming a unit in parentheses, e.g. ``torque (N*m)`` or ``count (samples)``; no legend is empty.

Use :func:`recording_figures` around a command: it wraps ``Figure.savefig``, lets the figure draw, then checks
the drawn figure (tick labels exist only after a draw)."""

from __future__ import annotations

import contextlib
import re
from pathlib import Path

from matplotlib.figure import Figure

UNIT = re.compile(r"\(([^()]+)\)\s*$|\[([^\[\]]+)\]\s*$")


def _has_data(ax) -> bool:
    return bool(ax.lines or ax.collections or ax.images or ax.patches or ax.containers)


def _shows_ticks(labels) -> bool:
    return any(t.get_visible() and t.get_text().strip() for t in labels)


def figure_problems(fig: Figure) -> list[str]:
    """What is unreadable in a drawn ``fig``: unlabeled axes, labels without a unit, empty legends."""
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
def recording_figures():
    """Yield a dict file name -> problems, filled by every ``Figure.savefig`` inside the block."""
    seen: dict[str, list[str]] = {}
    original = Figure.savefig

    def savefig(self, fname, *args, **kwargs):
        result = original(self, fname, *args, **kwargs)
        name = Path(str(fname)).name
        # bench.storage.outputs writes through a temporary '.<name>.<random>.tmp.png'; report the real name
        match = re.match(r"^\.(.+?)\.[^.]+\.tmp\.[a-z]+$", name)
        seen[match.group(1) if match else name] = figure_problems(self)
        return result

    Figure.savefig = savefig
    try:
        yield seen
    finally:
        Figure.savefig = original
