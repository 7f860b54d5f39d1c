"""Start the operator GUI: ``run_app(device="sim://")``."""

from __future__ import annotations

import sys
from pathlib import Path


def qt_problem() -> str:
    """Why this Qt binding cannot run the GUI here ("" when it can).

    PySide6 6.12.0 drops a reference to ``None`` on every call that returns nothing when run on Python
    < 3.12 (where ``None`` is not immortal, PEP 683); any Qt program then dies within seconds with
    "Fatal Python error: none_dealloc". 6.11.x is fine.
    """
    try:
        import PySide6
    except ImportError as exc:
        return f"PySide6 is not installed ({exc})"
    major_minor = tuple(int(x) for x in PySide6.__version__.split(".")[:2])
    if major_minor == (6, 12) and sys.version_info < (3, 12):
        return (f"PySide6 {PySide6.__version__} crashes on Python {sys.version.split()[0]} (None reference "
                f"count bug); install PySide6-Essentials<6.12 or use Python >= 3.12")
    return ""


def run_app(device: str = "sim://", runs_dir: str | Path = "runs", autoconnect: bool = False,
            open_file: str | None = None) -> int:
    """Create the QApplication and the main window, run the event loop; returns the exit code."""
    problem = qt_problem()
    if problem:
        raise OSError(problem)
    import pyqtgraph as pg
    from PySide6 import QtCore, QtWidgets

    from hilbench.analysis.execution import limit_process
    from hilbench.bench.gui.main_window import MainWindow

    limit_process()  # one BLAS thread in every thread of the GUI (analysis.execution), set from the main thread

    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    app.setApplicationName("hilbench")
    pg.setConfigOptions(antialias=False, useOpenGL=False)
    settings = QtCore.QSettings("hilbench", "gui")
    recent = [str(u) for u in (settings.value("recent_urls") or []) if isinstance(u, str)]
    window = MainWindow(device=device, runs_dir=runs_dir, autoconnect=autoconnect, recent=recent)
    if open_file:
        window.browser.open(open_file)
        window.tabs.setCurrentWidget(window.browser)
    window.show()
    try:
        return app.exec()
    finally:
        window.shutdown()
        settings.setValue("recent_urls", window.connection.recent)
