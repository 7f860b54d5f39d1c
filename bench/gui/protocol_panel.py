"""Protocol panel: one form per protocol built from its ``SPECS`` (units and ranges shared with the CLI),
run controls (start, pause/resume, abort), a progress bar with ETA and the output file name."""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtWidgets

from hilbench.bench.acquisition.protocols import PROTOCOLS, ParameterSpec, Protocol, ProtocolError, make_protocol
from hilbench.bench.gui.elided_label import ElidedLabel

#: forms build the setpoints (to run their checks) up to this many samples; longer runs are checked at start
CHECK_SETPOINTS_UP_TO = 600_000
TITLES = {"identification": "Identification", "chirp": "Chirp", "stepped_sine": "Stepped sine",
          "presliding": "Presliding"}


def default_values(cls: type[Protocol]) -> dict[str, Any]:
    """Each field's dataclass default."""
    out = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = f.default_factory()
    return out


def format_value(value: Any) -> str:
    if isinstance(value, tuple | list):
        return ", ".join(f"{v:g}" for v in value)
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def parse_value(spec: ParameterSpec, text: str) -> Any:
    """Text of a form field -> the value its spec expects (unchecked); raises ProtocolError on bad syntax."""
    text = text.strip()
    try:
        if spec.kind == "floats":
            return tuple(float(v) for v in text.replace(";", ",").split(",") if v.strip())
        if spec.kind == "int":
            value = float(text)
            return int(value) if value.is_integer() else value
        if spec.kind == "choice" or spec.kind == "str":
            return text
        return float(text)
    except ValueError:
        what = "comma-separated numbers" if spec.kind == "floats" else "a number"
        raise ProtocolError(f"{text!r} is not {what}") from None


def planned_samples(protocol: Protocol) -> tuple[int, int]:
    """(samples, steps) a protocol will play, from its parameters alone (no setpoints are built, so a
    form can check every keystroke of a one-hour run without freezing): ``duration*sample_rate`` or, for
    a stepped sine, whole periods ``(settle + measure)/f`` per (amplitude, frequency) step."""
    fs = protocol.sample_rate
    if hasattr(protocol, "frequencies"):  # as bench.acquisition.excitations.stepped_sine snaps each step
        g = math.gcd(protocol.settle_periods, protocol.measure_periods)
        blocks = protocol.settle_periods // g + protocol.measure_periods // g
        per_amplitude = sum(blocks * max(1, int(round(g * fs / f))) for f in protocol.frequencies)
        return per_amplitude * len(protocol.amplitudes), len(protocol.frequencies) * len(protocol.amplitudes)
    return round(protocol.duration * fs), 1  # a field of the other protocols


class ProtocolForm(QtWidgets.QWidget):
    """Fields of one protocol; every edit is checked against the spec at once (message under the form)."""

    changed = QtCore.Signal()

    def __init__(self, cls: type[Protocol], parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.cls = cls
        self.specs = cls.specs()
        self.fields: dict[str, QtWidgets.QWidget] = {}
        self.units: dict[str, QtWidgets.QLabel] = {}
        defaults = default_values(cls)
        form = QtWidgets.QFormLayout(self)
        for name, spec in self.specs.items():
            if spec.kind == "choice":
                widget = QtWidgets.QComboBox()
                widget.addItems(spec.choices)
                widget.setCurrentText(str(defaults[name]))
                widget.currentTextChanged.connect(self._on_change)
            else:
                widget = QtWidgets.QLineEdit(format_value(defaults[name]))
                widget.textChanged.connect(self._on_change)
            rng = (f" [{spec.minimum:g}, {spec.maximum:g}]" if spec.minimum is not None and
                   spec.maximum is not None else "")
            widget.setToolTip(f"{spec.help}{rng}")
            widget.setObjectName(name)
            unit = QtWidgets.QLabel()
            row = QtWidgets.QHBoxLayout()
            row.addWidget(widget, 1)
            row.addWidget(unit)
            form.addRow(name.replace("_", " "), row)
            self.fields[name] = widget
            self.units[name] = unit
        self._update_units()

    def _on_change(self, *_args) -> None:
        self._update_units()
        self.changed.emit()

    def _mode(self) -> str:
        box = self.fields.get("mode")
        return box.currentText() if isinstance(box, QtWidgets.QComboBox) else "current"

    def _update_units(self) -> None:
        mode = self._mode()
        for name, spec in self.specs.items():
            self.units[name].setText(spec.unit_for(mode) if spec.unit else "")

    def set_value(self, name: str, value: Any) -> None:
        widget = self.fields[name]
        if isinstance(widget, QtWidgets.QComboBox):
            widget.setCurrentText(str(value))
        else:
            widget.setText(value if isinstance(value, str) else format_value(value))

    def values(self) -> dict[str, Any]:
        """Parsed and range-checked values; raises ProtocolError naming the field, unit and range."""
        mode = self._mode()
        out = {}
        for name, spec in self.specs.items():
            widget = self.fields[name]
            text = widget.currentText() if isinstance(widget, QtWidgets.QComboBox) else widget.text()
            try:
                value = parse_value(spec, text)
            except ProtocolError as exc:
                raise ProtocolError(f"{name}: {exc}") from None
            out[name] = spec.check(name, value, mode)
        return out

    def protocol(self) -> Protocol:
        """The protocol these fields describe (including its cross-field checks)."""
        return make_protocol(self.cls.name, self.values())

    def mark_invalid(self, message: str) -> None:
        for name, widget in self.fields.items():
            bad = message.startswith(f"{name} ") or message.startswith(f"{name}:") or f" {name} " in message
            widget.setStyleSheet("background: #ffd0d0" if bad else "")


class DeviceSettingsForm(QtWidgets.QWidget):
    """The device limits and calibration sent with every run (the CLI's ``hilbench run`` options)."""

    changed = QtCore.Signal()

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        from hilbench.bench.acquisition.device_options import DEVICE_OPTIONS
        from hilbench.bench.acquisition.runner import DeviceSettings

        super().__init__(parent)
        from hilbench.bench.acquisition.user_config import default_settings
        from hilbench.bench.errors import BenchError

        try:  # the config file's [settings] (docs/cli.md); a bad file is reported by the CLI, not here
            configured = default_settings()
            defaults = DeviceSettings(**configured)
        except (BenchError, ValueError):
            configured, defaults = {}, DeviceSettings()
        self._defaults, self._configured = defaults, set(configured)
        self._shown: dict[str, str] = {}  # the text the form itself last put in each field
        self.fields: dict[str, QtWidgets.QLineEdit] = {}
        form = QtWidgets.QFormLayout(self)
        for name, (unit, text) in DEVICE_OPTIONS.items():
            edit = QtWidgets.QLineEdit(format_value(getattr(defaults, name)))
            edit.setToolTip(text)
            edit.setObjectName(name)
            edit.textChanged.connect(self.changed)
            row = QtWidgets.QHBoxLayout()
            row.addWidget(edit, 1)
            row.addWidget(QtWidgets.QLabel(unit))
            form.addRow(name.replace("_", " "), row)
            self.fields[name] = edit
            self._shown[name] = edit.text()

    def recommend(self, cls: type[Protocol]) -> None:
        """Show ``cls.RECOMMENDED_SETTINGS`` (else the defaults) in every field that neither the operator has
        edited nor the config file's ``[settings]`` sets: the order ``hilbench run`` applies."""
        for name, edit in self.fields.items():
            if name in self._configured or edit.text() != self._shown[name]:
                continue
            text = format_value(cls.RECOMMENDED_SETTINGS.get(name, getattr(self._defaults, name)))
            self._shown[name] = text
            edit.setText(text)

    def set_value(self, name: str, value: Any) -> None:
        self.fields[name].setText(value if isinstance(value, str) else format_value(value))

    def settings(self):
        """A :class:`bench.acquisition.runner.DeviceSettings`; raises ProtocolError naming a bad field."""
        from hilbench.bench.acquisition.runner import DeviceSettings

        values: dict[str, Any] = {}
        for name, edit in self.fields.items():
            text = edit.text().strip()
            try:
                value = float(text)
            except ValueError:
                raise ProtocolError(f"{name}: {text!r} is not a number") from None
            if math.isnan(value):
                raise ProtocolError(f"{name} is NaN")
            values[name] = int(value) if name == "counts_per_rev" and value.is_integer() else value
        try:
            settings = DeviceSettings(**values)
            from hilbench.drivers.protocol import Config

            problems = Config(sample_rate=10000, current_limit=settings.current_limit,
                              velocity_limit=settings.velocity_limit, position_min=settings.position_min,
                              position_max=settings.position_max, watchdog_timeout=settings.watchdog_timeout,
                              torque_constant=settings.torque_constant, counts_per_rev=settings.counts_per_rev,
                              ratio=settings.ratio).problems()
        except (TypeError, ValueError) as exc:
            raise ProtocolError(f"device settings: {exc}") from None
        if problems:
            raise ProtocolError("device settings: " + "; ".join(problems))
        return settings


class ProtocolPanel(QtWidgets.QGroupBox):
    """Forms, output file and run controls. Emits ``start_requested(protocol, out, operator, notes)``,
    ``pause_requested(bool)`` and ``abort_requested()``; the main window drives :meth:`set_running`,
    :meth:`show_progress` and :meth:`show_finished`."""

    start_requested = QtCore.Signal(object, str, str, str, object)  # protocol, out, operator, notes, settings
    plan_requested = QtCore.Signal(str)  # the campaign TOML the plan goes to
    pause_requested = QtCore.Signal(bool)
    abort_requested = QtCore.Signal()

    def __init__(self, parent: QtWidgets.QWidget | None = None, runs_dir: str | Path = "runs") -> None:
        super().__init__("Protocol", parent)
        self.runs_dir = Path(runs_dir)
        # two tabs that fit a narrow side panel (five did not: three hid behind scroll arrows); the protocol is
        # chosen in a list above its form
        self.tabs = QtWidgets.QTabWidget()
        self.tabs.tabBar().setUsesScrollButtons(False)
        self.protocol_box = QtWidgets.QComboBox()
        self.stack = QtWidgets.QStackedWidget()
        self.forms: dict[str, ProtocolForm] = {}
        for name, cls in PROTOCOLS.items():
            form = ProtocolForm(cls)
            form.changed.connect(self.validate)
            scroll = QtWidgets.QScrollArea()
            scroll.setWidget(form)
            scroll.setWidgetResizable(True)
            self.protocol_box.addItem(TITLES.get(name, name), name)
            self.stack.addWidget(scroll)
            self.forms[name] = form
        page = QtWidgets.QWidget()
        page_layout = QtWidgets.QVBoxLayout(page)
        page_layout.setContentsMargins(2, 4, 2, 2)
        page_layout.addWidget(self.protocol_box)
        page_layout.addWidget(self.stack, 1)
        self.tabs.addTab(page, "Protocol")
        self.device_form = DeviceSettingsForm()
        self.device_form.changed.connect(self.validate)
        scroll = QtWidgets.QScrollArea()
        scroll.setWidget(self.device_form)
        scroll.setWidgetResizable(True)
        self.tabs.addTab(scroll, "Device settings")
        self.protocol_box.currentIndexChanged.connect(self._on_protocol)
        self.tabs.currentChanged.connect(lambda _i: self.validate())
        self.summary = QtWidgets.QLabel("")
        self.summary.setWordWrap(True)
        self.out_edit = QtWidgets.QLineEdit()
        # the line edit shows the end of a long path; the label under it shows its start and end (elided in the
        # middle) and the tooltip the whole path
        self.out_label = ElidedLabel("")
        self.out_edit.textChanged.connect(self._show_out)
        browse = QtWidgets.QPushButton("...")
        browse.setFixedWidth(30)
        browse.clicked.connect(self._browse)
        self.operator_edit = QtWidgets.QLineEdit()
        self.notes_edit = QtWidgets.QLineEdit()
        self.start_button = QtWidgets.QPushButton("Start")
        self.start_button.clicked.connect(self._on_start)
        self.pause_button = QtWidgets.QPushButton("Pause")
        self.pause_button.setCheckable(True)
        self.pause_button.setToolTip("pause between steps (stepped sine) - the device is disarmed while paused")
        self.pause_button.toggled.connect(self._on_pause)
        self.abort_button = QtWidgets.QPushButton("Abort")
        self.abort_button.setToolTip("stop the run after the current block; the file is marked aborted")
        self.abort_button.clicked.connect(self.abort_requested)
        self.plan_button = QtWidgets.QPushButton("Plan experiments...")
        self.plan_button.setToolTip("probe the motor's break-away on the connected device (a few seconds, "
                                           "within the device settings' limits) and write a campaign sized from it "
                                           "(hilbench plan)")
        self.plan_button.clicked.connect(self._on_plan)
        self.progress = QtWidgets.QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.setFormat("idle")
        self.progress.setTextVisible(True)
        self.eta_label = QtWidgets.QLabel("")
        self.device_connected = False

        out_row = QtWidgets.QHBoxLayout()
        out_row.addWidget(self.out_edit, 1)
        out_row.addWidget(browse)
        meta = QtWidgets.QFormLayout()
        meta.addRow("Output", out_row)
        meta.addRow("", self.out_label)
        meta.addRow("Operator", self.operator_edit)
        meta.addRow("Notes", self.notes_edit)
        buttons = QtWidgets.QHBoxLayout()
        for b in (self.start_button, self.pause_button, self.abort_button):
            buttons.addWidget(b)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addWidget(self.tabs, 1)
        layout.addWidget(self.summary)
        layout.addLayout(meta)
        layout.addLayout(buttons)
        layout.addWidget(self.plan_button)
        layout.addWidget(self.progress)
        layout.addWidget(self.eta_label)
        self._new_out_name()
        self.set_running(False)
        self.validate()

    def _on_protocol(self, index: int) -> None:
        self.stack.setCurrentIndex(index)
        self._new_out_name()
        self.device_form.recommend(PROTOCOLS[self.current_name])
        self.validate()

    def _show_out(self, text: str) -> None:
        self.out_edit.setToolTip(f"run file to write (HDF5); a new name is proposed after every run:\n{text}")
        self.out_label.set_full_text(text)

    @property
    def current_name(self) -> str:
        """The protocol chosen in the list (the device-settings tab keeps it)."""
        return list(self.forms)[max(0, self.protocol_box.currentIndex())]

    @property
    def current_form(self) -> ProtocolForm:
        return self.forms[self.current_name]

    def select(self, name: str) -> ProtocolForm:
        self.tabs.setCurrentIndex(0)
        self.protocol_box.setCurrentIndex(list(self.forms).index(name))
        return self.forms[name]

    def _new_out_name(self) -> None:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        self.out_edit.setText(str(self.runs_dir / f"{self.current_name}-{stamp}.h5"))

    def _browse(self) -> None:
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Run file", self.out_edit.text(),
                                                        "HDF5 run files (*.h5)")
        if path:
            self.out_edit.setText(path)

    def validate(self) -> Protocol | None:
        """Check the current form; shows the problem in red and returns None, or the protocol."""
        form = self.current_form
        try:
            protocol = form.protocol()
            self.settings = self.device_form.settings()
        except (ProtocolError, ValueError) as exc:
            message = " ".join(str(exc).split())
            form.mark_invalid(message)
            self.summary.setText(f"<span style='color:#c00000'>{message}</span>")
            self.start_button.setEnabled(False)
            return None
        samples, steps = planned_samples(protocol)
        if samples <= CHECK_SETPOINTS_UP_TO:
            try:  # the excitation's own checks (e.g. a frequency too close to Nyquist, the device limit)
                protocol.excitation(self.settings.limit_for(protocol))
            except (ProtocolError, ValueError) as exc:
                message = " ".join(str(exc).split())
                self.summary.setText(f"<span style='color:#c00000'>{message}</span>")
                self.start_button.setEnabled(False)
                return None
        form.mark_invalid("")
        self.summary.setText(f"about {samples / protocol.sample_rate:.4g} s at {protocol.sample_rate} Hz "
                             f"({samples} samples{f', {steps} steps' if steps > 1 else ''})")
        self.start_button.setEnabled(not self._running)
        return protocol

    def _on_start(self) -> None:
        protocol = self.validate()
        if protocol is None:
            return
        out = self.out_edit.text().strip()
        if not out:
            self.summary.setText("<span style='color:#c00000'>choose an output file name</span>")
            return
        if Path(out).exists():
            self.summary.setText(f"<span style='color:#c00000'>{out} exists; choose another name</span>")
            return
        self.start_requested.emit(protocol, out, self.operator_edit.text(), self.notes_edit.text(), self.settings)

    def _on_plan(self) -> None:
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Campaign file for the plan",
                                                        str(self.runs_dir / "plan.toml"), "campaign files (*.toml)")
        if path:
            self.plan_requested.emit(path)

    def _on_pause(self, paused: bool) -> None:
        self.pause_button.setText("Resume" if paused else "Pause")
        self.pause_requested.emit(paused)

    # ------------------------------------------------------------- run state
    _running = False

    def set_running(self, running: bool) -> None:
        self._running = running
        self.tabs.setEnabled(not running)  # the protocol list and both forms
        self.out_edit.setEnabled(not running)
        self.start_button.setEnabled(not running)
        self.pause_button.setEnabled(running)
        self.abort_button.setEnabled(running)
        self.plan_button.setEnabled(not running)
        if not running:
            self.pause_button.blockSignals(True)
            self.pause_button.setChecked(False)
            self.pause_button.setText("Pause")
            self.pause_button.blockSignals(False)
        else:
            self.progress.setValue(0)
            self.progress.setFormat("starting")

    def show_progress(self, done: int, total: int, eta_s: float, segment: int, n_segments: int,
                      paused: bool) -> None:
        fraction = done / total if total else 0.0
        self.progress.setValue(int(1000 * fraction))
        self.progress.setFormat(f"{100 * fraction:.1f} %  ({done}/{total} samples)")
        step = f"step {segment + 1}/{n_segments}, " if n_segments > 1 else ""
        pause = "pause requested (takes effect between steps), " if paused else ""
        eta = f"ETA {eta_s:.1f} s" if eta_s == eta_s and eta_s != float("inf") else "ETA -"
        self.eta_label.setText(f"{pause}{step}{eta}")

    def show_finished(self, text: str) -> None:
        self.set_running(False)
        self.progress.setFormat(text)
        self.eta_label.setText("")
        self._new_out_name()
        self.validate()
