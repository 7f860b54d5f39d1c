"""Run browser: open run files (finished, crashed, or still being written: SWMR), plot any channel, and run
identification, skeleton, AFRF and residual analyses off the GUI thread."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6 import QtCore, QtGui, QtWidgets

from hilbench.analysis.execution import limited
from hilbench.bench.gui import analyses
from hilbench.bench.gui.elided_label import ElidedLabel
from hilbench.bench.gui.worker import one_line
from hilbench.common.runfile.schema import SAMPLE_INDEX

COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
#: analysis curves: the measurement dark and solid, a model orange and dashed, anything else from COLOURS with a
#: line style of its own, so no two curves of a plot differ by colour alone
MEASURED_PEN = {"color": "#202020", "width": 1}
MODEL_PEN = {"color": "#ff7f0e", "width": 1, "style": QtCore.Qt.PenStyle.DashLine}
STYLES = (QtCore.Qt.PenStyle.SolidLine, QtCore.Qt.PenStyle.DashLine, QtCore.Qt.PenStyle.DotLine,
          QtCore.Qt.PenStyle.DashDotLine)
#: a value longer than this goes above the table (wrapped), not into a cell
LONG_VALUE = 28
_UNIT = re.compile(r"^(.*)\(([^()]+)\)\s*$")


def curve_pen(label: str, index: int) -> dict:
    """The pen of analysis curve number ``index`` named ``label`` (see MEASURED_PEN, MODEL_PEN)."""
    if label.startswith("measured"):
        return MEASURED_PEN
    if label.startswith("model"):
        return MODEL_PEN
    return {"color": COLOURS[index % len(COLOURS)], "width": 1, "style": STYLES[index % len(STYLES)]}


def scaled_label(label: str, values) -> tuple[float, str]:
    """(factor, label) drawing ``values`` of an axis labelled ``name (unit)`` in an engineering unit (mrad,
    mN*m): pyqtgraph would otherwise write "position (rad) (x0.001)"."""
    from hilbench.analysis.figure_style import engineering

    m = _UNIT.match(label)
    if not m:
        return 1.0, label
    factor, unit = engineering(m.group(2), values)
    return factor, f"{m.group(1).rstrip()} ({unit})"


class AnalysisWorker(QtCore.QThread):
    """Runs one analysis on its own read handle of the run file."""

    done = QtCore.Signal(object)  # AnalysisResult
    failed = QtCore.Signal(str)

    def __init__(self, name: str, path: str, options: dict) -> None:
        super().__init__()
        self.name, self.path, self.options = name, path, options

    @limited()  # one BLAS thread (analysis.execution): the GUI thread and a running stream share the cores
    def run(self) -> None:
        try:  # the registry's entry: read within the memory budget, the CLI's refusals, the same figures
            result = analyses.run_analysis(self.name, self.path, self.options)
        except Exception as exc:  # shown in the browser; the GUI keeps running
            self.failed.emit(f"{analyses.titles().get(self.name, self.name)} failed: {one_line(exc)}")
            return
        self.done.emit(result)


class RunBrowser(QtWidgets.QWidget):
    """Open a run file, inspect metadata and events, plot channels, run analyses."""

    message = QtCore.Signal(str, bool)  # text, is_error

    def __init__(self, parent: QtWidgets.QWidget | None = None, runs_dir: str | Path = "runs") -> None:
        super().__init__(parent)
        self.runs_dir = Path(runs_dir)
        self.run = None
        self.worker: AnalysisWorker | None = None
        self.last_result: analyses.AnalysisResult | None = None

        self.path_edit = QtWidgets.QLineEdit()
        self.path_edit.setPlaceholderText("run file (.h5)")
        self.path_edit.returnPressed.connect(lambda: self.open(self.path_edit.text()))
        browse = QtWidgets.QPushButton("Browse...")
        browse.clicked.connect(self._browse)
        open_button = QtWidgets.QPushButton("Open")
        open_button.clicked.connect(lambda: self.open(self.path_edit.text()))
        self.follow_box = QtWidgets.QCheckBox("Follow live file")
        self.follow_box.setToolTip("re-read a file that is still being written (SWMR) once a second")
        self.follow_box.toggled.connect(self._on_follow)
        self.files = QtWidgets.QListWidget()
        # a long file name is elided in the middle (its time stamp stays readable), whole in the tooltip
        self.files.setTextElideMode(QtCore.Qt.TextElideMode.ElideMiddle)
        self.files.setHorizontalScrollBarPolicy(QtCore.Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        # one click opens a run (Enter too); a double click would open it twice
        self.files.itemClicked.connect(lambda item: self.open(item.data(QtCore.Qt.ItemDataRole.UserRole)))
        self.files.itemActivated.connect(self._activated)
        refresh = QtWidgets.QPushButton("Refresh list")
        refresh.clicked.connect(self.refresh_files)

        self.info = QtWidgets.QPlainTextEdit()
        self.info.setReadOnly(True)
        self.info.setLineWrapMode(QtWidgets.QPlainTextEdit.LineWrapMode.NoWrap)
        self.info.setFont(QtGui.QFontDatabase.systemFont(QtGui.QFontDatabase.SystemFont.FixedFont))
        self.channels = QtWidgets.QListWidget()
        self.channels.setSelectionMode(QtWidgets.QAbstractItemView.SelectionMode.ExtendedSelection)
        self.channels.itemSelectionChanged.connect(self.plot_selected)
        # one stacked plot per unit (position and torque never share an axis), time axes linked
        self.plot = pg.GraphicsLayoutWidget()
        self.plot.setBackground("w")
        self.unit_plots: dict[str, pg.PlotItem] = {}

        # analysis controls
        self.analysis_buttons: dict[str, QtWidgets.QPushButton] = {}
        buttons = QtWidgets.QGridLayout()  # one button per registry analysis, four to a row (fits 1280 px)
        for i, (name, title) in enumerate(analyses.titles().items()):
            b = QtWidgets.QPushButton(title.split(" (")[0])
            why = analyses.availability(name)
            b.setEnabled(not why)
            b.setToolTip(why or title)
            b.clicked.connect(lambda _c=False, n=name: self.analyse(n))
            buttons.addWidget(b, i // 4, i % 4)
            self.analysis_buttons[name] = b
        self.inertia_edit = QtWidgets.QLineEdit("")
        self.inertia_edit.setPlaceholderText("from identification")
        self.inertia_edit.setToolTip("inertia J for the skeleton analysis, kg*m^2 (kg on a linear axis); "
                                     "filled in by an identification")
        self.method_box = QtWidgets.QComboBox()
        self.method_box.addItems(["hilbert", "cwt"])
        opts = QtWidgets.QHBoxLayout()
        opts.addWidget(QtWidgets.QLabel("J (kg*m^2)"))
        opts.addWidget(self.inertia_edit)
        opts.addWidget(QtWidgets.QLabel("method"))
        self.method_box.setToolTip("instantaneous amplitude and frequency of the skeleton analysis: Hilbert "
                                   "transform or continuous wavelet transform")
        opts.addWidget(self.method_box)
        opts.addStretch(1)
        # the check box on a row of its own: the centre of a 1280 px screen holds no wider row
        incomplete_row = QtWidgets.QHBoxLayout()
        self.incomplete_box = QtWidgets.QCheckBox("analyse an incomplete run")
        self.incomplete_box.setToolTip("an aborted, crashed or short run, or one its drive marked unfit, is refused "
                                       "unless this is ticked; the result then says the record is incomplete "
                                       "(hilbench ... --allow-incomplete)")
        incomplete_row.addWidget(self.incomplete_box)
        incomplete_row.addStretch(1)
        # the model of an identification, saved as `hilbench identify --json` writes it; a model file as the
        # residual loop's start (what `hilbench residual --start MODEL.json` does)
        self.save_model_button = QtWidgets.QPushButton("Save model...")
        self.save_model_button.setToolTip("write the identified model file (JSON), as hilbench identify RUN --json "
                                          "MODEL.json does; run an identification first")
        self.save_model_button.setEnabled(False)
        self.save_model_button.clicked.connect(self._save_model_dialog)
        self.start_edit = QtWidgets.QLineEdit("")
        self.start_edit.setPlaceholderText("residual start: model file (.json); empty: J + Maxwell-slip")
        self.start_edit.setToolTip("a model file written by an identification (Save model..., hilbench identify) or "
                                   "hilbench compare: the residual loop starts from its terms")
        start_browse = QtWidgets.QPushButton("...")
        start_browse.setFixedWidth(30)
        start_browse.setToolTip("choose the residual loop's start model file")
        start_browse.clicked.connect(self._browse_start)
        model_row = QtWidgets.QHBoxLayout()
        model_row.addWidget(self.save_model_button)
        model_row.addWidget(self.start_edit, 1)
        model_row.addWidget(start_browse)
        self.analysis_status = QtWidgets.QLabel(self._availability_text())
        self.analysis_status.setWordWrap(True)
        self.numbers = QtWidgets.QTableWidget(0, 3)
        self.numbers.setHorizontalHeaderLabels(["quantity", "value", "unit"])
        self.numbers.verticalHeader().setVisible(False)
        # the value and unit columns fit their text; the quantity column takes the rest (elided in the middle,
        # the whole text in the tooltip), so the unit column is always on screen
        header = self.numbers.horizontalHeader()
        header.setSectionResizeMode(0, QtWidgets.QHeaderView.ResizeMode.Stretch)
        header.setSectionResizeMode(1, QtWidgets.QHeaderView.ResizeMode.ResizeToContents)
        header.setSectionResizeMode(2, QtWidgets.QHeaderView.ResizeMode.ResizeToContents)
        self.numbers.setTextElideMode(QtCore.Qt.TextElideMode.ElideMiddle)
        self.numbers.setWordWrap(False)
        self.numbers.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.figures = pg.GraphicsLayoutWidget()
        self.figures.setBackground("w")

        left = QtWidgets.QVBoxLayout()
        runs_label = ElidedLabel(f"Runs in {self.runs_dir}/")  # a long folder path never widens the window
        left.addWidget(runs_label)
        left.addWidget(self.files, 1)
        left.addWidget(refresh)
        left.addWidget(QtWidgets.QLabel("Channels"))
        left.addWidget(self.channels, 1)
        left_w = QtWidgets.QWidget()
        left_w.setLayout(left)

        data_tab = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        data_tab.addWidget(self.plot)
        data_tab.addWidget(self.info)
        data_tab.setSizes([500, 200])
        analysis_tab = QtWidgets.QWidget()
        al = QtWidgets.QVBoxLayout(analysis_tab)
        al.addLayout(buttons)
        al.addLayout(opts)
        al.addLayout(incomplete_row)
        al.addLayout(model_row)
        al.addWidget(self.analysis_status)
        # table above the plots: side by side, a 1280 px screen left the table too narrow for its unit column
        split = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        split.addWidget(self.numbers)
        split.addWidget(self.figures)
        split.setSizes([200, 400])
        al.addWidget(split, 1)
        self.tabs = QtWidgets.QTabWidget()
        self.tabs.addTab(data_tab, "Channels")
        self.tabs.addTab(analysis_tab, "Analysis")

        top = QtWidgets.QHBoxLayout()
        top.addWidget(self.path_edit, 1)
        top.addWidget(browse)
        top.addWidget(open_button)
        top.addWidget(self.follow_box)
        body = QtWidgets.QSplitter(QtCore.Qt.Orientation.Horizontal)
        body.addWidget(left_w)
        body.addWidget(self.tabs)
        body.setSizes([190, 470])
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(body, 1)

        self.follow_timer = QtCore.QTimer(self)
        self.follow_timer.timeout.connect(self.follow)
        self.refresh_files()

    @staticmethod
    def _availability_text() -> str:
        missing = [f"{t}: {why}" for n, t in analyses.titles().items() if (why := analyses.availability(n))]
        return "<br>".join(missing)

    # ------------------------------------------------------------- files
    def refresh_files(self) -> None:
        self.files.clear()
        if not self.runs_dir.is_dir():
            return
        paths = sorted(self.runs_dir.glob("*.h5"), key=lambda p: p.stat().st_mtime, reverse=True)
        for p in paths:
            item = QtWidgets.QListWidgetItem(p.name)
            item.setToolTip(str(p))
            item.setData(QtCore.Qt.ItemDataRole.UserRole, str(p))
            self.files.addItem(item)

    def _activated(self, item: QtWidgets.QListWidgetItem) -> None:
        path = item.data(QtCore.Qt.ItemDataRole.UserRole)
        if self.run is None or str(self.run.path) != str(path):  # the click before a double click opened it
            self.open(path)

    def _browse(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Open run file", str(self.runs_dir),
                                                        "HDF5 run files (*.h5);;all files (*)")
        if path:
            self.open(path)

    def open(self, path: str) -> bool:
        """Open ``path``; a bad file gives a message in the window, never an exception."""
        from hilbench.common.runfile import open_run

        path = str(path).strip()
        if not path:
            self.message.emit("enter a run file name", True)
            return False
        try:
            run = open_run(path)
        except Exception as exc:
            self.message.emit(f"cannot open {path}: {one_line(exc)}", True)
            return False
        if path != self.path_edit.text():  # the model of another run is not this run's: nothing to save
            self.save_model_button.setEnabled(False)
        self.close_run()
        self.run = run
        self.path_edit.setText(path)
        self.channels.blockSignals(True)
        self.channels.clear()
        for name in run.channels:
            if name == SAMPLE_INDEX:
                continue
            self.channels.addItem(f"{name}")
        self.channels.blockSignals(False)
        for i in range(self.channels.count()):
            if self.channels.item(i).text() in ("torque", "position"):
                self.channels.item(i).setSelected(True)
        if not self.channels.selectedItems() and self.channels.count():
            self.channels.item(self.channels.count() - 1).setSelected(True)
        self.follow_box.setChecked(run.status == "running")
        self.show_info()
        self.plot_selected()
        self.message.emit(f"opened {path} ({run.status}, {run.n_samples} samples)", False)
        return True

    def close_run(self) -> None:
        if self.run is not None:
            self.run.close()
            self.run = None

    def show_info(self) -> None:
        r = self.run
        if r is None:
            return
        self.info.setPlainText("\n".join(describe_run(r)))

    def _on_follow(self, on: bool) -> None:
        if on:
            self.follow_timer.start(1000)
        else:
            self.follow_timer.stop()

    def follow(self) -> None:
        """Pick up samples a live writer flushed; stop following once the run is finished."""
        if self.run is None:
            return
        try:
            before = self.run.n_samples
            after = self.run.refresh()
        except Exception as exc:
            self.message.emit(f"cannot refresh {self.run.path}: {one_line(exc)}", True)
            self.follow_box.setChecked(False)
            return
        if after != before:
            self.plot_selected()
        if self.run.status != "running":
            self.follow_box.setChecked(False)
            self.show_info()

    # ------------------------------------------------------------- plotting
    def plot_selected(self) -> None:
        self.plot.clear()
        self.unit_plots = {}
        if self.run is None:
            return
        names = [item.text() for item in self.channels.selectedItems()]
        try:
            t = self.run.channel("t")
            groups: dict[str, list[str]] = {}
            for name in names:
                groups.setdefault(self.run.unit(name), []).append(name)
            for row, (unit, members) in enumerate(groups.items()):
                item = self.plot.addPlot(row=row, col=0)
                item.showGrid(x=True, y=True, alpha=0.3)
                item.addLegend(offset=(5, 5), labelTextColor="k")
                for side in ("left", "bottom"):  # the unit stays the channel's unit: no "(x0.001)"
                    item.getAxis(side).enableAutoSIPrefix(False)
                item.setClipToView(True)
                item.setDownsampling(auto=True, mode="peak")
                item.setLabel("left", f"{', '.join(members)} ({unit})")
                item.setLabel("bottom", "t (s)")
                if self.unit_plots:
                    item.setXLink(next(iter(self.unit_plots.values())))
                self.unit_plots[unit] = item
                for name in members:
                    y = self.run.channel(name)
                    n = min(t.size, y.size)
                    colour = COLOURS[names.index(name) % len(COLOURS)]
                    item.plot(t[:n], np.asarray(y[:n], dtype=float), pen=pg.mkPen(colour), name=f"{name} ({unit})")
        except Exception as exc:
            self.message.emit(f"cannot plot: {one_line(exc)}", True)

    # ------------------------------------------------------------- analyses
    def analyse(self, name: str) -> None:
        if self.run is None:
            self.message.emit("open a run file first", True)
            return
        if self.worker is not None and self.worker.isRunning():
            self.message.emit("an analysis is still running", True)
            return
        options = {"method": self.method_box.currentText(),
                   "allow_incomplete": self.incomplete_box.isChecked()}
        if self.start_edit.text().strip():
            options["start_model"] = self.start_edit.text().strip()
        text = self.inertia_edit.text().strip()
        if text:
            try:
                options["inertia"] = float(text)
            except ValueError:
                self.message.emit(f"J = {text!r} is not a number (kg*m^2)", True)
                return
        self.analysis_status.setText(f"running {analyses.titles().get(name, name)} ...")
        self.tabs.setCurrentIndex(1)
        worker = AnalysisWorker(name, self.run.path, options)
        worker.done.connect(self.show_result, QtCore.Qt.ConnectionType.QueuedConnection)
        worker.failed.connect(self._analysis_failed, QtCore.Qt.ConnectionType.QueuedConnection)
        self.worker = worker
        worker.start()

    def save_model(self, target: str) -> bool:
        """Write the last identification's model file to ``target``; a message either way."""
        doc = self.last_result.model_document if self.last_result is not None else None
        if doc is None:
            self.message.emit("run an identification first: there is no model to save", True)
            return False
        try:
            path = analyses.save_model(doc, target, [self.path_edit.text()])
        except Exception as exc:  # a bad name, a full disk: said in the window
            self.message.emit(f"cannot save the model: {one_line(exc)}", True)
            return False
        self.message.emit(f"model saved to {path}", False)
        return True

    def _save_model_dialog(self) -> None:
        run = Path(self.path_edit.text() or "run.h5")
        default = str(run.with_name(f"{run.stem}-model.json"))
        path, _ = QtWidgets.QFileDialog.getSaveFileName(self, "Save model", default, "model files (*.json)")
        if path:
            self.save_model(path)

    def _browse_start(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Residual loop: start model", str(self.runs_dir),
                                                        "model files (*.json);;all files (*)")
        if path:
            self.start_edit.setText(path)

    def _analysis_failed(self, text: str) -> None:
        self.analysis_status.setText(f"<span style='color:#c00000'>{text}</span>")
        self.message.emit(text, True)

    def show_result(self, result: analyses.AnalysisResult) -> None:
        self.last_result = result
        self.save_model_button.setEnabled(result.model_document is not None)
        warn = "".join(f"<br><span style='color:#d08000'>warning: {w}</span>" for w in result.warnings)
        # a sentence (the residual verdict) is read above the table, wrapped, not cut in a cell
        long = [(q, v) for q, v, u in result.numbers if len(v) > LONG_VALUE and not u]
        rows = [r for r in result.numbers if not (len(r[1]) > LONG_VALUE and not r[2])]
        text = "".join(f"<br>{q}: <b>{v}</b>" for q, v in long)
        self.analysis_status.setText(f"<b>{result.title}</b>{text}{warn}")
        self.numbers.setRowCount(len(rows))
        for row, values in enumerate(rows):
            for col, v in enumerate(values):
                item = QtWidgets.QTableWidgetItem(v)
                item.setToolTip(v)
                self.numbers.setItem(row, col, item)
        if result.title.startswith("Identification"):
            for q, v, _u in result.numbers:
                if q == "inertia J":
                    self.inertia_edit.setText(v)
        self.figures.clear()
        for i, fig in enumerate(result.figures):
            p = self.figures.addPlot(row=i, col=0, title=fig.title)
            xs = [np.asarray(c[1], float) for c in fig.curves] or [np.zeros(0)]
            ys = [np.asarray(c[2], float) for c in fig.curves] or [np.zeros(0)]
            fx, xlabel = scaled_label(fig.xlabel, np.concatenate(xs))
            fy, ylabel = scaled_label(fig.ylabel, np.concatenate(ys))
            for side, text in (("bottom", xlabel), ("left", ylabel)):
                p.getAxis(side).enableAutoSIPrefix(False)  # the unit is in the label, scaled above
                p.setLabel(side, text)
            p.showGrid(x=True, y=True, alpha=0.3)
            if len(fig.curves) > 1:
                p.addLegend(offset=(5, 5), labelTextColor="k")
            for j, (label, x, y) in enumerate(fig.curves):
                pen = curve_pen(label, j)
                x, y = fx * np.asarray(x, float), fy * np.asarray(y, float)
                if fig.scatter:
                    p.plot(x, y, pen=None, symbol="o", symbolSize=3, symbolPen=None, symbolBrush=pen["color"],
                           name=label)
                else:
                    p.plot(x, y, pen=pg.mkPen(**pen), name=label)
        self.message.emit(f"{result.title}: done", False)


def _value(value) -> str:
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def _entries(values: dict, units: dict[str, str], indent: str = "  ") -> list[str]:
    """``key = value unit`` lines, one per entry, keys aligned; nested dicts indented."""
    width = max((len(str(k)) for k in values), default=0)
    lines = []
    for key, value in sorted(values.items()):
        if isinstance(value, dict):
            lines.append(f"{indent}{key}:")
            lines += _entries(value, units, indent + "  ")
            continue
        if isinstance(value, list | tuple):
            text = ", ".join(_value(v) for v in value)
        else:
            text = _value(value)
        unit = units.get(str(key), "")
        lines.append(f"{indent}{str(key):<{width}} = {text}{' ' + unit if unit and unit != '1' else ''}")
    return lines


def describe_run(r) -> list[str]:
    """The metadata pane: one fact per line, units named, dicts spelled out as ``key = value unit``."""
    from hilbench.bench.acquisition.device_options import DEVICE_OPTIONS
    from hilbench.bench.acquisition.protocols import PROTOCOLS

    device_units = {k: unit for k, (unit, _text) in DEVICE_OPTIONS.items()}
    device_units.update({"sample_rate": "Hz", "sample_period": "s"})
    params = dict(r.protocol_params) if isinstance(r.protocol_params, dict) else {}
    proto_units = params.pop("units", None)
    if not isinstance(proto_units, dict):
        cls = PROTOCOLS.get(r.protocol_name or "")
        mode = str(params.get("mode", "current"))
        proto_units = {k: spec.unit_for(mode) for k, spec in cls.specs().items()} if cls is not None else {}
    config = getattr(r, "config", None)
    lines = [
        f"{r.path}",
        f"status      {r.status}",
        f"protocol    {r.protocol_name or '-'}",
        f"samples     {r.n_samples} at {r.sample_rate:g} Hz ({r.duration:.6g} s)",
        f"axis        {r.axis}",
        f"start       {r.start_time}",
        f"end         {r.end_time or '-'}",
        f"operator    {r.meta.get('operator', '') or '-'}",
        f"notes       {r.meta.get('notes', '') or '-'}",
        "device:",
        *(_entries(r.device, device_units) if isinstance(r.device, dict) else [f"  {r.device}"]),
        "device configuration:",
        *(_entries(config, device_units) if isinstance(config, dict) and config else ["  -"]),
        "protocol parameters:",
        *(_entries(params, proto_units) if params else ["  -"]),
        "channels:",
        *[f"  {name:<14} {r.unit(name)}" for name in r.channels],
        f"events: {len(r.events)}",
    ]
    for e in r.events:
        lines.append(f"  t = {e['t']:<10.6g} s  #{e[SAMPLE_INDEX]:<9} {e['kind']:<7} {e['message']}")
    return lines
