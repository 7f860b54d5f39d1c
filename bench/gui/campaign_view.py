"""Campaign view: load a campaign TOML, see its planned runs, play it on the connected device with per-run
progress, and resume an interrupted one (runs whose file says ``completed`` are skipped). A finished campaign is
analysed from here: *Analyse* runs ``hilbench analyse`` on its folder and *Drift* runs ``hilbench drift`` on the
results, each in its own process (bench.gui.command_process). The Results tab shows an analysed campaign: the runs
table and the drift charts of ``hilbench drift``."""

from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any

from PySide6 import QtCore, QtWidgets

from hilbench.bench.gui.command_process import CommandProcess
from hilbench.bench.gui.plot_style import style_plot, style_view
from hilbench.bench.gui.worker import one_line
from hilbench.common.metrics import UNIT, is_fraction
from hilbench.common.units import EFFORT

COLUMNS = ("run", "protocol", "duration (s)", "state", "progress")
#: the results table: (header, column of results.parquet, scale to the shown unit); identify rows,
#: numbered in start order. The headers get their units from the runs' axis (:func:`result_headers`).
RESULT_COLUMNS = (("#", "order", 1.0), ("run", "key", None), ("repeat", "repeat", None), ("status", "status", None),
                  ("inertia J", "inertia", 1.0), ("break-away torque", "breakaway", 1.0),
                  ("viscous coefficient b", "viscous", 1.0),
                  ("validation torque NRMSE", "validation_torque_nrmse", 100.0),
                  ("winding", "temperature_mean", 1.0), ("verdict / reason", "verdict", None))


def result_headers(axis: str = "rotary") -> list[str]:
    """The results table's headers with the units of a run on ``axis`` (a break-away force on a linear one) and
    percent for an NRMSE (the table keeps the fraction: scale 100)."""
    from hilbench.bench.campaign_analysis.table import column_units

    units = column_units(axis)
    out = []
    for head, column, scale in RESULT_COLUMNS:
        unit = UNIT if is_fraction(column) else units.get(column, "")
        head = head.replace("torque", EFFORT[axis]) if column == "breakaway" else head
        out.append(f"{head}\n({unit})" if scale is not None and unit not in ("", "1") else head)
    return out
#: a parameter's name on its chart's axis: the table's (a label longer than the chart is tall is cut)
SHORT_NAMES = {"inertia": "J", "breakaway": "break-away", "viscous": "b", "temperature_mean": "winding"}
#: the drift charts, stacked and x-linked as the live plots are: (key, y axis label; {unit}: the parameter's)
CHARTS = (("value", "{name} ({unit})"), ("ewma", "EWMA (z)"), ("cusum", "CUSUM (z)"))
#: rows the results table shows without scrolling (more scroll; the charts keep the rest of the height)
TABLE_ROWS = 6


class CampaignView(QtWidgets.QWidget):
    """Emits ``start_requested(campaign, out_dir, resume)``; the main window runs it in a worker thread
    on the connected bench and feeds :meth:`show_progress` and :meth:`show_finished`."""

    start_requested = QtCore.Signal(object, str, bool)
    abort_requested = QtCore.Signal()
    message = QtCore.Signal(str, bool)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.campaign = None
        self.path_edit = QtWidgets.QLineEdit()
        self.path_edit.setPlaceholderText("campaign file (.toml)")
        browse = QtWidgets.QPushButton("Browse...")
        browse.clicked.connect(self._browse)
        self.load_button = QtWidgets.QPushButton("Load")
        self.load_button.clicked.connect(self.load)
        self.out_edit = QtWidgets.QLineEdit("campaign-out")
        self.out_edit.setToolTip("folder for the run files and index.json")
        self.resume_box = QtWidgets.QCheckBox("Resume")
        self.resume_box.setToolTip("skip the runs the output folder's index says are completed")
        self.start_button = QtWidgets.QPushButton("Start campaign")
        self.start_button.setEnabled(False)
        self.start_button.clicked.connect(self._on_start)
        self.abort_button = QtWidgets.QPushButton("Abort")
        self.abort_button.setEnabled(False)
        self.abort_button.clicked.connect(self.abort_requested)
        self.table = QtWidgets.QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(COLUMNS)
        self.table.verticalHeader().setVisible(False)
        self.table.horizontalHeader().setStretchLastSection(True)
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.status = QtWidgets.QLabel("")
        self.status.setWordWrap(True)
        self.results_edit = QtWidgets.QLineEdit()
        self.results_edit.setPlaceholderText("default: OUTPUT/analysis")
        self.results_edit.setToolTip("results folder of hilbench analyse (default: the output folder's analysis/)")
        self.analyse_button = QtWidgets.QPushButton("Analyse")
        self.analyse_button.setToolTip("hilbench analyse on the output folder (identify every run) into the "
                                       "results folder, in its own process; then the Results tab")
        self.analyse_button.clicked.connect(self.analyse)
        self.drift_button = QtWidgets.QPushButton("Drift")
        self.drift_button.setToolTip("hilbench drift on the results folder: drift.json, the figures and the "
                                     "campaign page in RESULTS/drift/")
        self.drift_button.clicked.connect(self.drift)
        self.analysis_bar = QtWidgets.QProgressBar()
        self.analysis_bar.setRange(0, 1)
        self.analysis_bar.setValue(0)
        self.analysis_bar.setFormat("")  # "%v/%m runs" once an analysis runs
        #: options added to ``hilbench analyse`` (the Dask dashboard is not shown here: it costs seconds)
        self.analyse_options: tuple[str, ...] = ("--no-dashboard",)
        self.command: CommandProcess | None = None
        self._campaign_running = False
        self._bars: dict[str, QtWidgets.QProgressBar] = {}
        self._rows: dict[str, int] = {}

        plan = QtWidgets.QWidget()
        layout = QtWidgets.QVBoxLayout(plan)
        # one row each: the campaign file, its output folder and run, its results folder and analysis
        for name, edit, *buttons in (("Campaign", self.path_edit, browse, self.load_button),
                                     ("Output folder", self.out_edit, self.resume_box, self.start_button,
                                      self.abort_button),
                                     ("Results folder", self.results_edit, self.analyse_button, self.drift_button,
                                      self.analysis_bar)):
            row = QtWidgets.QHBoxLayout()
            row.addWidget(QtWidgets.QLabel(name))
            row.addWidget(edit, 1)
            for button in buttons:
                row.addWidget(button)
            layout.addLayout(row)
        layout.addWidget(self.status)
        layout.addWidget(self.table, 1)
        self.results = CampaignResults()
        self.tabs = QtWidgets.QTabWidget()
        self.tabs.addTab(plan, "Plan and run")
        self.tabs.addTab(self.results, "Results")
        QtWidgets.QVBoxLayout(self).addWidget(self.tabs)
        self.out_edit.textChanged.connect(self._update_analysis_buttons)
        self.results_edit.textChanged.connect(self._update_analysis_buttons)
        self._update_analysis_buttons()

    def _browse(self) -> None:
        path, _ = QtWidgets.QFileDialog.getOpenFileName(self, "Campaign file", "", "TOML (*.toml)")
        if path:
            self.path_edit.setText(path)
            self.load()

    def load(self) -> bool:
        """Parse and validate the campaign file; problems are shown with file and line."""
        from hilbench.bench.acquisition.campaign import load_campaign, read_index

        path = self.path_edit.text().strip()
        try:
            campaign = load_campaign(path)
        except Exception as exc:
            self.campaign = None
            self.start_button.setEnabled(False)
            self.status.setText(f"<span style='color:#c00000'>{one_line(exc)}</span>")
            self.message.emit(f"campaign not loaded: {one_line(exc)}", True)
            return False
        self.campaign = campaign
        if self.out_edit.text().strip() in ("", "campaign-out"):
            self.out_edit.setText(str(Path(path).with_suffix("")) + "-runs")
        try:
            done = read_index(Path(self.out_edit.text()))
        except Exception:
            done = {}
        self.resume_box.setChecked(bool(done))
        self.table.setRowCount(len(campaign.runs))
        self._bars.clear()
        self._rows.clear()
        total = 0.0
        for row, planned in enumerate(campaign.runs):
            duration = planned.protocol.duration
            total += duration
            state = done.get(planned.key, {}).get("status", "planned")
            for col, text in enumerate((planned.key, planned.protocol.name, f"{duration:.4g}", state)):
                self.table.setItem(row, col, QtWidgets.QTableWidgetItem(text))
            bar = QtWidgets.QProgressBar()
            bar.setRange(0, 1000)
            bar.setValue(1000 if state == "completed" else 0)
            self.table.setCellWidget(row, 4, bar)
            self._bars[planned.key] = bar
            self._rows[planned.key] = row
        self.status.setText(f"{len(campaign.runs)} runs, {total:.4g} s of excitation, device "
                            f"{campaign.device}" + (f"; {len(done)} already in the index" if done else ""))
        self.start_button.setEnabled(True)
        self._update_analysis_buttons()
        return True

    def _on_start(self) -> None:
        if self.campaign is None and not self.load():
            return
        self.start_requested.emit(self.campaign, self.out_edit.text().strip(), self.resume_box.isChecked())

    def set_running(self, running: bool) -> None:
        self.start_button.setEnabled(not running and self.campaign is not None)
        self.load_button.setEnabled(not running)
        self.abort_button.setEnabled(running)
        self._campaign_running = running
        self._update_analysis_buttons()

    def show_progress(self, item) -> None:
        """One :class:`bench.acquisition.campaign.CampaignProgress` (GUI thread)."""
        row = self._rows.get(item.key)
        if row is None:
            return
        self.table.item(row, 3).setText(item.state)
        bar = self._bars[item.key]
        if item.run is not None and item.run.total:
            bar.setValue(int(1000 * item.run.done / item.run.total))
        elif item.state in ("completed", "skipped"):
            bar.setValue(1000)
        self.status.setText(f"run {item.index + 1}/{item.total}: {item.key} {item.state}")

    def show_finished(self, text: str, error: bool = False) -> None:
        self.set_running(False)
        self._say(text + ("" if error else "; Analyse reads its results"), error)

    def _say(self, text: str, error: bool = False) -> None:
        colour = "#c00000" if error else "#008000"
        self.status.setText(f"<span style='color:{colour}'>{html.escape(text)}</span>")

    # ------------------------------------------------------------------ analyse and drift
    def campaign_folder(self) -> Path:
        return Path(self.out_edit.text().strip())

    def results_folder(self) -> Path:
        """The results folder: as typed, else ``hilbench analyse``'s default (CAMPAIGN/analysis)."""
        typed = self.results_edit.text().strip()
        return Path(typed) if typed else self.campaign_folder() / "analysis"

    @property
    def busy(self) -> bool:
        return self.command is not None and self.command.running()

    def _update_analysis_buttons(self) -> None:
        """Analyse: a campaign folder with its index and nothing running; Drift: a results table to read."""
        from hilbench.bench.acquisition.campaign import INDEX_NAME
        from hilbench.bench.campaign_analysis.table import TABLE_NAME

        free = not self._campaign_running and not self.busy
        has_campaign = bool(self.out_edit.text().strip()) and (self.campaign_folder() / INDEX_NAME).is_file()
        self.analyse_button.setEnabled(free and has_campaign)
        self.drift_button.setEnabled(free and (self.results_folder() / TABLE_NAME).is_file())

    def _run_command(self, args: list[str], done) -> bool:
        if self._campaign_running or self.busy:
            self._say("wait until the campaign or the running analysis has finished", error=True)
            return False
        self.command = CommandProcess(args, self)
        self.command.progress.connect(self._on_command_progress)
        self.command.finished.connect(done)
        self.command.start()
        self._update_analysis_buttons()
        return True

    def _on_command_progress(self, done: int, total: int) -> None:
        self.analysis_bar.setRange(0, max(total, 1))
        self.analysis_bar.setValue(done)

    def analyse(self) -> bool:
        """``hilbench analyse CAMPAIGN -o RESULTS`` in its own process; the progress bar follows its runs."""
        folder, results = self.campaign_folder(), self.results_folder()
        self.analysis_bar.setFormat("%v/%m runs")
        self.analysis_bar.setRange(0, 0)  # busy until the first count: planning hashes every run file
        started = self._run_command(["analyse", str(folder), "-o", str(results), *self.analyse_options],
                                    self._analysed)
        if started:
            self._say(f"analysing {folder} into {results} (hilbench analyse, its own process)")
        else:
            self.analysis_bar.setRange(0, 1)
        return started

    def _analysed(self, ok: bool, text: str) -> None:
        self.analysis_bar.setRange(0, max(self.analysis_bar.maximum(), 1))
        self.command = None
        self._update_analysis_buttons()
        if not ok:
            self._say(f"analyse failed: {text}", error=True)
            self.message.emit(f"analyse failed: {text}", True)
            return
        self.analysis_bar.setValue(self.analysis_bar.maximum())
        self._say(f"analysed: {text}; Drift writes the drift report and the campaign page")
        self.message.emit(f"campaign analysed into {self.results_folder()}", False)
        self.results.path_edit.setText(str(self.results_folder()))
        self.results.load()
        self.tabs.setCurrentWidget(self.results)

    def drift(self) -> bool:
        """``hilbench drift RESULTS`` (an earlier report in RESULTS/drift is replaced) in its own process."""
        results = self.results_folder()
        started = self._run_command(["drift", str(results), "--overwrite"], self._drifted)
        if started:
            self._say(f"drift report of {results} (hilbench drift, its own process)")
        return started

    def _drifted(self, ok: bool, text: str) -> None:
        lines = self.command.lines if self.command is not None else []
        self.command = None
        self._update_analysis_buttons()
        if not ok:
            self._say(f"drift failed: {text}", error=True)
            self.message.emit(f"drift failed: {text}", True)
            return
        report = self.results_folder() / "drift" / "drift.json"
        pages = [line.removeprefix("page: ") for line in lines if line.startswith("page: ")]
        where = f"drift report {report}" + (f", page {', '.join(pages)}" if pages else "")
        self._say(f"{where}; {text}")
        self.message.emit(where, False)

    def shutdown(self) -> None:
        """Stop a running analysis (the window closes)."""
        if self.command is not None:
            self.command.kill()


class CampaignResults(QtWidgets.QWidget):
    """An analysed campaign: the identify rows of ``RESULTS/results.parquet`` as a table, and for the chosen
    parameter the drift charts of ``hilbench drift`` (analysis.drift.monitor with its defaults, the baseline rule
    included, so the tab and the command agree): the value with its standard error and the baseline fit, the EWMA
    with its limits, the CUSUM with h, and the change points as vertical lines. A campaign with several series
    (protocols or analysis settings) shows the first series that follows the parameter; the status line names it."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        import pyqtgraph as pg

        super().__init__(parent)
        self.rows: list[dict[str, Any]] = []
        self.drift = None
        self.path_edit = QtWidgets.QLineEdit()
        self.path_edit.setPlaceholderText("results folder of hilbench analyse (or its results.parquet)")
        self.load_button = QtWidgets.QPushButton("Load results")
        self.load_button.clicked.connect(self.load)
        self.parameter = QtWidgets.QComboBox()
        self.parameter.addItems(["breakaway", "viscous", "inertia"])
        self.parameter.currentTextChanged.connect(lambda _name: self.show_drift())
        self.status = QtWidgets.QLabel("")
        self.status.setWordWrap(True)
        self.table = QtWidgets.QTableWidget(0, len(RESULT_COLUMNS))
        self.table.setHorizontalHeaderLabels(result_headers())
        self.table.verticalHeader().setVisible(False)
        # compact rows (the default section is about 1.5 lines tall), headers on two lines (name, unit): each
        # column as wide as its widest line, so no header is cut ("reak-away (N" was)
        self.table.verticalHeader().setDefaultSectionSize(self.table.fontMetrics().height() + 6)
        self.table.horizontalHeader().setStretchLastSection(True)
        self.table.setEditTriggers(QtWidgets.QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.setSortingEnabled(True)
        self.units: dict[str, str] = {}
        self.axis = "rotary"  # the loaded rows' axis (hilbench.common.units.rows_axis), which the units follow
        self.graphics = style_view(pg.GraphicsLayoutWidget())
        self.plots: dict[str, pg.PlotItem] = {}
        for row, (key, _label) in enumerate(CHARTS):
            plot = style_plot(self.graphics.addPlot(row=row, col=0))
            plot.getAxis("left").setWidth(90)  # one width: the three charts' x axes line up
            if row:
                plot.setXLink(self.plots["value"])
            if row < len(CHARTS) - 1:
                plot.hideAxis("bottom")
            self.plots[key] = plot
        self.plots["cusum"].setLabel("bottom", "run (# in the table: start order)")
        top = QtWidgets.QHBoxLayout()
        top.addWidget(self.path_edit, 1)
        top.addWidget(self.load_button)
        top.addWidget(QtWidgets.QLabel("parameter"))
        top.addWidget(self.parameter)
        self.split = QtWidgets.QSplitter(QtCore.Qt.Orientation.Vertical)
        self.split.setChildrenCollapsible(False)
        self.split.addWidget(self.table)
        self.split.addWidget(self.graphics)
        self.split.setStretchFactor(0, 0)  # a taller window gives its height to the charts; the table keeps its rows
        self.split.setStretchFactor(1, 1)
        self._user_split = False  # the operator dragged the handle: keep their share until the next load
        self.split.splitterMoved.connect(self._on_split_moved)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(self.status)
        layout.addWidget(self.split, 1)
        self._label_charts()

    def _label_charts(self, values=()) -> None:
        """Each chart's y label; the parameter's in the engineering unit of ``values`` (SI): 0.004 N*m*s/rad
        reads 4 on a "(mN*m*s/rad)" axis, as the live plots do (the data stay SI, the axis scales its ticks)."""
        from hilbench.analysis.figure_style import engineering

        name = self.parameter.currentText()
        finite = [float(v) for v in values if v is not None and math.isfinite(v)]
        factor, unit = engineering(self.units.get(name) or "", finite) if finite else (1.0, self.units.get(name))
        for key, label in CHARTS:
            axis = self.plots[key].getAxis("left")
            axis.setScale(factor if key == "value" else 1.0)
            axis.setLabel(label.format(name=SHORT_NAMES.get(name, name), unit=unit or "-"))

    def _table_height(self) -> int:
        """Pixels the header and up to TABLE_ROWS rows need (all rows of a small campaign)."""
        rows = max(1, min(self.table.rowCount(), TABLE_ROWS))
        bar = self.table.horizontalScrollBar().sizeHint().height()
        header = max(self.table.horizontalHeader().height(), self.table.horizontalHeader().sizeHint().height())
        return (header + rows * self.table.verticalHeader().defaultSectionSize()
                + bar + 2 * self.table.frameWidth() + 6)

    def _on_split_moved(self, *_args) -> None:
        self._user_split = True

    def _share_height(self) -> None:
        """The table gets the height of its rows (up to TABLE_ROWS), the charts the rest (at least half); not
        after the operator moved the handle (until the next table is loaded)."""
        if self._user_split:
            return
        total = sum(self.split.sizes()) or self.split.height()
        table = min(self._table_height(), total // 2)
        self.split.setSizes([table, total - table])

    def load(self) -> bool:
        """Read the table; a missing or unreadable file is said in the status line."""
        import pyarrow.parquet as pq

        from hilbench.bench.campaign_analysis.table import TABLE_NAME
        from hilbench.common.units import rows_axis, schema_units

        path = Path(self.path_edit.text().strip())
        table = path if path.suffix == ".parquet" else path / TABLE_NAME
        try:
            read = pq.read_table(table)
            rows = [r for r in read.to_pylist() if r.get("step") == "identify"]
            axis = rows_axis(rows)
            units = schema_units(read.schema, axis)  # a linear axis reads N, kg, N*s/m (unit_linear)
        except Exception as exc:
            self.status.setText(f"<span style='color:#c00000'>{table}: {one_line(exc)}</span>")
            return False
        rows.sort(key=lambda r: (str(r.get("start_time")), str(r.get("campaign")), str(r.get("key"))))
        self.rows = rows
        self.units, self.axis = units, axis
        self._fill_table()
        return self.show_drift()

    def _fill_table(self) -> None:
        self.table.setSortingEnabled(False)
        self.table.setHorizontalHeaderLabels(result_headers(self.axis))  # units follow the runs' axis
        self.table.setRowCount(len(self.rows))
        for i, row in enumerate(self.rows):
            for j, (_header, column, scale) in enumerate(RESULT_COLUMNS):
                value = i + 1 if column == "order" else row.get(column)  # start order: sort back to it
                if column == "verdict" and row.get("status") != "ok":
                    value = row.get("error")
                item = QtWidgets.QTableWidgetItem()
                if scale is not None and value is not None:
                    item.setData(QtCore.Qt.ItemDataRole.DisplayRole, float(f"{value * scale:.6g}"))
                else:
                    item.setText("" if value is None else str(value))
                self.table.setItem(i, j, item)
        self.table.setSortingEnabled(True)
        self.table.sortByColumn(0, QtCore.Qt.SortOrder.AscendingOrder)
        self.table.resizeColumnsToContents()  # headers (their widest line) and values whole
        self.table.horizontalHeader().setStretchLastSection(True)
        self._user_split = False
        self._share_height()

    def resizeEvent(self, event) -> None:  # noqa: N802 - Qt API
        super().resizeEvent(event)
        self._share_height()

    def showEvent(self, event) -> None:  # noqa: N802 - Qt API: loaded while hidden, sized when shown
        super().showEvent(event)
        self._share_height()

    def show_drift(self) -> bool:
        """The drift charts of the chosen parameter; too few runs or no spread is said in the status line."""
        import numpy as np
        import pyqtgraph as pg

        from hilbench.analysis.drift.monitor import DriftSettings, monitor

        for plot in self.plots.values():
            plot.clear()
        name = self.parameter.currentText()
        self._label_charts()
        ok = sum(r.get("status") == "ok" for r in self.rows)
        try:
            report = monitor(self.rows, DriftSettings(parameters=(name,)))
        except Exception as exc:
            self.drift = None
            self.status.setText(f"{len(self.rows)} runs; no drift charts: {one_line(exc)}")
            return False
        if not report.series:  # every series too short or without spread: said, nothing to chart
            self.drift = None
            why = "; ".join(g.baseline_line() for g in report.groups)
            self.status.setText(f"{len(self.rows)} runs ({ok} ok); no drift charts: {why}")
            return False
        label, s = next(iter(report.series.items()))
        self._label_charts(s.value)
        self.drift = report.result_of(label)
        # x: each run's "#" in the table (start order over every row, failed ones included), so the chart and the
        # table name a run by one number
        order = {f"{r.get('campaign')}/{r.get('key')}": i + 1 for i, r in enumerate(self.rows)}
        x = np.array([order.get(run, np.nan) for run in self.drift.runs], dtype=float)
        value = self.plots["value"]
        value.addItem(pg.ErrorBarItem(x=x, y=s.value, height=2 * np.nan_to_num(s.se), pen="#888"))
        value.plot(x, s.value, pen=None, symbol="o", symbolSize=5, symbolBrush="#1f77b4", symbolPen="#1f77b4",
                   name=name)
        value.plot(x, s.fitted, pen=pg.mkPen("#d62728", width=2), name="baseline fit")
        self.plots["ewma"].plot(x, s.ewma, pen=pg.mkPen("#1f77b4", width=2), name="EWMA")
        for sign in (1, -1):
            self.plots["ewma"].plot(x, sign * s.ewma_limit, pen=pg.mkPen("#d62728", style=QtCore.Qt.PenStyle.DashLine))
        self.plots["cusum"].plot(x, s.cusum_hi, pen=pg.mkPen("#1f77b4", width=2), name="CUSUM +")
        self.plots["cusum"].plot(x, s.cusum_lo, pen=pg.mkPen("#2ca02c", width=2), name="CUSUM -")
        self.plots["cusum"].addItem(pg.InfiniteLine(s.cusum_h, angle=0, pen="#d62728"))
        for cp in s.change_points:
            for plot in self.plots.values():
                plot.addItem(pg.InfiniteLine(x[cp], angle=90, pen=pg.mkPen("#ff7f0e", width=2)))
        points = ", ".join(self.drift.runs[cp] for cp in s.change_points) or "none"
        series = f" in {len(report.groups)} series, shown: {label}" if len(report.groups) > 1 else ""
        self.status.setText(f"{len(self.rows)} runs ({ok} ok){series}; {self.drift.baseline_line()}; {name}: change "
                            f"points at {points}; EWMA alarms {len(s.ewma_alarms)}, CUSUM alarms "
                            f"{len(s.cusum_alarms)}")
        return True
