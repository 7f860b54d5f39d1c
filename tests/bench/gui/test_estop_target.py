"""An e-stop aborts the run that was running when it was requested, never one started after it (the e-stop thread
acts once the command went out: an idle e-stop, a fault clear and a new run could otherwise lose the new run)."""

import pytest

from hilbench.bench.gui.main_window import MainWindow

pytestmark = pytest.mark.device_free


class _Control:
    paused = True  # a paused run is aborted at once (no grace timer to wait for)

    def __init__(self) -> None:
        self.aborted: list[str] = []

    def abort(self, reason: str = "") -> None:
        self.aborted.append(reason)


class _Worker:
    def __init__(self) -> None:
        self.control = _Control()

    def isRunning(self) -> bool:  # noqa: N802 (Qt's name)
        return True


def test_an_idle_estop_leaves_a_run_started_after_it_alone(qapp, tmp_path, qtbot):
    w = MainWindow(runs_dir=tmp_path)
    qtbot.addWidget(w)
    try:
        w.estop_line.on_trigger.clear()  # the e-stop thread's callback is called by hand, in the racy order
        w.estop()  # idle: no run
        later = _Worker()
        w.run_worker = later  # a run started before the e-stop thread got to its callback
        w._abort_from_estop()
        assert later.control.aborted == []
        running = _Worker()
        w.run_worker = running
        w.estop()  # while it runs: that run is aborted
        w._abort_from_estop()
        assert running.control.aborted == ["E-STOP while paused: aborted"]
    finally:
        w.run_worker = None
        w.shutdown()
