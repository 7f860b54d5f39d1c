"""One look for every plot of the GUI (the live plots, the campaign results): a white background, black legend
text, and axes that say their unit in their label only (pyqtgraph's automatic SI prefix would add "(x0.001)")."""

from __future__ import annotations

import pyqtgraph as pg

BACKGROUND = "w"
LEGEND_TEXT = "k"


def style_view(view: pg.GraphicsView) -> pg.GraphicsView:
    """The white background of every plot area (pyqtgraph's default is black)."""
    view.setBackground(BACKGROUND)
    return view


def style_plot(plot: pg.PlotItem) -> pg.PlotItem:
    """Axes without pyqtgraph's automatic SI prefix: the unit is the label's, engineering units are scaled by
    the caller (analysis/figure_style.py)."""
    for side in ("left", "bottom"):
        plot.getAxis(side).enableAutoSIPrefix(False)
    return plot


def add_legend(plot: pg.PlotItem) -> pg.LegendItem:
    """A legend in the plot's top-left corner, its text readable on the white background."""
    return plot.addLegend(offset=(5, 5), labelTextColor=LEGEND_TEXT)
