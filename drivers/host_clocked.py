"""The host-clocked drive: one stream loop for every drive family, with per-drive hooks.

As python-can's ``BusABC.recv`` does the shared work and calls each backend's ``_recv_internal``,
:meth:`HostClockedDevice.stream` owns the timing-critical skeleton every host-clocked drive shares, and a
drive module supplies only what differs:

- :meth:`~HostClockedDevice._cycle_spec` (encode): the frames of every cycle from the setpoints;
- :meth:`~HostClockedDevice._rows` (decode and check a block): the samples of the feedback rows that arrived,
  and whether they end the stream (the drive left its enabled state);
- :meth:`~HostClockedDevice._end_stream` (end): what a stream that ended short means for this drive;
- :meth:`~HostClockedDevice._guard_frame`: where position and velocity sit in its feedback frames, so that the
  cycle checks the host's limits on every frame.

The skeleton: the cycle (drivers/host_cycle.py :class:`CanCycle`) runs in its own process; every
:data:`BLOCK_PERIOD` the loop takes the rows every feedback slot has received (``ready = min`` over the slots,
cut at a tripped limit's row), decodes them into one :class:`CycleSamples` block, and raises, after yielding
every sample received, on a bus that could not open, a tripped limit, a drive fault, a drive gone silent for
``timeout`` s, or a short stream. Whatever happens, the cycle is stopped, its timing summarised and its
shared memory released.
"""

from __future__ import annotations

import abc
import math
import struct
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from hilbench.common.can import drop_malformed_frames, enlarge_receive_buffer
from hilbench.common.runfile.schema import HOST_TIME
from hilbench.drivers import protocol as p
from hilbench.drivers.amplifier import check_setpoints
from hilbench.drivers.device import CycleSamples, Device, refusal
from hilbench.drivers.errors import (
    CommandRefusedError,
    ConfigError,
    DeviceFaultError,
    DeviceTimeoutError,
    DriverError,
)
from hilbench.drivers.host_cycle import CanCycle, CanCycleSpec, Guard, TimingSummary, timing_summary

BLOCK_PERIOD = 0.02  # s between sample blocks handed to the caller
FEED_PERIOD = 0.02   # s between watchdog feeds while armed and not streaming


@dataclass(frozen=True)
class GuardFrame:
    """Where a drive's feedback frame carries position and velocity, for the host's limit checks: rx slot
    ``slot``, struct format ``fmt`` of both values, their byte offsets, and the frame's units per rad (per
    rad/s) at the motor shaft."""

    slot: int
    fmt: str
    position_offset: int
    velocity_offset: int
    per_rad: float
    per_rad_s: float


class HostClockedDevice(Device):
    """What every host-clocked drive shares: the stream loop, the timing of its last stream, the run events,
    the host's limit checks, an idempotent close.

    Subclasses set ``name``, ``timeout`` (s), ``label`` (e.g. "CANopen node 1") and ``config`` (None until
    configured), and implement the hooks named in the module doc, :meth:`live_state` and :meth:`_release`.
    """

    clock = "host"
    config = None
    timeout = 2.0
    label = "drive"
    #: how the limit line names a row (a CiA 402 drive's rows are SYNC cycles; the others' samples)
    row_name = "sample"
    #: what the host's end of a stream did, for the limit line
    end_text = "zero torque sent"
    _timing: TimingSummary | None = None
    _closed = False
    _cycle: CanCycle | None = None
    _progress = 0          # cycles sent in the current (or last) stream
    _malformed_cycle = 0   # malformed frames the cycles' buses dropped
    malformed = None       # the drive's own bus's counter of dropped frames (hilbench/common/can.py), once opened
    #: whether the drive's watchdog is fed by its commands (ODrive, moteus): then a zero-torque feed
    #: (:meth:`_feed_message`, sent on ``self.bus``) runs while armed and not streaming
    feeds_watchdog = False
    _feed = None

    @property
    def timing(self) -> TimingSummary | None:
        """Timing of the last stream."""
        return self._timing

    def fault_line(self) -> str:
        """The latched fault in one line with its code and text, "" when there is none."""
        return ""

    @abc.abstractmethod
    def live_state(self) -> dict:
        """For an operator display, without disturbing a stream: ``state`` (text), ``armed`` (power stage on),
        ``streaming``, ``faults`` (one-line texts), ``cycle`` (cycles sent in the current or last stream),
        ``current_cmd`` (A, the last command sent) and ``counters`` (name: (value, unit)) of the last stream."""

    def _open_bus(self, interface: str, channel: str, **bus_kwargs):
        """The drive's python-can bus, its socket buffer enlarged and its malformed frames counted
        (``self.malformed``), never fatal; one line naming the URL when it cannot be opened."""
        import can

        try:
            bus = can.Bus(interface=interface, channel=channel, **bus_kwargs)
        except Exception as exc:  # python-can raises many types for a missing interface
            raise DriverError(f"{self.name}: cannot open the CAN bus: {' '.join(str(exc).split())}") from exc
        return self._guard_bus(bus)

    def _guard_bus(self, bus):
        """``bus`` with its socket buffer enlarged and its malformed frames counted (``self.malformed``)."""
        enlarge_receive_buffer(bus)
        self.malformed = drop_malformed_frames(bus)  # a stray datagram is counted, never fatal
        return bus

    # ------------------------------------------------------------------ the watchdog feed
    def _feed_message(self):
        """The zero-torque command that feeds the drive's watchdog (a python-can message), where
        :attr:`feeds_watchdog`."""
        raise NotImplementedError

    def _start_feed(self) -> None:
        if self.feeds_watchdog and self._feed is None:
            self._feed = self.bus.send_periodic(self._feed_message(), FEED_PERIOD)

    def _stop_cycle(self) -> None:
        """Stop the stream's cycle and wait for its end (within FEED_PERIOD, or 0.1 s mid-stream): no frame of
        the cycle (its zero-torque keepalive) can then follow the stop or idle command the caller sends next."""
        cycle = self._cycle
        if cycle is not None:
            cycle.stop()
            cycle.join()

    def _stop_feed(self) -> None:
        if self._feed is not None:
            self._feed.stop()
            # python-can's stop() only flags its thread: joined, no feed frame can follow what the caller sends next
            thread = getattr(self._feed, "thread", None)
            if thread is not None:
                thread.join(1.0)
            self._feed = None

    def _configured(self, doing: str):
        """The configuration, or one line refusing ``doing`` (arming, streaming) before :meth:`configure`."""
        if self.config is None:
            raise CommandRefusedError(f"configure() the drive before {doing}")
        return self.config

    def _check_config(self, config) -> None:
        """Refuse, before anything is sent, a CONFIG with problems or one the drive's capabilities cannot run."""
        problems = config.problems()
        if problems:
            raise ConfigError("; ".join(problems))
        why = refusal(self.name, self.capabilities, config.mode.name.lower(), config.sample_rate)
        if why:
            raise ConfigError(why)

    def timing_counters(self) -> dict[str, tuple[float, str]]:
        """The last stream's timing figures as (value, unit) for a display."""
        t = self._timing
        if t is None:
            return {}
        return {"cycles": (t.cycles, "cycles"), "missed cycles": (t.missed, "cycles"),
                "late cycles": (t.late, "cycles"), "cycle time p99": (round(t.p99 * 1e3, 3), "ms"),
                "cycle time max": (round(t.max * 1e3, 3), "ms"),
                "jitter p99": (round(t.jitter_p99 * 1e6), "us")}

    def run_events(self) -> list[tuple[str, str]]:
        out = [("info", self._timing.line())] if self._timing is not None else []
        fault = self.fault_line()
        if fault:
            out.append(("fault", fault))
        out += self._drive_events()
        dropped = (self.malformed.count if self.malformed is not None else 0) + self._malformed_cycle
        if dropped:
            out.append(("info", f"{dropped} malformed frame(s) on the bus were counted and dropped"))
        return out

    def _drive_events(self) -> list[tuple[str, str]]:
        """The drive's own run events (adopted units, notes on the stream), after the timing and the fault."""
        return []

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            if self.config is not None:
                self.disarm()
        except Exception:  # closing must release the bus whatever the drive or the bus says
            pass
        finally:
            self._release()

    @abc.abstractmethod
    def _release(self) -> None:
        """Stop background tasks and free the bus (called once, by :meth:`close`)."""

    # ------------------------------------------------------------------ the hooks of the stream loop
    def _check_ready(self) -> None:
        """Raise (one line) when the drive cannot stream now (not enabled, a fault latched)."""

    @abc.abstractmethod
    def _cycle_spec(self, values: np.ndarray) -> tuple[CanCycleSpec, np.ndarray]:
        """Encode: the cycle's frames for ``values`` (checked setpoints, one per cycle) and the tx payloads, a
        uint8 array of shape (n, len(tx_ids), 8); resets what the drive keeps per stream."""

    @abc.abstractmethod
    def _rows(self, done: int, ready: int, arrays: dict) -> tuple[CycleSamples | None, int, bool]:
        """Decode and check rows ``done:ready`` of the feedback slots: the block (None when none is kept), the
        row the stream has reached (``ready``, or fewer when the rows end the stream), and whether they end it
        (the cycle is then stopped)."""

    def _begin(self, cycle: CanCycle, started: float) -> None:
        """Once the cycle is started: hand the watchdog over from the feed to the cycle's commands.

        The feed keeps the watchdog fed until the cycle's first command is out: starting the cycle process takes
        longer than a watchdog timeout on a loaded host. A feed frame that lands between the first commands makes
        the drive hold zero torque for that cycle. A cycle in a thread sends its first command ``start_delay``
        (0.05 s) after its start, within any watchdog timeout: its feed stops at once."""
        if not self.feeds_watchdog:
            return
        while not cycle.in_process and not cycle.sent and cycle.alive() and not cycle.arrays["ctl"][1]:
            time.sleep(0.0005)
            cycle.check_started(started, self.label)
        self._stop_feed()  # the cycle's commands feed the watchdog now

    def _poll(self, cycle: CanCycle, n: int) -> str:
        """Every poll: the drive's fault that ends the stream now, in words ("" while there is none)."""
        return ""

    def _answer_slack(self, rate: float) -> float:
        """Cycles the drive's answers may lag the triggers sent before its silence is timed."""
        return 0.0

    def _silence_line(self, done: int, n: int) -> str:
        return f"{self.label} stopped answering at sample {done} of {n} (nothing for {self.timeout:g} s)"

    def _fault_stop_line(self, done: int, fault: str) -> str:
        return f"{self.label} stopped at sample {done}: {fault}"

    def _end_stream(self, cycle: CanCycle, done: int, n: int, allow_loss: bool) -> None:
        """After a stream that raised nothing else: raise what ``done`` of ``n`` samples means."""

    def _after_stream(self, finished: bool, fault: str) -> None:
        """Last, whatever happened (``finished``: the loop ran to its end; ``fault``: what :meth:`_poll` said)."""

    @abc.abstractmethod
    def _guard_frame(self) -> GuardFrame:
        """Where the feedback frames carry position and velocity (see :class:`GuardFrame`)."""

    # ------------------------------------------------------------------ the loop
    def stream(self, setpoints, allow_loss: bool = False) -> Iterator[CycleSamples]:
        """Play ``setpoints`` (A in current mode; rad in position mode) one per cycle at the configured rate;
        yield blocks of samples as the drive's feedback arrives.

        Raises :class:`DeviceFaultError` (after yielding every sample received) when the drive faults or a host
        limit trips, :class:`DeviceTimeoutError` when the drive falls silent, and :class:`SampleLossError` when
        samples are missing, unless ``allow_loss``.
        """
        values = check_setpoints(setpoints, self._configured("streaming"))
        self._check_ready()
        return self._stream(values, allow_loss)

    def _stream(self, values: np.ndarray, allow_loss: bool) -> Iterator[CycleSamples]:
        n, rate = len(values), self.config.sample_rate
        spec, tx = self._cycle_spec(values)
        if self.feeds_watchdog:  # the cycle feeds the watchdog from its last command until the feed here has started
            # (bounded by the watchdog timeout the configuration names: host_cycle.keepalive_limit)
            spec = replace(spec, keepalive=FEED_PERIOD, watchdog_timeout=self.config.watchdog_timeout)
        cycle = CanCycle(spec, tx)
        self._cycle, self._timing, self._progress = cycle, None, 0
        arrays, slots = cycle.arrays, range(len(spec.rx_ids))
        done, fault, finished = 0, "", False
        try:
            started = time.monotonic()
            cycle.start()
            self._begin(cycle, started)
            silent_since = None
            while True:
                time.sleep(BLOCK_PERIOD)
                cycle.check_started(started, self.label)
                ended = not cycle.alive() or cycle.finished
                fault = fault or self._poll(cycle, n)
                if fault:
                    cycle.stop()
                    ended = True
                elif (cycle.sent >= n or cycle.limit is not None) and not self._closed:
                    # the cycle's last command is out: the feed keeps the watchdog fed while it collects the tail
                    self._start_feed()
                if ended:  # the feed (when the drive needs one) has started: the cycle's keepalive may stop
                    cycle.stop()
                    cycle.join()
                sent = self._progress = cycle.sent
                ready = min(cycle.received(j) for j in slots)
                if cycle.limit is not None:  # the sample that tripped a limit is the last one
                    ready = min(ready, cycle.limit[1] + 1)
                if ready > done:
                    block, ready, end = self._rows(done, ready, arrays)
                    if end:
                        cycle.stop()
                        cycle.join()
                        ended = True
                    if block is not None:
                        yield block
                    done, silent_since = ready, None
                elif not ended and sent > done + self._answer_slack(rate):
                    silent_since = silent_since or time.monotonic()
                    if time.monotonic() - silent_since > self.timeout:
                        cycle.stop()
                        raise DeviceTimeoutError(self._silence_line(done, n))
                if ended:
                    break
            finished = True
            if cycle.error:
                raise DriverError(f"{self.name}: the cycle process could not open the CAN bus")
            if cycle.limit is not None:
                guard, row = cycle.limit
                raise DeviceFaultError(self._limit_line(guard, row, arrays), int(p.Fault[guard.name]))
            if fault:
                raise DeviceFaultError(self._fault_stop_line(done, fault))
            self._end_stream(cycle, done, n, allow_loss)
        finally:
            cycle.stop()
            cycle.join()
            sent = cycle.sent
            if sent:
                self._timing = timing_summary(arrays[HOST_TIME][:sent], arrays["scheduled"][:sent], rate,
                                              cycle.echoed if spec.echo_id is not None else None)
            self._cycle = None
            self._malformed_cycle += cycle.malformed
            cycle.close()
            if not self._closed and not fault:
                self._start_feed()
            self._after_stream(finished, fault)

    # ------------------------------------------------------------------ the host's limits
    def _guards(self, cfg: p.Config) -> tuple[Guard, ...]:
        """The host's own check of the position window and the velocity limit on every feedback frame that
        carries them (at the motor shaft, as the hilbench device checks them)."""
        g = self._guard_frame()
        out = []
        if math.isfinite(cfg.position_min) or math.isfinite(cfg.position_max):
            out.append(Guard("POSITION_WINDOW", g.slot, g.position_offset, g.fmt, cfg.position_min * g.per_rad,
                             cfg.position_max * g.per_rad))
        out.append(Guard("OVER_SPEED", g.slot, g.velocity_offset, g.fmt, -cfg.velocity_limit * g.per_rad_s,
                         cfg.velocity_limit * g.per_rad_s))
        return tuple(out)

    def _limit_line(self, guard: Guard, row: int, arrays: dict) -> str:
        g = self._guard_frame()
        raw = struct.unpack_from(guard.fmt, arrays["rx"][guard.slot, row].tobytes(), guard.offset)[0]
        cfg = self.config
        if guard.name == "POSITION_WINDOW":
            what = (f"position {raw / g.per_rad:.6g} rad outside the window [{cfg.position_min:.6g}, "
                    f"{cfg.position_max:.6g}] rad")
        else:
            what = f"speed {abs(raw / g.per_rad_s):.6g} rad/s above the velocity limit {cfg.velocity_limit:.6g} rad/s"
        return (f"stream stopped by the host at {self.row_name} {row}: {guard.name} ({what}, at the motor shaft); "
                f"{self.end_text}")
