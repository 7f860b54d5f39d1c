"""The operator GUI (pyqtgraph + PySide6): ``bench gui``. See ``docs/gui.md``."""
