"""The operator GUI (pyqtgraph + PySide6): ``hilbench gui``. See ``docs/gui.md``."""
