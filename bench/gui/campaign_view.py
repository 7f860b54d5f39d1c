"""Campaign view: load a campaign TOML, see its planned runs, play it on the connected device with per-run
progress, and resume an interrupted one (runs whose file says ``completed`` are skipped)."""

from __future__ import annotations

from pathlib import Path

from PySide6 import QtCore, QtWidgets

from hilbench.bench.gui.worker import one_line

COLUMNS = ("run", "protocol", "duration (s)", "state", "progress")


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
        self.resume_box = QtWidgets.QCheckBox("Resume (skip completed runs)")
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
        self._bars: dict[str, QtWidgets.QProgressBar] = {}
        self._rows: dict[str, int] = {}

        row1 = QtWidgets.QHBoxLayout()
        row1.addWidget(QtWidgets.QLabel("Campaign"))
        row1.addWidget(self.path_edit, 1)
        row1.addWidget(browse)
        row1.addWidget(self.load_button)
        row2 = QtWidgets.QHBoxLayout()
        row2.addWidget(QtWidgets.QLabel("Output folder"))
        row2.addWidget(self.out_edit, 1)
        row2.addWidget(self.resume_box)
        row2.addWidget(self.start_button)
        row2.addWidget(self.abort_button)
        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(row1)
        layout.addLayout(row2)
        layout.addWidget(self.status)
        layout.addWidget(self.table, 1)

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
        return True

    def _on_start(self) -> None:
        if self.campaign is None and not self.load():
            return
        self.start_requested.emit(self.campaign, self.out_edit.text().strip(), self.resume_box.isChecked())

    def set_running(self, running: bool) -> None:
        self.start_button.setEnabled(not running and self.campaign is not None)
        self.load_button.setEnabled(not running)
        self.abort_button.setEnabled(running)

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
        colour = "#c00000" if error else "#008000"
        self.status.setText(f"<span style='color:{colour}'>{text}</span>")
