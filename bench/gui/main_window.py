"""The operator's main window: device, live plots, protocol, E-STOP, run browser and campaigns.

Threads: the GUI thread only draws. :class:`~bench.gui.worker.DeviceWorker` (own QThread) connects, polls
status and clears faults; a :class:`~bench.gui.worker.RunWorker` QThread runs each protocol or campaign;
:class:`~bench.gui.worker.EStopLine` (own thread) sends E-STOP without waiting for anything else.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from PySide6 import QtCore, QtGui, QtWidgets

from hilbench.bench.gui.campaign_view import CampaignView
from hilbench.bench.gui.connection_panel import ConnectionPanel, identity_text
from hilbench.bench.gui.live_plot import LivePlot
from hilbench.bench.gui.protocol_panel import ProtocolPanel
from hilbench.bench.gui.run_browser import RunBrowser
from hilbench.bench.gui.worker import DeviceWorker, EStopLine, RunWorker, one_line
from hilbench.drivers.device import refusal

#: signals from worker threads always reach the GUI thread through its event queue
QUEUED = QtCore.Qt.ConnectionType.QueuedConnection
#: side panel widths, px: fixed, so a long status text wraps instead of pushing the centre around; with the
#: centre they fit a 1280 px wide screen
PANEL_WIDTHS = {"Device": 290, "Protocol": 330}
ESTOP_STYLE = ("QPushButton { background: #d00000; color: white; font-size: 20px; font-weight: bold; "
               "border: 3px solid #800000; border-radius: 8px; padding: 12px 28px; }"
               "QPushButton:pressed { background: #800000; }")


class MainWindow(QtWidgets.QMainWindow):
    """Args: ``device``: URL put in the connection panel (and connected at once with ``autoconnect``);
    ``runs_dir``: where new run files go and the browser looks; ``timeout``: device reply timeout, s."""

    _open_device = QtCore.Signal(str, float)
    _close_device = QtCore.Signal()
    _clear_faults = QtCore.Signal()
    _poll_device = QtCore.Signal()

    def __init__(self, device: str = "sim://", runs_dir: str | Path = "runs", timeout: float = 2.0,
                 autoconnect: bool = False, live_fps: float = 40.0, recent: list[str] | None = None) -> None:
        super().__init__()
        self.setWindowTitle("hilbench - operator")
        self.runs_dir = Path(runs_dir)
        self.timeout = timeout
        self.run_worker: RunWorker | None = None
        self._estop_worker: RunWorker | None = None  # the run an e-stop request is for (estop)
        self.run_kind = ""
        self.messages: list[tuple[float, str, bool]] = []
        self.device_info: dict | None = None
        self._last_progress = 0.0  # progress bar refreshed at most 10 times a second

        # threads first: the e-stop line exists before any device does
        self.estop_line = EStopLine()
        self.estop_line.on_trigger.append(self._abort_from_estop)
        self.estop_line.sent.connect(self._estop_sent, QUEUED)
        self.estop_line.failed.connect(self._estop_failed, QUEUED)
        self.device_thread = QtCore.QThread(self)
        self.device_thread.setObjectName("device")
        self.device = DeviceWorker(self.estop_line)
        self.device.moveToThread(self.device_thread)
        self._open_device.connect(self.device.open)
        self._close_device.connect(self.device.close)
        self._clear_faults.connect(self.device.clear_faults)
        self._poll_device.connect(self.device.poll)
        self.device_thread.start()

        # widgets
        self.connection = ConnectionPanel(recent=recent)
        self.connection.url_box.setCurrentText(device)
        self.protocol = ProtocolPanel(runs_dir=self.runs_dir)
        self.live = LivePlot(fps=live_fps)
        self.browser = RunBrowser(runs_dir=self.runs_dir)
        self.campaign = CampaignView()
        self.estop_button = QtWidgets.QPushButton("E-STOP  (Esc)")
        self.estop_button.setStyleSheet(ESTOP_STYLE)
        self.estop_button.setToolTip("zero the current and latch ESTOP now (clear faults to continue)")
        self.estop_button.setFocusPolicy(QtCore.Qt.FocusPolicy.NoFocus)
        self.estop_button.pressed.connect(self.estop)  # on press, not release: no waiting for the mouse
        self.estop_shortcut = QtGui.QShortcut(QtGui.QKeySequence(QtCore.Qt.Key.Key_Escape), self)
        self.estop_shortcut.setContext(QtCore.Qt.ShortcutContext.ApplicationShortcut)
        self.estop_shortcut.activated.connect(self.estop)
        self.banner = QtWidgets.QLabel("")
        self.banner.setWordWrap(True)
        self.banner.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)

        top = QtWidgets.QHBoxLayout()
        top.addWidget(self.banner, 1)
        top.addWidget(self.estop_button)
        self.tabs = QtWidgets.QTabWidget()
        self.tabs.addTab(self.live, "Live")
        self.tabs.addTab(self.browser, "Run browser")
        self.tabs.addTab(self.campaign, "Campaign")
        central = QtWidgets.QWidget()
        layout = QtWidgets.QVBoxLayout(central)
        layout.addLayout(top)
        layout.addWidget(self.tabs, 1)
        self.setCentralWidget(central)
        for panel, area in ((self.connection, QtCore.Qt.DockWidgetArea.LeftDockWidgetArea),
                            (self.protocol, QtCore.Qt.DockWidgetArea.RightDockWidgetArea)):
            dock = QtWidgets.QDockWidget(panel.title(), self)
            dock.setObjectName(panel.title())
            dock.setWidget(panel)
            panel.setFixedWidth(PANEL_WIDTHS.get(panel.title(), 300))
            panel.setTitle("")  # the dock's title bar names it
            dock.setFeatures(QtWidgets.QDockWidget.DockWidgetFeature.DockWidgetMovable
                             | QtWidgets.QDockWidget.DockWidgetFeature.DockWidgetFloatable)
            self.addDockWidget(area, dock)
        for tabs in (self.tabs, self.protocol.tabs, self.browser.tabs):
            tabs.currentChanged.connect(lambda _index: self._clear_error())
        self.statusBar().showMessage("not connected")
        self.resize(1280, 800)

        # wiring
        self.connection.connect_requested.connect(self.connect_device)
        self.connection.disconnect_requested.connect(self.disconnect_device)
        self.connection.clear_faults_requested.connect(self._clear_faults)
        self.device.connected.connect(self._on_connected, QUEUED)
        self.device.disconnected.connect(self._on_disconnected, QUEUED)
        self.device.status.connect(self.connection.show_state, QUEUED)
        self.device.failed.connect(self._on_device_failed, QUEUED)
        self.protocol.start_requested.connect(self.start_run)
        self.protocol.pause_requested.connect(self.pause_run)
        self.protocol.abort_requested.connect(self.abort_run)
        self.protocol.plan_requested.connect(self.start_plan)
        self.browser.message.connect(self.show_message)
        self.campaign.message.connect(self.show_message)
        self.campaign.start_requested.connect(self.start_campaign)
        self.campaign.abort_requested.connect(self.abort_run)
        if autoconnect:
            self.connect_device(device)

    # ------------------------------------------------------------------ messages
    def show_message(self, text: str, error: bool = False) -> None:
        """One line in the banner and the status bar (red for errors); kept in ``self.messages``."""
        self.messages.append((time.monotonic(), text, error))
        colour = "#c00000" if error else "#202020"
        self.banner.setText(f"<span style='color:{colour}'>{'Error: ' if error else ''}{text}</span>")
        self.statusBar().showMessage(text, 0 if error else 15000)

    def _clear_error(self) -> None:
        """A red error belongs to what the operator was doing; moving to another tab clears it (it stays in
        ``self.messages``)."""
        if self.messages and self.messages[-1][2]:
            self.banner.setText("")
            self.statusBar().clearMessage()

    # ------------------------------------------------------------------ device
    @property
    def connected(self) -> bool:
        return self.device_info is not None

    def connect_device(self, url: str) -> None:
        url = url.strip()
        self.connection.url_box.setCurrentText(url)
        if "://" not in url:
            self.show_message(f"{url!r} is not a device URL (sim://, serial:///dev/ttyUSB0, "
                              f"can://socketcan/can0)", error=True)
            self.connection.show_failed()
            return
        self.show_message(f"connecting to {url} ...")
        self.connection.connect_button.setEnabled(False)
        self._open_device.emit(url, self.timeout)

    def disconnect_device(self) -> None:
        if self.running:
            self.show_message("a run is in progress: abort it (or E-STOP) before disconnecting", error=True)
            return
        self._close_device.emit()

    def _on_connected(self, info: dict) -> None:
        self.device_info = info
        self.connection.show_connected(info)
        self.show_message(f"connected to {info['url']}: {identity_text(info['identity'])}")

    def _on_disconnected(self, reason: str) -> None:
        self.device_info = None
        self.connection.show_disconnected(reason)
        if reason:
            self.show_message(f"device disconnected: {reason}", error=True)
            if self.run_worker is not None:
                self.run_worker.control.abort()
        else:
            self.show_message("disconnected")

    def _on_device_failed(self, text: str) -> None:
        self.show_message(text, error=True)
        self.connection.show_failed()

    # ------------------------------------------------------------------ e-stop
    def estop(self) -> None:
        """E-STOP: hand the request to the dedicated e-stop thread at once, then tell the operator."""
        # the run this e-stop is for: the one running now (the e-stop thread acts after the command went out, and a
        # run started by then, e.g. after an idle e-stop and a fault clear, is not this request's to abort)
        self._estop_worker = self.run_worker
        self.estop_line.trigger()
        self.show_message("E-STOP requested", error=True)

    def _abort_from_estop(self) -> None:  # e-stop thread, after the command went out
        """A streaming run ends by itself on the latched fault (and records it); a paused run, or one
        whose device did not answer, is aborted after a grace period so it never waits forever."""
        worker = self._estop_worker
        if worker is None:
            return
        if worker.control.paused:
            worker.control.abort("E-STOP while paused: aborted")
            return
        reason = "E-STOP: the run did not end by itself within 1 s of the e-stop; aborted"
        timer = threading.Timer(1.0, lambda: worker.control.abort(reason) if worker.isRunning() else None)
        timer.daemon = True
        timer.start()

    def _estop_failed(self, text: str) -> None:
        self.show_message(f"E-STOP: {text}", error=True)

    def _estop_sent(self, latency: float) -> None:
        self.show_message(f"E-STOP acknowledged by the device {1000 * latency:.1f} ms after the request; "
                          f"clear faults to continue", error=True)
        self._poll_device.emit()

    # ------------------------------------------------------------------ runs
    @property
    def running(self) -> bool:
        return self.run_worker is not None and self.run_worker.isRunning()

    def _start_worker(self, worker: RunWorker, kind: str) -> None:
        self.run_worker, self.run_kind = worker, kind
        worker.blocks_ready.connect(self._drain, QUEUED)
        worker.done.connect(self._run_done, QUEUED)
        worker.failed.connect(self._run_failed, QUEUED)
        self.live.clear()
        self.live.set_paused(False)
        self.tabs.setCurrentWidget(self.live)
        self.protocol.set_running(True)
        self.campaign.set_running(kind == "campaign")
        worker.start()

    def start_run(self, protocol, out: str, operator: str = "", notes: str = "", settings=None) -> bool:
        """Run ``protocol`` on the connected bench in a worker thread, logging to ``out``; ``settings``
        (:class:`bench.acquisition.runner.DeviceSettings`) replace the bench's device settings first."""
        if self.running:
            self.show_message("a run is already in progress", error=True)
            return False
        bench = self.device.bench
        if bench is None or not self.connected:
            self.show_message("connect to a device before starting a run", error=True)
            return False
        why = refusal(self.device.url, bench.amplifier.capabilities, protocol.mode, protocol.sample_rate)
        if why:  # before anything moves, and before a file exists (a drive runs fewer modes and rates)
            self.show_message(f"cannot run {protocol.name}: {why}", error=True)
            return False
        if settings is not None:
            bench.settings = settings
        self.current_out = out
        self._start_worker(RunWorker.for_protocol(bench, protocol, out, operator, notes), "run")
        self.show_message(f"{protocol.name} started: {protocol.duration:.4g} s -> {out}")
        return True

    def start_campaign(self, campaign, out_dir: str, resume: bool) -> bool:
        from hilbench.bench.acquisition.campaign import run_campaign

        if self.running:
            self.show_message("a run is already in progress", error=True)
            return False
        bench = self.device.bench
        if bench is None or not self.connected:
            self.show_message(f"connect to a device before starting a campaign (the file asks for "
                              f"{campaign.device})", error=True)
            return False
        if campaign.device != self.device.url:
            self.show_message(f"campaign file names {campaign.device}; running it on the connected "
                              f"{self.device.url}")
        self.current_out = out_dir
        worker = RunWorker(lambda progress, control: run_campaign(campaign, out_dir, resume=resume,
                                                                  progress=progress, control=control,
                                                                  bench=bench))
        self._start_worker(worker, "campaign")
        return True

    def start_plan(self, target: str) -> bool:
        """``hilbench plan`` from the window: a break-away probe on the connected device (run files in
        ``runs/plan-probe-<time>/``, drawn live), then the campaign sized from it, written to ``target`` (TOML)
        and put in the Campaign tab. Runs in the run thread, like a protocol."""
        import importlib

        if self.running:
            self.show_message("a run is already in progress", error=True)
            return False
        bench = self.device.bench
        if bench is None or not self.connected:
            self.show_message("connect to a device before planning experiments (the plan probes the motor)",
                              error=True)
            return False
        if not str(target).strip():
            self.show_message("choose a campaign file (.toml) for the plan", error=True)
            return False
        settings = self.protocol.settings if self.protocol.validate() is not None else bench.settings
        plan_experiments = importlib.import_module("hilbench.bench.acquisition.planning").plan_experiments
        probe_dir = self.runs_dir / f"plan-probe-{time.strftime('%Y%m%d-%H%M%S')}"
        self.current_out = str(probe_dir)
        self.plan_target = str(target)
        worker = RunWorker(lambda progress, control: plan_experiments(bench, settings, probe_dir=probe_dir,
                                                                      progress=progress))
        self._start_worker(worker, "plan")
        self.show_message(f"planning: break-away probe on {self.device.url} (runs in {probe_dir})")
        return True

    def _plan_done(self, plan) -> None:
        try:
            plan.write(self.plan_target)
        except Exception as exc:  # a bad name or a full disk: said, the plan's lines still shown
            self.show_message(f"the plan could not be written to {self.plan_target}: {one_line(exc)}", error=True)
            return
        self.protocol.show_finished("plan written")
        self.plan_lines = plan.lines()
        # the campaign tab shows the planned runs; the plan's lines (probe findings, each run sized) are the
        # banner's tooltip: several lines would not fit the banner row
        self.campaign.path_edit.setText(self.plan_target)
        self.campaign.load()
        self.tabs.setCurrentWidget(self.campaign)
        self.show_message(f"plan written to {self.plan_target} ({len(plan.runs)} runs), loaded in the Campaign tab "
                          f"(hover here for the plan)")
        self.banner.setToolTip("\n".join(self.plan_lines))

    def pause_run(self, paused: bool) -> None:
        if self.run_worker is None:
            return
        if paused:
            self.run_worker.control.pause()
            self.show_message("pause requested: the run pauses at the next step boundary (device disarmed)")
        else:
            self.run_worker.control.resume()
            self.show_message("resumed")

    def abort_run(self) -> None:
        if self.run_worker is not None and self.run_worker.isRunning():
            self.run_worker.control.abort()
            self.show_message("abort requested")

    def _drain(self) -> None:
        worker = self.run_worker
        if worker is None:
            return
        last = None
        for item in worker.take_blocks():
            if self.run_kind == "campaign":
                self.campaign.show_progress(item)
                item = item.run
                if item is None:
                    continue
            self.live.append(item.t, {"current_cmd": item.current_cmd, "current_meas": item.current_meas,
                                      "torque": item.torque, "position": item.position,
                                      "velocity": item.velocity, "position_cmd": item.position_cmd})
            last = item
        now = time.monotonic()
        if last is not None and (now - self._last_progress >= 0.1 or last.done == last.total):
            self._last_progress = now
            self.protocol.show_progress(last.done, last.total, last.eta_s, last.segment, last.n_segments,
                                        worker.control.paused)

    def _finish_worker(self) -> None:
        self._drain()
        worker, self.run_worker = self.run_worker, None
        if worker is not None:
            worker.wait(5000)
        self.campaign.set_running(False)
        self.browser.refresh_files()

    def _run_done(self, result) -> None:
        kind = self.run_kind
        self._finish_worker()
        if kind == "campaign":
            states = [e["status"] for e in result.values()]
            text = f"campaign: {states.count('completed')} of {len(states)} runs completed"
            self.campaign.show_finished(text, error=states.count("completed") != len(states))
            self.protocol.show_finished("campaign finished")
            self.show_message(text)
            return
        if kind == "plan":
            self._plan_done(result)
            return
        self.last_result = result
        self.protocol.show_finished(f"{result.status}: {result.samples} samples")
        self.show_message(f"run {result.status}: {result.path} ({result.samples} samples)"
                          + (f" - {result.message}" if result.message else ""), error=result.status != "completed")

    def _run_failed(self, text: str) -> None:
        kind = self.run_kind
        self._finish_worker()
        self.protocol.show_finished("stopped")
        if kind == "campaign":
            self.campaign.show_finished(f"campaign stopped: {text}", error=True)
        self.show_message(f"run stopped: {text} (file {self.current_out} finished as aborted)", error=True)

    # ------------------------------------------------------------------ shutdown
    def closeEvent(self, event: QtGui.QCloseEvent) -> None:  # noqa: N802 - Qt API
        self.shutdown()
        super().closeEvent(event)

    def shutdown(self) -> None:
        """Abort a run, wait for it (shutdown disarms), close the device, stop every thread."""
        if getattr(self, "_shut", False):
            return
        self._shut = True
        self.live.timer.stop()
        self.campaign.shutdown()  # an analysis or drift process of the campaign tab
        if self.run_worker is not None:
            self.run_worker.control.abort()
            self.run_worker.wait(10000)
        QtCore.QMetaObject.invokeMethod(self.device, "close", QtCore.Qt.ConnectionType.BlockingQueuedConnection)
        self.device_thread.quit()
        self.device_thread.wait(5000)
        self.estop_line.shutdown()
