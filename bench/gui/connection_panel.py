"""Connection panel: device URL, identity, configuration, armed state, latched faults, link counters."""

from __future__ import annotations

import os
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from hilbench.bench.gui.worker import DeviceState
from hilbench.drivers import protocol as wire

DEFAULT_URL = "sim://"


def serial_urls() -> list[str]:
    """``serial://PORT`` for every serial port pyserial lists (USB adapters, on-board UARTs)."""
    try:
        from serial.tools import list_ports
    except ImportError:
        return []
    return [f"serial://{port.device}" for port in sorted(list_ports.comports(), key=lambda p: p.device)]


def can_urls(sys_net: str = "/sys/class/net") -> list[str]:
    """``can://socketcan/NAME`` for every SocketCAN interface (ARPHRD_CAN = 280), plus a virtual bus."""
    urls = []
    try:
        names = sorted(os.listdir(sys_net))
    except OSError:
        names = []
    for name in names:
        try:
            kind = Path(sys_net, name, "type").read_text().strip()
        except OSError:
            continue
        if kind == "280":
            urls.append(f"can://socketcan/{name}")
    urls.append("can://virtual/bench0")
    return urls


class ConnectionPanel(QtWidgets.QGroupBox):
    """URL entry with suggestions, connect/disconnect, and the device's live state.

    Emits ``connect_requested(url)``, ``disconnect_requested()`` and ``clear_faults_requested()``; the
    main window forwards them to the device thread and feeds back :meth:`show_connected`,
    :meth:`show_state` and :meth:`show_disconnected`.
    """

    connect_requested = QtCore.Signal(str)
    disconnect_requested = QtCore.Signal()
    clear_faults_requested = QtCore.Signal()

    def __init__(self, parent: QtWidgets.QWidget | None = None, recent: list[str] | None = None) -> None:
        super().__init__("Device", parent)
        self.url_box = QtWidgets.QComboBox()
        self.url_box.setEditable(True)
        # the longest URL listed must not widen the fixed-width panel: the box shows 10 characters, scrolls the rest
        self.url_box.setSizeAdjustPolicy(QtWidgets.QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
        self.url_box.setMinimumContentsLength(10)
        self.url_box.setToolTip("sim:// (simulated bench), serial:///dev/ttyUSB0?baud=2000000, "
                                "can://socketcan/can0?node=1; host-clocked drives: "
                                "canopen://socketcan/can0?node=1&eds=FILE (CiA 402), "
                                "odrive://socketcan/can0?node=0&tvl_endpoint=ID, or the URL that "
                                "'hilbench sim --canopen|--odrive' prints")
        self.recent = list(recent or [])
        self.refresh_urls()
        self.url_box.setCurrentText(DEFAULT_URL)
        self.rescan_button = QtWidgets.QPushButton("Rescan")
        self.rescan_button.setToolTip("list serial ports and CAN interfaces again")
        self.rescan_button.clicked.connect(self.refresh_urls)
        self.connect_button = QtWidgets.QPushButton("Connect")
        self.connect_button.clicked.connect(self._on_connect_clicked)
        self.connected = False

        self.identity_label = QtWidgets.QLabel("-")
        self.identity_label.setWordWrap(True)
        self.config_label = QtWidgets.QLabel("-")
        self.config_label.setWordWrap(True)
        self.state_label = QtWidgets.QLabel("disconnected")
        self.state_label.setObjectName("state")
        self.state_label.setWordWrap(True)  # a long state wraps; it never widens the panel
        self.faults_label = QtWidgets.QLabel("-")
        self.faults_label.setWordWrap(True)
        self.clear_button = QtWidgets.QPushButton("Clear faults")
        self.clear_button.setToolTip("clear every latched fault (e-stop included)")
        self.clear_button.clicked.connect(self.clear_faults_requested)
        self.clear_button.setEnabled(False)
        self.counters_table = QtWidgets.QTableWidget(0, 3)
        self.counters_table.setHorizontalHeaderLabels(["counter", "value", "unit"])
        self.counters_table.verticalHeader().setVisible(False)
        self.counters_table.horizontalHeader().setStretchLastSection(True)
        self.counters_table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)

        url_row = QtWidgets.QHBoxLayout()
        url_row.addWidget(self.url_box, 1)
        url_row.addWidget(self.rescan_button)
        form = QtWidgets.QFormLayout()
        form.addRow("URL", url_row)
        form.addRow("", self.connect_button)
        form.addRow("Identity", self.identity_label)
        form.addRow("Config", self.config_label)
        form.addRow("State", self.state_label)
        faults_row = QtWidgets.QHBoxLayout()
        faults_row.addWidget(self.faults_label, 1)
        faults_row.addWidget(self.clear_button)
        form.addRow("Faults", faults_row)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(form)
        layout.addWidget(QtWidgets.QLabel("Link counters"))
        layout.addWidget(self.counters_table, 1)

    @property
    def url(self) -> str:
        return self.url_box.currentText().strip()

    def refresh_urls(self) -> None:
        current = self.url_box.currentText()
        urls = []
        for url in [DEFAULT_URL, *self.recent, *serial_urls(), *can_urls()]:
            if url not in urls:
                urls.append(url)
        self.url_box.clear()
        self.url_box.addItems(urls)
        if current:
            self.url_box.setCurrentText(current)

    def _on_connect_clicked(self) -> None:
        if self.connected:
            self.disconnect_requested.emit()
            return
        url = self.url
        if not url:
            self.state_label.setText("enter a device URL first (e.g. sim://)")
            return
        self.connect_button.setEnabled(False)
        self.connect_button.setText("Connecting...")
        self.state_label.setText(f"connecting to {url}")
        self.connect_requested.emit(url)

    def remember(self, url: str) -> None:
        if url in self.recent:
            self.recent.remove(url)
        self.recent.insert(0, url)
        del self.recent[10:]

    # ------------------------------------------------------------- feedback from the device thread
    def show_connected(self, info: dict) -> None:
        self.connected = True
        self.remember(info["url"])
        self.connect_button.setEnabled(True)
        self.connect_button.setText("Disconnect")
        self.url_box.setEnabled(False)
        self.identity_label.setText(identity_text(info["identity"]))
        cfg = info.get("config") or {}
        if cfg:
            mode = wire.Mode(cfg["mode"]).name.lower() if "mode" in cfg else "?"
            self.config_label.setText(
                f"{cfg.get('sample_rate', '?')} Hz, {mode} mode, current limit {cfg.get('current_limit', 0):g} A,"
                f" velocity limit {cfg.get('velocity_limit', 0):g} rad/s, kt {cfg.get('torque_constant', 0):g}"
                f" N*m/A, {cfg.get('counts_per_rev', '?')} counts/rev")
        else:
            self.config_label.setText("not configured (each run configures the device)")
        if info.get("clock") == "host":
            self.config_label.setText(f"{self.config_label.text()}; host-clocked drive, runs "
                                      f"{info.get('capabilities', '?')}")
        self.clear_button.setEnabled(True)

    def show_state(self, state: DeviceState) -> None:
        armed = state.state in ("ARMED", "STREAMING")
        colour, verdict = state_colour(state)
        detail = f" {state.detail}" if state.detail else ""
        self.state_label.setText(f"<b style='color:{colour}'>{state.state}</b>{detail}"
                                 f"{'  (power stage ON)' if armed else ''}  {verdict}<br>sample {state.index}, "
                                 f"current {state.current_applied:.3g} A")
        if state.faults:
            self.faults_label.setText(f"<b style='color:#c00000'>{', '.join(state.faults)}</b>")
        else:
            self.faults_label.setText("none")
        self.counters_table.setRowCount(len(state.counters))
        for row, (name, value) in enumerate(sorted(state.counters.items())):
            self.counters_table.setItem(row, 0, QtWidgets.QTableWidgetItem(name))
            item = QtWidgets.QTableWidgetItem(str(value))
            item.setTextAlignment(QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter)
            self.counters_table.setItem(row, 1, item)
            self.counters_table.setItem(row, 2, QtWidgets.QTableWidgetItem(state.units.get(name) or
                                                                           counter_unit(name)))
        self.counters_table.resizeColumnsToContents()

    def show_disconnected(self, reason: str = "") -> None:
        self.connected = False
        self.connect_button.setEnabled(True)
        self.connect_button.setText("Connect")
        self.url_box.setEnabled(True)
        self.clear_button.setEnabled(False)
        self.state_label.setText(f"disconnected{': ' + reason if reason else ''}")

    def show_failed(self) -> None:
        """A connection attempt failed: allow another one."""
        if not self.connected:
            self.show_disconnected("connection failed (see the message above)")


#: link counters that count lost or damaged traffic (the others count frames sent and received)
LINK_ERRORS = ("crc", "dropped", "lost", "duplicate", "overrun", "error")
GREEN, AMBER, RED, NEUTRAL = "#008000", "#b06000", "#c00000", "#404040"


def state_colour(state: DeviceState) -> tuple[str, str]:
    """(colour of the state word, a short verdict in words). Green only for healthy and ready: no fault, no lost
    or damaged link traffic, power stage off. A latched fault is red; a power stage that is on (ARMED, STREAMING)
    amber; UNCONFIGURED and DISARMED are states, not health, so the word is neutral and the verdict says ready."""
    if state.faults:
        return RED, f"<span style='color:{RED}'>fault: clear it before a run</span>"
    if state.state in ("ARMED", "STREAMING"):
        return AMBER, ""
    errors = sum(v for k, v in state.counters.items() if any(w in k for w in LINK_ERRORS))
    if errors:
        return NEUTRAL, f"<span style='color:{AMBER}'>{errors} link errors (see the counters)</span>"
    return NEUTRAL, f"<span style='color:{GREEN}'>ready</span>"


def identity_text(ident: dict) -> str:
    """One line naming the device: a hilbench device's model, serial, firmware, protocol and buffer, or a
    drive's protocol, model and serial."""
    if "protocol" in ident:  # a host-clocked drive (drivers.canopen_drive, drivers.odrive_drive)
        parts = [str(ident["protocol"])]
        parts += [f"{key} {ident[key]}" for key in ("model", "serial", "node", "rated_torque_Nm") if key in ident]
        return "  ".join(parts)
    sensors = wire.Sensor(int(ident.get("sensors", 0) or 0))  # IDENTITY v3
    sensing = "  senses winding temperature" if sensors & wire.Sensor.TEMPERATURE else ""
    return (f"{ident.get('model', '?')}  serial {ident.get('serial', '?')}  firmware {ident.get('firmware', '?')}"
            f"  protocol v{ident.get('protocol_version', '?')}  buffer {ident.get('buffer_capacity', '?')}{sensing}")


def counter_unit(name: str) -> str:
    """Unit of a link counter (``host_*``/``device_*`` from :attr:`drivers.amplifier.Amplifier.counters`)."""
    return "samples" if name.endswith("_samples") else "frames"
