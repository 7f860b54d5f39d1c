"""Threads of the GUI: nothing that talks to the device runs in the GUI thread.

- :class:`DeviceWorker` lives in its own QThread: connect, disconnect, status polling, clear faults.
- :class:`RunWorker` is a QThread whose ``run`` calls :meth:`bench.acquisition.runner.Bench.run`; sample blocks are
  queued and handed to the GUI thread with one Qt signal per batch (never more signals than the GUI takes).
- :class:`EStopLine` is a dedicated plain thread that only waits for a trigger and calls
  ``amplifier.estop()``: it never waits for the stream, the device thread or the GUI.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from PySide6 import QtCore

from hilbench.drivers import protocol as wire


def one_line(exc: BaseException) -> str:
    """An exception as one line of words for the status bar: its message, never its class name (an operator
    reads "device fault: ESTOP", not "DeviceFaultError: ..."); a message-less exception says so in words."""
    text = " ".join(str(exc).split())
    if isinstance(exc, KeyError) and text:  # str(KeyError('x')) is just "'x'"
        return f"missing entry {text}"
    return text or "an unexpected failure without a message"


@dataclass
class DeviceState:
    """What the connection panel shows; built in the device thread, read in the GUI thread."""

    state: str
    faults: list[str]
    fault_bits: int
    index: int
    current_applied: float  # A
    counters: dict[str, int]
    detail: str = ""  # the device's own state (a drive's CiA 402 state and statusword, an ODrive axis state)
    units: dict[str, str] = field(default_factory=dict)  # counter name -> unit, where not frames or samples


def describe_drive(live: dict) -> DeviceState:
    """A host-clocked drive's :meth:`~drivers.host_clocked.HostClockedDevice.live_state` for the panel."""
    if live["faults"]:
        state = "FAULT"
    elif live["streaming"]:
        state = "STREAMING"
    else:
        state = "ARMED" if live["armed"] else "DISARMED"
    counters = live["counters"]
    return DeviceState(state, list(live["faults"]), int(bool(live["faults"])), int(live["cycle"]),
                       float(live["current_cmd"]), {k: v for k, (v, _) in counters.items()}, live["state"],
                       {k: unit for k, (_, unit) in counters.items()})


def describe_status(status: wire.Status, counters: dict[str, int]) -> DeviceState:
    names = [f.name for f in wire.Fault if f and status.faults & f]
    return DeviceState(wire.State(status.state).name, names, int(status.faults), int(status.index),
                       float(status.current_applied), dict(counters))


class DeviceWorker(QtCore.QObject):
    """Owns the :class:`bench.acquisition.runner.Bench`; every slot runs in the device thread.

    The bench is shared (read-only reference) with the run thread and the e-stop line; the amplifier is
    thread-safe for status, estop and streaming at once.
    """

    connected = QtCore.Signal(object)      # dict: url, identity, config
    disconnected = QtCore.Signal(str)      # reason ("" when asked to)
    status = QtCore.Signal(object)         # DeviceState
    failed = QtCore.Signal(str)            # one-line error for the window
    busy = QtCore.Signal(bool)

    def __init__(self, estop_line: EStopLine, poll_interval: float = 0.5) -> None:
        super().__init__()
        self.bench = None
        self.url = ""
        self._estop_line = estop_line
        self._poll_interval = poll_interval
        self._timer: QtCore.QTimer | None = None

    @QtCore.Slot(str, float)
    def open(self, url: str, timeout: float) -> None:
        from hilbench.bench.acquisition.runner import Bench

        if self.bench is not None:
            self.close()
        self.busy.emit(True)
        try:
            bench = Bench.open(url, timeout=timeout)
        except Exception as exc:  # every failure becomes a message in the window, never a crash
            self.failed.emit(f"cannot connect to {url}: {one_line(exc)}")
            self.busy.emit(False)
            return
        self.bench, self.url = bench, url
        self._estop_line.amplifier = bench.amplifier
        amp = bench.amplifier
        config = amp.config
        info = {"url": url, "identity": bench.identity(), "clock": amp.clock,
                "capabilities": amp.capabilities.describe(),
                "config": {k: getattr(config, k) for k in config.__slots__} if config is not None else {}}
        self.connected.emit(info)
        self.busy.emit(False)
        if self._timer is None:
            self._timer = QtCore.QTimer(self)
            self._timer.timeout.connect(self.poll)
        self._timer.start(int(self._poll_interval * 1000))
        self.poll()

    @QtCore.Slot()
    def close(self, reason: str = "") -> None:
        if self._timer is not None:
            self._timer.stop()
        bench, self.bench = self.bench, None
        self._estop_line.amplifier = None
        if bench is not None:
            try:
                bench.close()
            except Exception as exc:
                reason = reason or f"closed with an error: {one_line(exc)}"
            self.disconnected.emit(reason)

    @QtCore.Slot()
    def poll(self) -> None:
        bench = self.bench
        if bench is None:
            return
        try:
            amp = bench.amplifier
            if amp.clock == "host":  # a drive: its state without disturbing a running cycle
                self.status.emit(describe_drive(amp.live_state()))
            else:
                self.status.emit(describe_status(amp.status(), amp.counters))
        except Exception as exc:
            from hilbench.drivers.errors import DeviceTimeoutError

            if isinstance(exc, DeviceTimeoutError):
                self.failed.emit(f"device does not answer: {one_line(exc)}")
                return
            self.close(reason=f"connection lost: {one_line(exc)}")

    @QtCore.Slot()
    def clear_faults(self) -> None:
        if self.bench is None:
            self.failed.emit("not connected")
            return
        try:
            self.bench.amplifier.clear_faults()
        except Exception as exc:
            self.failed.emit(f"clear faults failed: {one_line(exc)}")
        self.poll()


class RunWorker(QtCore.QThread):
    """Runs one job in this thread: ``job(progress, control)``, e.g. a ``bench.run`` or a campaign.

    ``blocks_ready`` is emitted when the first progress item of a batch arrives; the GUI drains the whole
    batch with :meth:`take_blocks`, so a busy GUI thread receives fewer, larger batches instead of a
    backlog of signals.
    """

    blocks_ready = QtCore.Signal()
    done = QtCore.Signal(object)   # the job's result (RunResult, campaign entries)
    failed = QtCore.Signal(str)    # one-line message

    def __init__(self, job: Callable[[Callable[[Any], None], Any], Any]) -> None:
        super().__init__()
        from hilbench.bench.acquisition.runner import RunControl

        self.job = job
        self.control = RunControl()
        self._blocks: deque = deque()
        self._lock = threading.Lock()
        self._signalled = False

    @classmethod
    def for_protocol(cls, bench: Any, protocol: Any, out: str, operator: str = "", notes: str = "") -> RunWorker:
        """A worker that runs ``bench.run(protocol, out, ...)``."""
        return cls(lambda progress, control: bench.run(protocol, out=out, operator=operator, notes=notes,
                                                       progress=progress, control=control))

    def _on_progress(self, progress: Any) -> None:  # worker thread
        with self._lock:
            self._blocks.append(progress)
            signal = not self._signalled
            self._signalled = True
        if signal:
            self.blocks_ready.emit()

    def take_blocks(self) -> list:
        """Every progress item received since the last call (GUI thread)."""
        with self._lock:
            blocks = list(self._blocks)
            self._blocks.clear()
            self._signalled = False
        return blocks

    def run(self) -> None:  # QThread entry point
        try:
            result = self.job(self._on_progress, self.control)
        except Exception as exc:  # reported in the window; the run file was finished by the runner
            self.failed.emit(one_line(exc))
            return
        self.done.emit(result)


class EStopLine(QtCore.QObject):
    """A dedicated thread that sends E-STOP the moment :meth:`trigger` is called.

    ``trigger`` only records the time and sets an event, so it returns at once in the GUI thread. The
    thread calls ``amplifier.estop()`` directly; the driver serialises link writes with a lock held for
    one write only, so the command goes out between two setpoint blocks of a running stream.
    ``sent`` carries the seconds from trigger to the device's acknowledgement (an upper bound of the time
    the command took to reach the device) and ``failed`` a one-line error.
    """

    sent = QtCore.Signal(float)
    failed = QtCore.Signal(str)

    def __init__(self) -> None:
        super().__init__()
        self.amplifier = None
        self.on_trigger: list = []  # plain callables run in the e-stop thread after the command (abort runs)
        self.last_latency: float | None = None
        self._event = threading.Event()
        self._stop = False
        self._t_trigger = 0.0
        self._thread = threading.Thread(target=self._loop, name="gui-estop", daemon=True)
        self._thread.start()

    def trigger(self) -> float:
        """Request an e-stop now; returns the trigger time (``time.perf_counter``)."""
        self._t_trigger = time.perf_counter()
        self._event.set()
        return self._t_trigger

    def _loop(self) -> None:
        while True:
            self._event.wait()
            self._event.clear()
            if self._stop:
                return
            t0 = self._t_trigger
            amp = self.amplifier
            try:
                if amp is None:
                    raise RuntimeError("no device connected")
                amp.estop()
                self.last_latency = time.perf_counter() - t0
                self.sent.emit(self.last_latency)
            except Exception as exc:
                self.failed.emit(one_line(exc))
            for callback in list(self.on_trigger):
                try:
                    callback()
                except Exception as exc:
                    self.failed.emit(one_line(exc))

    def shutdown(self) -> None:
        self._stop = True
        self._event.set()
        self._thread.join(timeout=2.0)
