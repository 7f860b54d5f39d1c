"""A ``hilbench`` subcommand run from the window in its own process (a QProcess): the GUI thread never waits for
it. Its output is read as it comes: tqdm's ``12/40`` becomes :attr:`CommandProcess.progress`, every other line
:attr:`CommandProcess.line`; :attr:`CommandProcess.finished` carries the exit status and, on failure, the error
line the command printed (``hilbench analyse: error: ...``) without its prefix."""

from __future__ import annotations

import os
import re
import signal
import sys

from PySide6 import QtCore

#: tqdm's counter, e.g. "analyse:  40%|####      | 4/10 [00:01<00:02, 3.1run/s]"
_COUNT = re.compile(r"(\d+)/(\d+) \[")
_ERROR = re.compile(r"^hilbench [\w-]+: error: ")


class CommandProcess(QtCore.QObject):
    """``python -m hilbench ARGS...`` (this interpreter, so the same install) in its own process."""

    progress = QtCore.Signal(int, int)  # done, total
    line = QtCore.Signal(str)           # one line of output, not a progress update
    finished = QtCore.Signal(bool, str)  # succeeded, the error line (failure) or the last line (success)

    def __init__(self, args: list[str], parent: QtCore.QObject | None = None) -> None:
        super().__init__(parent)
        self.args = [str(a) for a in args]
        self.lines: list[str] = []
        self._pending = ""
        self.process = QtCore.QProcess(self)
        self.process.setProcessChannelMode(QtCore.QProcess.ProcessChannelMode.MergedChannels)
        env = QtCore.QProcessEnvironment.systemEnvironment()
        env.insert("PYTHONUNBUFFERED", "1")  # lines as they are printed, not when a buffer fills
        self.process.setProcessEnvironment(env)
        self.process.readyReadStandardOutput.connect(self._read)
        self.process.finished.connect(self._finished)
        self.process.errorOccurred.connect(self._error)
        self._done = False

    def start(self) -> None:
        self.process.start(sys.executable, ["-m", "hilbench", *self.args])

    def running(self) -> bool:
        return self.process.state() != QtCore.QProcess.ProcessState.NotRunning

    def kill(self, grace: float = 5.0) -> None:
        """Stop the command (the window closes): an interrupt first, as Ctrl-C would (``analyse`` then closes its
        Dask cluster and the workers it started, and the results table keeps every finished row), then a kill
        after ``grace`` s."""
        if not self.running():
            return
        pid = self.process.processId()
        if hasattr(signal, "SIGINT") and os.name == "posix" and pid > 0:
            os.kill(pid, signal.SIGINT)
        else:
            self.process.terminate()
        if not self.process.waitForFinished(int(grace * 1000)):
            self.process.kill()
            self.process.waitForFinished(5000)

    def _read(self) -> None:
        text = self._pending + bytes(self.process.readAllStandardOutput().data()).decode(errors="replace")
        parts = re.split(r"[\r\n]", text)
        self._pending = parts.pop()  # an unfinished line waits for its end
        for part in parts:
            self._take(part)

    def _take(self, part: str) -> None:
        part = part.strip()
        if not part:
            return
        count = _COUNT.search(part)
        if count:
            self.progress.emit(int(count.group(1)), int(count.group(2)))
            return
        self.lines.append(part)
        self.line.emit(part)

    def _finished(self, code: int, status: QtCore.QProcess.ExitStatus) -> None:
        self._read()
        self._take(self._pending)
        self._pending = ""
        ok = status == QtCore.QProcess.ExitStatus.NormalExit and code == 0
        errors = [_ERROR.sub("", line) for line in self.lines if _ERROR.match(line)]
        if ok:
            text = self.lines[-1] if self.lines else ""
        elif errors:
            text = errors[-1]
        elif status != QtCore.QProcess.ExitStatus.NormalExit:
            text = f"hilbench {self.args[0]} stopped ({self.process.errorString()})"
        else:
            text = f"hilbench {self.args[0]} exited with {code}" + (f": {self.lines[-1]}" if self.lines else "")
        self._emit_once(ok, text)

    def _error(self, error: QtCore.QProcess.ProcessError) -> None:
        if error == QtCore.QProcess.ProcessError.FailedToStart:  # no finished signal follows
            self._emit_once(False, f"cannot start {sys.executable} -m hilbench: {self.process.errorString()}")

    def _emit_once(self, ok: bool, text: str) -> None:
        if not self._done:
            self._done = True
            self.finished.emit(ok, text)

