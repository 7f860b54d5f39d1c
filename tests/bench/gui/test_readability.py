"""Issue 13, GUI bullets: counters keep their names and units visible; `hilbench gui` without a display
gives one line and exit 2 (Qt would abort the process with SIGABRT)."""

import os
import subprocess
import sys

import pytest

from hilbench.bench.gui.connection_panel import ConnectionPanel
from hilbench.bench.gui.worker import DeviceState

pytestmark = pytest.mark.usefixtures("starts_devices")  # starts a device: the serial realtime part of make test


def test_counter_names_and_units_are_not_cut_off(qtbot):
    panel = ConnectionPanel()
    qtbot.addWidget(panel)
    panel.resize(420, 600)
    panel.show()
    counters = {"host_crc_errors": 0, "host_dropped_frames": 3, "host_lost_samples": 0,
                "host_duplicate_samples": 0, "device_rx_frames": 123456, "device_tx_frames": 654321}
    panel.show_state(DeviceState("IDLE", [], 0, 10, 0.0, counters))
    table = panel.counters_table
    assert table.columnCount() == 3 and table.horizontalHeaderItem(2).text() == "unit"
    metrics = table.fontMetrics()
    for row in range(table.rowCount()):
        name = table.item(row, 0).text()
        unit = table.item(row, 2).text()
        assert unit == ("samples" if name.endswith("_samples") else "frames")
        # the column is at least as wide as its longest text: nothing is elided
        assert table.columnWidth(0) >= metrics.horizontalAdvance(name)
        assert table.columnWidth(2) >= metrics.horizontalAdvance(unit)


@pytest.mark.device_free  # refused before the GUI or any device starts: the parallel part
@pytest.mark.parametrize("env", [{"QT_QPA_PLATFORM": "xcb"}, {"QT_QPA_PLATFORM": "xcb", "DISPLAY": ":97"}])
def test_gui_without_a_display_is_one_line_and_exit_2(env, tmp_path):
    base = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
    cp = subprocess.run([sys.executable, "-m", "hilbench", "gui", "--runs", str(tmp_path)],
                        env={**base, **env}, capture_output=True, text=True, timeout=120)
    assert cp.returncode == 2, cp.stderr
    err = cp.stderr.strip()
    assert "\n" not in err and err.startswith("hilbench gui: error: no usable display")
    assert "libxcb-cursor0" in err and "libxkbcommon-x11-0" in err
