"""The operator window driving host-clocked drives: the simulated CiA 402 drive and the simulated ODrive,
each in this process on its own python-can ``virtual`` bus (the host side is the real driver, as with
``hilbench sim --canopen|--odrive``). One window serves the module; the tests run in file order.
"""

from __future__ import annotations

import threading
import time
import uuid

import can
import canopen
import numpy as np
import pytest
from PySide6 import QtCore

from hilbench.bench.gui.main_window import MainWindow
from hilbench.common.runfile import open_run
from hilbench.firmware_sim.devices.cia402_drive import EDS_PATH, SimCia402Drive
from hilbench.firmware_sim.devices.odrive_sim import TVL_ENDPOINT, SimOdrive
from hilbench.firmware_sim.devices.sim_config import load_sim_config

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]  # starts a device
@pytest.fixture(scope="module")
def drives():
    """(canopen URL, odrive URL) of two simulated drives on their own virtual buses."""
    sim = load_sim_config()
    co_channel, od_channel = f"g-{uuid.uuid4().hex[:8]}", f"g-{uuid.uuid4().hex[:8]}"
    network = canopen.Network()
    network.connect(interface="virtual", channel=co_channel)
    cia402 = SimCia402Drive(network, 3, sim, clock="sync", sync_timeout=1.0)  # in-process: GIL stalls
    od_bus = can.Bus(interface="virtual", channel=od_channel)
    odrive = SimOdrive(od_bus, 4, sim, watchdog_timeout=1.0)
    yield (f"canopen://virtual/{co_channel}?node=3&eds={EDS_PATH}",
           f"odrive://virtual/{od_channel}?node=4&tvl_endpoint={TVL_ENDPOINT}")
    cia402.close()
    network.disconnect()
    odrive.close()
    od_bus.shutdown()


@pytest.fixture(scope="module")
def window(qapp, drives, tmp_path_factory):
    w = MainWindow(device=drives[0], runs_dir=tmp_path_factory.mktemp("runs"), timeout=2.0)
    w.show()
    yield w
    w.shutdown()
    w.close()


def _errors(window, since: float) -> list[str]:
    return [text for t, text, error in window.messages if error and t >= since]


def _connect(window, qtbot, url: str) -> None:
    if window.connected and window.device.url != url:
        window.disconnect_device()
        qtbot.waitUntil(lambda: not window.connected, timeout=5000)
    if not window.connected:
        window.connect_device(url)
        qtbot.waitUntil(lambda: window.connected, timeout=10000)
    qtbot.waitUntil(lambda: "sample" in window.connection.state_label.text(), timeout=5000)


def _start(window, qtbot, out, **values) -> bool:
    window.protocol.device_form.set_value("watchdog_timeout", "0.5")
    form = window.protocol.select("identification")
    for key, value in values.items():
        form.set_value(key, value)
    window.protocol.out_edit.setText(str(out))
    assert window.protocol.validate() is not None, window.protocol.summary.text()
    qtbot.mouseClick(window.protocol.start_button, QtCore.Qt.MouseButton.LeftButton)
    return window.running


def _wait(window, qtbot, condition, timeout: int) -> None:
    """qtbot.waitUntil, failing with the window's messages (what went wrong, if anything did)."""
    try:
        qtbot.waitUntil(condition, timeout=timeout)
    except Exception:
        pytest.fail(f"timed out after {timeout} ms; messages: {[m for _, m, _ in window.messages[-5:]]}")


def _stream_threads(window) -> list[threading.Thread]:
    """Record the thread each stream of the connected drive runs in."""
    amp = window.device.bench.amplifier
    threads, stream = [], amp.stream

    def recorded(*args, **kwargs):
        threads.append(threading.current_thread())
        return stream(*args, **kwargs)

    amp.stream = recorded
    return threads


def test_canopen_drive_connects_and_shows_its_state(window, qtbot, drives):
    _connect(window, qtbot, drives[0])
    assert "CiA 402" in window.connection.identity_label.text()
    assert "host-clocked drive, runs current at 1000, 2000 Hz" in window.connection.config_label.text()
    assert "statusword 0x" in window.connection.state_label.text()
    assert window.connection.faults_label.text() == "none"


def test_a_protocol_the_drive_cannot_run_is_refused_in_one_line_before_anything_moves(window, qtbot, drives,
                                                                                        tmp_path):
    _connect(window, qtbot, drives[0])
    out = tmp_path / "refused.h5"
    t0 = time.monotonic()
    assert not _start(window, qtbot, out, sample_rate="10000", duration="1")
    errors = _errors(window, t0)
    assert len(errors) == 1 and "\n" not in errors[0]
    assert "cannot run identification" in errors[0] and "at 10000 Hz" in errors[0]
    assert "choose --sample-rate 1000" in errors[0]
    assert not out.exists() and window.protocol.start_button.isEnabled()


@pytest.mark.parametrize("which", [0, 1], ids=["canopen", "odrive"])
def test_a_run_on_the_drive_updates_the_live_view_off_the_gui_thread_and_writes_host_time(
        window, qtbot, drives, tmp_path, which):
    _connect(window, qtbot, drives[which])
    threads = _stream_threads(window)
    out = tmp_path / "drive.h5"
    t0 = time.monotonic()
    assert _start(window, qtbot, out, sample_rate="1000", duration="1.5", amplitude="8", period="0.5",
                  cutoff="40")
    _wait(window, qtbot, lambda: window.live.buffer.total > 300, 20000)
    _wait(window, qtbot, lambda: not window.running and window.run_worker is None, 30000)
    assert not _errors(window, t0), _errors(window, t0)
    assert window.last_result.status == "completed" and window.last_result.samples == 1500
    assert window.live.buffer.total == 1500
    x, y = window.live.curves["position"].getData()
    assert x is not None and len(x) > 10 and np.ptp(y) > 0
    assert threads and all(t is not threading.main_thread() for t in threads)  # the stream ran in the worker
    with open_run(out) as r:
        host_time = r.channel("host_time")
        assert r.status == "completed" and host_time.size == 1500 and np.all(np.diff(host_time) > 0)
    # the panel shows the stream's timing, with units
    qtbot.waitUntil(lambda: window.connection.counters_table.rowCount() >= 6, timeout=5000)
    rows = {window.connection.counters_table.item(r, 0).text(): window.connection.counters_table.item(r, 2).text()
            for r in range(window.connection.counters_table.rowCount())}
    assert rows["missed cycles"] == "cycles" and rows["cycle time p99"] == "ms"


def test_estop_quick_stops_the_canopen_drive_mid_run(window, qtbot, drives, tmp_path):
    _connect(window, qtbot, drives[0])
    out = tmp_path / "estop.h5"
    t0 = time.monotonic()
    assert _start(window, qtbot, out, sample_rate="1000", duration="5", amplitude="4")
    _wait(window, qtbot, lambda: window.live.buffer.total > 200, 20000)
    window.estop()
    _wait(window, qtbot, lambda: not window.running and window.run_worker is None, 20000)
    assert any("quick stop" in e for e in _errors(window, t0)), _errors(window, t0)
    with open_run(out) as r:
        assert r.status == "aborted" and r.n_samples < 5000
        assert any("quick stop" in str(m) for m in r.events["message"])
    qtbot.waitUntil(lambda: "DISARMED" in window.connection.state_label.text(), timeout=5000)
