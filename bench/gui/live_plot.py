"""Live plots of current, torque, position and velocity with a rolling window.

Blocks go into a :class:`~bench.gui.display_buffer.RingBuffer` as they arrive (cheap copies); a QTimer
redraws at ``fps`` Hz from a min/max decimation per pixel column, so drawing cost depends on the plot
width, not on the sample rate. Pause freezes the view on a snapshot while acquisition continues; zooming a
paused view re-decimates the visible span of the snapshot at full resolution.
"""

from __future__ import annotations

import time

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtWidgets

from hilbench.analysis.figure_style import engineering
from hilbench.bench.gui.display_buffer import RingBuffer, minmax_decimate
from hilbench.bench.gui.plot_style import add_legend, style_plot, style_view
from hilbench.common.units import AXIS_UNITS

#: a setpoint: grey and dashed, drawn under the measured trace (a colour and a line style of its own)
SETPOINT = {"color": "#7f7f7f", "width": 1.5, "style": QtCore.Qt.PenStyle.DashLine}

#: a device streams at its (rotary) load: the live panels' units
ROTARY = AXIS_UNITS["rotary"]
#: (plot title, SI unit, [(channel, pen, legend name or None), ...]); the position setpoint comes only from a
#: position-mode run (it is NaN, and not drawn, otherwise)
PANELS = (
    ("current", "A", (("current_cmd", SETPOINT, "setpoint"),
                      ("current_meas", {"color": "#1f77b4", "width": 1}, "measured"))),
    ("torque", ROTARY["torque"], (("torque", {"color": "#d62728", "width": 1}, None),)),
    ("position", ROTARY["position"], (("position_cmd", SETPOINT, "setpoint"),
                         ("position", {"color": "#2ca02c", "width": 1}, "measured"))),
    ("velocity", ROTARY["velocity"], (("velocity", {"color": "#9467bd", "width": 1}, None),)),
)
CHANNELS = tuple(name for _, _, traces in PANELS for name, _, _ in traces)


class LivePlot(QtWidgets.QWidget):
    """Four stacked, x-linked plots fed by :meth:`append`; redrawn by a timer.

    Args:
        window: rolling window shown, s.
        sample_rate: expected sample rate, Hz (sizes the ring buffer: ``max_window * sample_rate``).
        fps: redraw rate, Hz.
        decimate: min/max decimation per pixel column (off only for the benchmark's baseline).
    """

    frame_drawn = QtCore.Signal()

    def __init__(self, parent: QtWidgets.QWidget | None = None, *, window: float = 10.0,
                 sample_rate: float = 20000.0, fps: float = 40.0, max_window: float = 60.0,
                 decimate: bool = True) -> None:
        super().__init__(parent)
        self.decimate = decimate
        self.max_window = max_window
        self.buffer = RingBuffer(CHANNELS, int(max_window * sample_rate))
        self.frames = 0
        self._dirty = False
        self._paused = False
        self._frozen: tuple[np.ndarray, np.ndarray] | None = None
        self._period = 1.0 / sample_rate  # s, learned from the blocks

        self.graphics = style_view(pg.GraphicsLayoutWidget())
        self.plots: list[pg.PlotItem] = []
        self.curves: dict[str, pg.PlotDataItem] = {}
        self._legends: dict[str, pg.LegendItem] = {}  # channel -> the legend of its panel
        for row, (title, unit, traces) in enumerate(PANELS):
            plot = style_plot(self.graphics.addPlot(row=row, col=0))
            plot.setLabel("left", title, units=None)
            plot.getAxis("left").setLabel(f"{title} ({unit})")
            # no grid: an AxisItem with grid lines spans the plot area, so every curve update would repaint
            # (and re-render the tick labels of) all axes
            plot.setClipToView(True)
            if row:
                plot.setXLink(self.plots[0])
            if row < len(PANELS) - 1:
                plot.hideAxis("bottom")
            plot.getAxis("left").setWidth(70)  # fixed: a new tick label width never re-lays out the plots
            plot.disableAutoRange()
            legend_item = add_legend(plot) if len(traces) > 1 else None
            for name, pen, legend in traces:
                self.curves[name] = plot.plot(pen=pg.mkPen(**pen), name=legend)
                if legend_item is not None:
                    self._legends[name] = legend_item
            self.plots.append(plot)
        self.plots[-1].setLabel("bottom", "time before the newest sample (s)")
        self.plots[0].sigXRangeChanged.connect(self._on_range_changed)

        self.window_box = QtWidgets.QDoubleSpinBox(suffix=" s", decimals=1, minimum=0.5, maximum=max_window)
        self.window_box.setValue(window)
        self.window_box.setToolTip("rolling window shown (display only; the run file keeps every sample)")
        self.window_box.valueChanged.connect(self._set_x_window)
        self.pause_button = QtWidgets.QPushButton("Pause display")
        self.pause_button.setCheckable(True)
        self.pause_button.setToolTip("freeze the plots (acquisition continues); zoom with the mouse")
        self.pause_button.toggled.connect(self.set_paused)
        self.clear_button = QtWidgets.QPushButton("Clear")
        self.clear_button.clicked.connect(self.clear)
        self.rate_label = QtWidgets.QLabel("")

        bar = QtWidgets.QHBoxLayout()
        bar.addWidget(QtWidgets.QLabel("Window"))
        bar.addWidget(self.window_box)
        bar.addWidget(self.pause_button)
        bar.addWidget(self.clear_button)
        bar.addStretch(1)
        bar.addWidget(self.rate_label)
        layout = QtWidgets.QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(bar)
        layout.addWidget(self.graphics, 1)

        self._y_ranges: list[tuple[float, float] | None] = [None] * len(self.plots)
        self._in_legend: dict[str, bool] = {}  # channel -> listed in its panel's legend (default: yes)
        self.units = [unit for _, unit, _ in PANELS]  # the unit each y axis shows now (mrad, mN*m, ...)
        self._set_x_window()
        for plot in self.plots:
            plot.setMouseEnabled(x=False, y=False)
        self._fps_count = 0
        self._fps_t0 = time.monotonic()
        self.timer = QtCore.QTimer(self)
        self.timer.setTimerType(QtCore.Qt.TimerType.PreciseTimer)
        self.timer.timeout.connect(self.redraw)
        self.timer.start(max(1, int(1000 / fps)))

    # ---------------------------------------------------------------- data in
    def append(self, t: np.ndarray, values: dict[str, np.ndarray]) -> None:
        """Add one block (``t`` in s; arrays per channel of :data:`CHANNELS`). GUI thread only."""
        t = np.asarray(t, dtype=float)
        if t.size > 1 and t[-1] > t[0]:
            self._period = (t[-1] - t[0]) / (t.size - 1)
        missing = [c for c in CHANNELS if values.get(c) is None]  # no position setpoint in current mode
        if missing:
            values = {**values, **dict.fromkeys(missing, np.full(t.size, np.nan))}
        self.buffer.append(t, values)
        self._dirty = True

    def clear(self) -> None:
        self.buffer.clear()
        self._frozen = None
        for curve in self.curves.values():
            curve.setData([], [])
        self._y_ranges = [None] * len(self.plots)
        self._dirty = False

    # ---------------------------------------------------------------- pause / zoom
    @property
    def paused(self) -> bool:
        return self._paused

    def set_paused(self, paused: bool) -> None:
        """Freeze (True) or follow (False) the display; the buffer keeps filling either way.

        While paused the view shows a snapshot of the whole buffer (up to ``max_window`` s): pan and zoom
        with the mouse; every zoom re-decimates the visible span at full resolution."""
        self._paused = bool(paused)
        if self.pause_button.isChecked() != self._paused:
            self.pause_button.setChecked(self._paused)
        self.pause_button.setText("Resume display" if paused else "Pause display")
        for plot in self.plots:
            plot.setMouseEnabled(x=paused, y=paused)
        if paused:
            t, data = self.buffer.snapshot()
            self._frozen = (t - t[-1], data) if t.size else None
        else:
            self._frozen = None
            self._y_ranges = [None] * len(self.plots)
            self._set_x_window()
        self._dirty = True

    def _set_x_window(self, *_args) -> None:
        self.plots[0].setXRange(-self.window_box.value(), 0.0, padding=0)
        self._dirty = True

    def _on_range_changed(self, *_args) -> None:
        if self._paused and self._frozen is not None:  # re-decimate the zoomed span of the snapshot
            self._draw(*self._frozen, self.plots[0].viewRange()[0])

    # ---------------------------------------------------------------- drawing
    def _columns(self) -> int:
        return max(100, int(self.plots[0].getViewBox().width()) or 800)

    def redraw(self) -> None:
        """Timer slot: draw the newest window (when following and something changed).

        The x axis is time relative to the newest sample, so its range (and its tick labels) stay fixed
        while data scroll; y ranges change only when the data leave them or shrink to under 40 % of them.
        """
        now = time.monotonic()
        if now - self._fps_t0 >= 1.0:
            self.rate_label.setText(f"{self._fps_count / (now - self._fps_t0):.0f} frames/s")
            self._fps_count, self._fps_t0 = 0, now
        if not self._dirty or self._paused:
            return
        self._dirty = False
        window = self.window_box.value()
        t, data = self.buffer.last(int(window / self._period) + 2)
        if t.size == 0:
            return
        first = int(np.searchsorted(t, t[-1] - window))
        self._draw(t[first:] - t[-1], data[:, first:], None)
        self._follow_y(data[:, first:])

    def _follow_y(self, data: np.ndarray) -> None:
        row = 0
        for p, (_title, _unit, traces) in enumerate(PANELS):
            block = data[row:row + len(traces)]
            row += len(traces)
            finite = block[np.isfinite(block)]
            if finite.size == 0:
                continue
            lo, hi = float(finite.min()), float(finite.max())
            span = max(hi - lo, 1e-12 * max(1.0, abs(hi)), 1e-15)
            current = self._y_ranges[p]
            if current is not None:
                c_lo, c_hi = current
                if c_lo <= lo and hi <= c_hi and (hi - lo) >= 0.4 * (c_hi - c_lo):
                    continue
            pad = 0.1 * span
            self._y_ranges[p] = (lo - pad, hi + pad)
            self.plots[p].setYRange(lo - pad, hi + pad, padding=0)
            self._show_unit(p, lo, hi)

    def _show_unit(self, p: int, lo: float, hi: float) -> None:
        """Label panel ``p``'s y axis in the engineering unit of its data range [lo, hi] (SI): a range under
        0.1 rad reads "position (mrad)", its ticks scaled by 1000 (the axis's scale: the data stay SI), as the
        report figures do (analysis/figure_style.py). Changed only with the y range, so it does not flicker."""
        title, unit, _ = PANELS[p]
        factor, shown = engineering(unit, [lo, hi])
        if shown != self.units[p]:
            axis = self.plots[p].getAxis("left")
            axis.setScale(factor)
            axis.setLabel(f"{title} ({shown})")
            self.units[p] = shown

    def _show_in_legend(self, name: str, present: bool) -> None:
        """The legend names only the traces the run has (no "setpoint" beside a position without one)."""
        if present == self._in_legend.get(name, True):
            return
        self._in_legend[name] = present
        curve = self.curves[name]
        legend = self._legends.get(name)
        if legend is None:
            return
        if present:
            legend.addItem(curve, curve.name())
        else:
            legend.removeItem(curve)

    def _draw(self, t: np.ndarray, data: np.ndarray, span: list[float] | None) -> None:
        if span is not None and t.size:
            lo, hi = np.searchsorted(t, span[0]), np.searchsorted(t, span[1])
            lo, hi = max(0, lo - 1), min(t.size, hi + 1)
            t, data = t[lo:hi], data[:, lo:hi]
        if self.decimate:
            t, data = minmax_decimate(t, data, self._columns())
        for i, name in enumerate(CHANNELS):
            present = bool(np.isfinite(data[i]).any())
            if present:
                self.curves[name].setData(t, data[i], skipFiniteCheck=True)
            else:  # a channel this run does not have (the position setpoint of a current-mode run)
                self.curves[name].setData([], [])
            self._show_in_legend(name, present)
        self.frames += 1
        self._fps_count += 1
        self.frame_drawn.emit()
