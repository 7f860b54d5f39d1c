"""The live view (issue 28): axes in engineering units with their names, as the report figures, and setpoints
told apart from measurements by colour and line style."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6 import QtCore

from hilbench.bench.gui.live_plot import CHANNELS, PANELS, LivePlot


@pytest.fixture
def live(qapp, qtbot):
    w = LivePlot(sample_rate=1000.0, fps=1.0)
    w.timer.stop()  # drawn by hand below
    qtbot.addWidget(w)
    w.resize(900, 700)
    w.show()
    yield w
    w.timer.stop()


def _block(position_amplitude: float, torque: float, position_cmd: bool = True, n: int = 2000) -> tuple:
    t = np.arange(n) / 1000.0
    q = position_amplitude * np.sin(2 * np.pi * t)
    values = {"current_cmd": np.full(n, 1.5), "current_meas": np.full(n, 1.4), "torque": torque * np.cos(t),
              "position": q, "velocity": np.gradient(q, t)}
    if position_cmd:
        values["position_cmd"] = 1.1 * q
    return t, values


def _axis(live: LivePlot, title: str):
    return live.plots[[p[0] for p in PANELS].index(title)].getAxis("left")


def _tick_texts(axis) -> list[str]:
    """The tick labels the axis draws for its current range (as AxisItem.generateDrawSpecs computes them)."""
    lo, hi = axis.linkedView().viewRange()[1]
    texts = []
    for spacing, values in axis.tickValues(lo, hi, axis.size().height()):
        texts += axis.tickStrings(values, axis.autoSIPrefixScale * axis.scale, spacing)
    return texts


def test_small_values_read_in_mrad_and_mn_m_with_plain_ticks(live):
    live.append(*_block(2.5e-4, 3e-3))  # 0.25 mrad, 3 mN*m: the default chirp's range
    live.redraw()
    position, torque, current = _axis(live, "position"), _axis(live, "torque"), _axis(live, "current")
    assert (position.labelText, position.scale) == ("position (mrad)", 1000.0)
    assert (torque.labelText, torque.scale) == ("torque (mN*m)", 1000.0)
    assert (current.labelText, current.scale) == ("current (A)", 1.0)
    assert "x0.001" not in position.labelString() and "(mrad)" in position.labelString()
    ticks = [float(s) for s in _tick_texts(position) if s]
    # the setpoint 1.1 * 0.25 mrad, padded by 10 % of its 0.55 mrad span: the view is +-0.33 mrad and the ticks
    # read as mrad (0.1, 0.2, 0.3), never as rad (0.0002)
    assert ticks and 0.1 <= max(abs(v) for v in ticks) <= 0.33, ticks
    live.clear()
    live.append(*_block(2.0, 0.5))  # large again: back to rad and N*m
    live.redraw()
    assert (position.labelText, position.scale) == ("position (rad)", 1.0)
    assert (torque.labelText, torque.scale) == ("torque (N*m)", 1.0)


def test_setpoint_and_measured_differ_in_colour_and_line_style(live):
    for title, _, traces in PANELS:
        if len(traces) > 1:
            (cmd, _, cmd_name), (meas, _, meas_name) = traces
            a, b = live.curves[cmd].opts["pen"], live.curves[meas].opts["pen"]
            assert a.color().name() != b.color().name(), title
            assert a.style() == QtCore.Qt.PenStyle.DashLine and b.style() == QtCore.Qt.PenStyle.SolidLine, title
            assert (cmd_name, meas_name) == ("setpoint", "measured")
    live.append(*_block(1e-3, 0.1))
    live.redraw()
    x, y = live.curves["position_cmd"].getData()
    assert x is not None and np.allclose(np.nanmax(y), 1.1e-3, rtol=1e-3)


def _legend_names(live: LivePlot, title: str) -> list[str]:
    legend = live.plots[[p[0] for p in PANELS].index(title)].legend
    return [label.text for _, label in legend.items]


def test_a_current_mode_run_draws_no_position_setpoint(live):
    live.append(*_block(1e-3, 0.1, position_cmd=False))
    live.redraw()
    x, _ = live.curves["position_cmd"].getData()
    assert x is None or len(x) == 0
    assert _legend_names(live, "position") == ["measured"]  # no "setpoint" without one
    assert _legend_names(live, "current") == ["setpoint", "measured"]
    live.clear()
    live.append(*_block(1e-3, 0.1))  # a position-mode run next: the setpoint is back
    live.redraw()
    assert sorted(_legend_names(live, "position")) == ["measured", "setpoint"]
    live.clear()
    live.append(*_block(1e-3, 0.1, position_cmd=False))
    live.redraw()
    assert _legend_names(live, "position") == ["measured"]
    x, y = live.curves["position"].getData()
    assert len(x) > 0 and np.isfinite(y).all()
    assert set(CHANNELS) >= {"position_cmd", "position", "current_cmd", "current_meas"}
