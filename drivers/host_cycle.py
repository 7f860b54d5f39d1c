"""Host-clocked cycles: the timing loop and its honest bookkeeping.

A host-clocked drive buffers nothing; the host sends one trigger (SYNC, or a cyclic message) per period
``T`` at the scheduled times ``t0 + k*T``. The loop never skips a setpoint: when it falls behind it sends
the overdue cycles back to back, so every sample exists, but the drive held the previous torque for longer
than ``T``. :func:`timing_summary` turns the host timestamps into the figures the run file keeps.

Definitions (``d_k = host_time[k+1] - host_time[k]``, the cycle time the drive saw, give or take the bus):

- cycle-time p50, p99, max: percentiles of ``d_k``;
- **missed** cycles: scheduled trigger slots that stayed empty, ``sum(max(0, round(d_k/T) - 1))``;
- **late** cycles: triggers sent more than ``LATE_FRACTION*T`` after their scheduled time;
- **jitter**: p99 of ``|d_k - T|``. A run is unfit for identification when that exceeds ``JITTER_LIMIT*T``
  or when more than ``MISSED_LIMIT`` of the cycles were missed: the plant then integrated a held torque
  over a span the analysis (which takes ``t = k*T``) does not know about.
"""

from __future__ import annotations

import struct
import time
from dataclasses import dataclass

import numpy as np

from hilbench.common.can import drop_malformed_frames, enlarge_receive_buffer
from hilbench.common.runfile.schema import HOST_TIME
from hilbench.drivers.errors import DeviceTimeoutError

LATE_FRACTION = 0.25
JITTER_LIMIT = 0.10
MISSED_LIMIT = 1e-3


@dataclass(frozen=True)
class TimingSummary:
    """Timing of one host-clocked stream (times in s)."""

    cycles: int
    rate: float
    p50: float
    p99: float
    max: float
    missed: int
    late: int
    jitter_p99: float
    echoed: int | None = None  # cycles whose host time is the trigger's own echo from the bus (None: not asked)

    @property
    def fit(self) -> bool:
        period = 1.0 / self.rate
        return self.jitter_p99 <= JITTER_LIMIT * period and self.missed <= MISSED_LIMIT * max(self.cycles, 1)

    def line(self) -> str:
        """One line with the figures and the verdict."""
        period = 1.0 / self.rate
        figures = (f"host-clocked timing: {self.cycles} cycles at {self.rate:g} Hz; cycle p50 {self.p50 * 1e3:.3f} "
                   f"ms, p99 {self.p99 * 1e3:.3f} ms, max {self.max * 1e3:.3f} ms; {self.missed} missed, "
                   f"{self.late} late; jitter p99 {self.jitter_p99 * 1e6:.0f} us ({self.jitter_p99 / period:.1%} of T)")
        if self.echoed is not None:
            figures += f"; host times from the bus for {self.echoed} of {self.cycles} cycles"
        if self.fit:
            return figures + "; fit for identification"
        return figures + (f"; UNFIT for identification (limits {JITTER_LIMIT:.0%} of T, "
                          f"{MISSED_LIMIT:.1%} missed)")

    def as_dict(self) -> dict:
        return {"cycles": self.cycles, "rate_hz": self.rate, "cycle_time_p50_s": self.p50,
                "cycle_time_p99_s": self.p99, "cycle_time_max_s": self.max, "missed": self.missed,
                "late": self.late, "jitter_p99_s": self.jitter_p99, "fit_for_identification": self.fit,
                "host_times_from_bus": self.echoed}


def timing_summary(host_time: np.ndarray, scheduled: np.ndarray, rate: float, echoed: int | None = None
                   ) -> TimingSummary:
    """Figures of a stream from the host times its triggers went out and the times they were due (s);
    ``echoed``: how many of those times are the triggers' echoes from the bus."""
    host_time = np.asarray(host_time, dtype=np.float64)
    period = 1.0 / rate
    d = np.diff(host_time)
    if d.size == 0:
        return TimingSummary(int(host_time.size), rate, period, period, period, 0, 0, 0.0, echoed)
    missed = int(np.maximum(np.rint(d / period) - 1, 0).sum())
    late = int(np.count_nonzero(host_time - np.asarray(scheduled) > LATE_FRACTION * period))
    return TimingSummary(int(host_time.size), rate, float(np.percentile(d, 50)), float(np.percentile(d, 99)),
                         float(d.max()), missed, late, float(np.percentile(np.abs(d - period), 99)), echoed)


@dataclass(frozen=True)
class Guard:
    """A limit the cycle checks on every frame it receives: the value at byte ``offset`` of the frames of rx
    slot ``slot``, decoded with the struct format ``fmt``, must lie in [``low``, ``high``] (NaN trips).
    ``name`` is the fault name the host reports (POSITION_WINDOW, OVER_SPEED, as the hilbench device's)."""

    name: str
    slot: int
    offset: int
    fmt: str
    low: float
    high: float


@dataclass(frozen=True)
class CanCycleSpec:
    """What a host-clocked CAN cycle sends and collects.

    ``tx_ids`` are sent in order each cycle, with payloads ``tx_data[k, j, :tx_len[j]]`` (uint8 array of
    shape (n, len(tx_ids), 8)); ``stop_data`` replaces the payloads once an e-stop is requested;
    ``end_data`` is sent once after the last cycle (e.g. zero torque). Frames with an id in ``rx_ids`` are
    stored in arrival order from the first trigger on, one row per frame, with the host time it arrived
    (a CiA 402 drive answers each SYNC with one frame per TPDO; an ODrive sends its own cyclic frames).

    ``echo_id``: the trigger's id (CiA 402 SYNC, 0x80). Where the bus hands a sender its own frames back
    with a receive timestamp (udp_multicast always; SocketCAN and ``virtual`` with
    ``receive_own_messages``), ``host_time[k]`` is that timestamp of trigger k: when it was on the bus, as
    the drive saw it, rather than when ``send`` returned. Under load the two differ by milliseconds
    (loopback delivery is deferred to a kernel thread; a SocketCAN frame waits in the transmit queue).

    ``guards``: limits checked on every received frame, in the cycle itself (:class:`Guard`). The first
    value out of its range ends the cycle at once: no further setpoint is sent, ``end_data`` (zero torque,
    operation disabled) goes out, and :attr:`CanCycle.limit` says which guard tripped on which frame.

    ``fd`` and ``width``: CAN-FD frames, and the payload bytes each row keeps (tx ``(n, len(tx_ids), width)``).

    ``keepalive``: for a drive whose watchdog only its commands feed (ODrive, moteus), the period (s) at which the
    cycle repeats ``end_data`` (``stop_data`` after an e-stop, both zero torque) from its last trigger until the
    host stops it (:meth:`CanCycle.stop`), having started its own feed. The host's feed runs in a process of
    normal priority: a host descheduled for longer than the watchdog timeout when the cycle ended left the drive
    unfed, and its watchdog latched a fault after a complete run. 0: the cycle stops by itself after the tail.
    The repeats stop at the host's stop, at the host's death (the cycle's parent gone), and at the latest
    :func:`keepalive_limit` (``watchdog_timeout``) s after the last trigger: a stalled host must not keep its drive
    fed for long.
    """

    interface: str
    channel: str
    bus_kwargs: dict
    rate: float
    tx_ids: tuple[int, ...]
    tx_len: tuple[int, ...]
    rx_ids: tuple[int, ...]
    stop_data: tuple[bytes, ...]
    end_data: tuple[bytes, ...]
    echo_id: int | None = None
    guards: tuple[Guard, ...] = ()
    fd: bool = False   # CAN-FD frames (with bit-rate switch), e.g. moteus's
    width: int = 8     # payload bytes each tx and rx row holds (64 for CAN-FD)
    rx_len: tuple[int, ...] = ()  # each rx id's data length, bytes: a frame of another length is dropped, counted
    keepalive: float = 0.0  # s between end_data frames from the last trigger until the host's stop (0: none)
    watchdog_timeout: float = 0.0  # s: the drive's watchdog timeout, which bounds the keepalive (0: not known)


OWN_FRAMES_OPTION = ("virtual", "socketcan")  # interfaces that return own frames only when asked to
_SENT, _STOP, _ESTOP, _ERROR, _REALTIME, _ECHOED = 0, 1, 2, 3, 4, 5  # control slots; rx counters from _RX
_MALFORMED, _LIMIT, _LIMIT_AT = 6, 7, 8  # frames dropped undecoded; limit tripped (guard index + 1), at rx row
_DONE = 9  # the cycle has collected its answers and only feeds the watchdog until stopped (keepalive)
_RX = 10
RT_PRIORITY = 20  # SCHED_FIFO priority of the cycle process, where the OS allows it
START_LIMIT = 20.0  # s: the longest wait for a cycle's first trigger (a spawned process on a loaded host)
TAIL_LIMIT = 60.0  # s: the longest wait, after the last trigger, for a lagging drive's remaining answers
# The keepalive covers a host descheduled as its stream ends (the CLI was measured off the CPU ~1 s): at least
# KEEPALIVE_MIN, at most KEEPALIVE_MAX, else KEEPALIVE_FACTOR watchdog timeouts, counted from the last trigger.
KEEPALIVE_MIN, KEEPALIVE_MAX, KEEPALIVE_FACTOR = 1.5, 3.0, 3.0


def keepalive_limit(watchdog_timeout: float) -> float:
    """How long (s) after its last trigger a cycle may go on feeding a drive's watchdog with zero torque:
    ``min(KEEPALIVE_MAX, max(KEEPALIVE_MIN, KEEPALIVE_FACTOR * watchdog_timeout))``, KEEPALIVE_MAX when the
    timeout is not known (0). A host stalled longer than this leaves its drive unfed: the watchdog trips at
    most this plus its timeout after the stream's last command."""
    if watchdog_timeout <= 0:
        return KEEPALIVE_MAX
    return min(KEEPALIVE_MAX, max(KEEPALIVE_MIN, KEEPALIVE_FACTOR * watchdog_timeout))


class CanCycle:
    """A host-clocked CAN cycle run in a dedicated process (off this process's GIL), or in a thread for
    python-can's in-process ``virtual`` bus. Shares its arrays with the caller through shared memory.

    The cycle opens its own bus; it sends the frames of cycle k at ``t0 + k/rate``, sleeping in
    ``bus.recv`` (select) until then, so receiving the drive's answers costs no extra thread.
    """

    def __init__(self, spec: CanCycleSpec, tx_data: np.ndarray, start_delay: float = 0.05) -> None:
        from multiprocessing import shared_memory

        self.spec = spec
        n = len(tx_data)
        self.n = n
        m = len(spec.rx_ids)
        layout = self._layout(n, len(spec.tx_ids), m, spec.width)
        size = layout[-1][1] + layout[-1][2]
        self._shm = shared_memory.SharedMemory(create=True, size=max(size, 8))
        self.arrays = self._view(self._shm.buf, n, len(spec.tx_ids), m, spec.width)
        self.arrays["tx"][:] = tx_data
        self.arrays["ctl"][:] = 0
        self._start_delay = start_delay
        self._worker = None

    @staticmethod
    def _layout(n: int, ntx: int, m: int, width: int = 8) -> list[tuple[str, int, int, tuple, str]]:
        parts = [("ctl", (_RX + m,), "i8"), (HOST_TIME, (n,), "f8"), ("scheduled", (n,), "f8"),
                 ("rx", (m, n, width), "u1"), ("rx_time", (m, n), "f8"),
                 ("tx", (n, ntx, width), "u1")]
        out, offset = [], 0
        for name, shape, dtype in parts:
            nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
            out.append((name, offset, nbytes, shape, dtype))
            offset += (nbytes + 7) // 8 * 8
        return out

    @classmethod
    def _view(cls, buf, n: int, ntx: int, m: int, width: int = 8) -> dict[str, np.ndarray]:
        return {name: np.ndarray(shape, dtype, buffer=buf, offset=offset)
                for name, offset, _, shape, dtype in cls._layout(n, ntx, m, width)}

    def start(self) -> None:
        import os

        if self.spec.interface == "virtual":
            import threading

            # In a thread, the bus is opened here and the arrays are shared as they are: the thread only runs
            # the loop (a CI run once hung with the thread waiting inside can.Bus(), the cycle never started).
            bus = _open_bus(self.spec, self.arrays["ctl"])
            if bus is None:
                return
            self._worker = threading.Thread(target=_cycle_with_bus, args=(bus, self.spec, self.arrays, self.n,
                                                                          self._start_delay), name="can-cycle",
                                            daemon=True)
        else:
            import multiprocessing

            args = (self.spec, self._shm.name, self.n, self._start_delay, os.getpid())
            self._worker = multiprocessing.get_context("spawn").Process(target=_cycle_main, args=args,
                                                                        name="can-cycle", daemon=True)
        self._worker.start()

    @property
    def sent(self) -> int:
        return int(self.arrays["ctl"][_SENT])

    def received(self, j: int) -> int:
        return int(min(self.arrays["ctl"][_RX + j], self.n))

    @property
    def in_process(self) -> bool:
        """Whether the cycle runs in a thread of this process (python-can's ``virtual`` bus): it then sends its
        first frame ``start_delay`` after :meth:`start`, not after a process has started."""
        return self.spec.interface == "virtual"

    @property
    def realtime(self) -> bool:
        """Whether the cycle ran with SCHED_FIFO priority."""
        return bool(self.arrays["ctl"][_REALTIME])

    @property
    def echoed(self) -> int:
        """How many triggers have their host time from the bus's own echo (the rest: when sent)."""
        return int(self.arrays["ctl"][_ECHOED])

    @property
    def malformed(self) -> int:
        """Frames the cycle's bus dropped because they did not decode (known once the cycle has ended)."""
        return int(self.arrays["ctl"][_MALFORMED])

    @property
    def limit(self) -> tuple[Guard, int] | None:
        """The guard that tripped and the row (in its rx slot) of the frame that tripped it, or None."""
        which = int(self.arrays["ctl"][_LIMIT])
        return (self.spec.guards[which - 1], int(self.arrays["ctl"][_LIMIT_AT])) if which else None

    @property
    def error(self) -> int:
        return int(self.arrays["ctl"][_ERROR])

    def alive(self) -> bool:
        return self._worker is not None and self._worker.is_alive()

    @property
    def finished(self) -> bool:
        """Whether the cycle has ended its stream: stopped, or (with a keepalive) only feeding the watchdog."""
        ctl = self.arrays["ctl"]
        return bool(ctl[_STOP] or ctl[_DONE])

    def stop(self) -> None:
        self.arrays["ctl"][_STOP] = 1

    def check_started(self, since: float, name: str) -> None:
        """Raise :class:`DeviceTimeoutError` when the cycle, started at ``since`` (``time.monotonic``), has sent
        no trigger within :data:`START_LIMIT` while still alive: a run must end in one line, never hang."""
        if not self.sent and self.alive() and time.monotonic() - since > START_LIMIT:
            self.stop()
            self.join()
            raise DeviceTimeoutError(f"{name}: the host's CAN cycle sent no frame within {START_LIMIT:g} s of "
                                     f"its start (it never started; nothing was commanded)")

    def estop(self) -> None:
        self.arrays["ctl"][_ESTOP] = 1

    def join(self, timeout: float = 5.0) -> None:
        if self._worker is None:
            return
        self._worker.join(timeout)
        if self._worker.is_alive() and hasattr(self._worker, "terminate"):
            self._worker.terminate()
            self._worker.join(1.0)

    def close(self) -> None:
        self.stop()
        self.join()
        self.arrays = {}
        try:
            self._shm.close()
        except BufferError:  # a cycle thread that outlived its join still holds views: the mapping goes with it
            pass
        self._shm.unlink()


def _cycle_main(spec: CanCycleSpec, shm_name: str, n: int, start_delay: float, parent: int) -> None:
    """The cycle (in its own process, child of ``parent``, or in a thread when ``parent`` is 0): send,
    record, receive, until n cycles, a stop, or the parent's death (then the triggers just stop, as
    they would if the host itself ran them, and the drive's SYNC or heartbeat timeout takes over)."""
    from multiprocessing import shared_memory

    shm = shared_memory.SharedMemory(name=shm_name)
    try:
        a = CanCycle._view(shm.buf, n, len(spec.tx_ids), len(spec.rx_ids), spec.width)
        ctl = a["ctl"]
        if parent:
            import gc

            ctl[_REALTIME] = _realtime_priority()
            gc.disable()  # no collector pauses in the cycle; it allocates nothing that lives on
        bus = _open_bus(spec, ctl)
        if bus is None:
            return
        _cycle_with_bus(bus, spec, a, n, start_delay, parent)
        del a, ctl  # the views must go before the mapping closes
    finally:
        shm.close()


def _open_bus(spec: CanCycleSpec, ctl):
    """The cycle's own bus; None when it cannot be opened, and then ``ctl`` says so (error, stopped)."""
    import can

    kwargs = dict(spec.bus_kwargs)
    if spec.echo_id is not None and spec.interface in OWN_FRAMES_OPTION:
        kwargs["receive_own_messages"] = True
    try:
        return can.Bus(interface=spec.interface, channel=spec.channel, **kwargs)
    except Exception:
        ctl[_ERROR] = 1
        ctl[_STOP] = 1
        return None


def _cycle_with_bus(bus, spec: CanCycleSpec, a: dict, n: int, start_delay: float, parent: int = 0) -> None:
    """Run the cycle on an open ``bus`` over the arrays ``a``, then release the bus."""
    ctl = a["ctl"]
    enlarge_receive_buffer(bus)
    malformed = drop_malformed_frames(bus)
    try:
        _cycle_loop(bus, spec, n, start_delay, ctl, a[HOST_TIME], a["scheduled"], (a["rx"], a["rx_time"]), a["tx"],
                    parent)
    finally:
        ctl[_MALFORMED] += malformed.count  # besides the frames of the wrong length the cycle dropped
        bus.shutdown()


def _cycle_loop(bus, spec: CanCycleSpec, n: int, start_delay: float, ctl, host_time, scheduled, received, tx,
                parent: int) -> None:
    import os

    import can

    slot = {cob: j for j, cob in enumerate(spec.rx_ids)}
    rx_len = spec.rx_len
    counts = [0] * len(spec.rx_ids)
    fd = {"is_fd": True, "bitrate_switch": True} if spec.fd else {}
    msgs = [can.Message(arbitration_id=cob, data=bytes(length), is_extended_id=cob > 0x7FF, **fd)
            for cob, length in zip(spec.tx_ids, spec.tx_len, strict=True)]
    stop_msgs, end_msgs = ([can.Message(arbitration_id=cob, data=d, is_extended_id=cob > 0x7FF, **fd)
                            for cob, d in zip(spec.tx_ids, payloads, strict=True)]
                           for payloads in (spec.stop_data, spec.end_data))
    clock = time.monotonic
    period = 1.0 / spec.rate
    epoch = time.time() - clock()  # bus timestamps are wall-clock times: this turns them into clock()'s
    echoes = 0

    rx, rx_time = received
    width = spec.width
    guards = [(g.slot, g.offset, g.fmt, g.low, g.high) for g in spec.guards]

    def take(msg) -> None:
        nonlocal echoes
        if msg.arbitration_id == spec.echo_id and echoes < ctl[_SENT]:  # trigger k back from the bus
            if msg.timestamp and abs(msg.timestamp - epoch - host_time[echoes]) < 1.0:
                host_time[echoes] = msg.timestamp - epoch
                ctl[_ECHOED] += 1
            echoes += 1
            return
        j = slot.get(msg.arbitration_id)
        if j is None or msg.is_remote_frame or not ctl[_SENT]:  # frames before the first trigger: not ours
            return
        if rx_len and len(msg.data) != rx_len[j]:
            ctl[_MALFORMED] += 1  # a frame of the wrong length would leave invented bytes in its row (or overflow it)
            return
        k = counts[j]
        if k < n:
            data = msg.data[:width]  # a longer frame than the cycle expects keeps its first bytes
            rx[j, k, :len(data)] = data
            rx_time[j, k] = clock()
        counts[j] = k + 1
        ctl[_RX + j] = k + 1
        if not ctl[_LIMIT]:
            for g, (where, offset, fmt, low, high) in enumerate(guards):
                if where == j and len(msg.data) >= offset + struct.calcsize(fmt):
                    value = struct.unpack_from(fmt, msg.data, offset)[0]
                    if not low <= value <= high:
                        ctl[_LIMIT_AT] = k
                        ctl[_LIMIT] = g + 1
                        return

    def wait_until(deadline: float) -> None:
        while True:
            left = deadline - clock()
            if left <= 0 or ctl[_LIMIT] or ctl[_STOP]:
                return
            msg = bus.recv(timeout=min(left, 0.1))  # a stop is seen within 0.1 s, however far off the next cycle
            if msg is not None:
                take(msg)

    t0 = clock() + start_delay
    orphaned = False
    last_trigger = clock()
    for k in range(n):
        if ctl[_STOP] or ctl[_LIMIT]:
            break
        if parent and os.getppid() != parent:
            orphaned = True
            break
        due = t0 + k * period
        wait_until(due)
        if ctl[_LIMIT] or ctl[_STOP]:  # a limit tripped, or a stop came, while waiting: this setpoint is not sent
            break
        if ctl[_ESTOP]:
            for msg in stop_msgs:
                bus.send(msg)
        else:
            for j, msg in enumerate(msgs):
                msg.data = bytearray(tx[k, j, :spec.tx_len[j]])
                bus.send(msg)
        host_time[k] = last_trigger = clock()
        scheduled[k] = due
        ctl[_SENT] = k + 1
    if orphaned:
        return
    keepalive = spec.keepalive
    next_feed = clock() + keepalive
    feed_until = last_trigger + keepalive_limit(spec.watchdog_timeout)

    def feeding() -> bool:  # a stopped, dead or stalled host's drive is not fed: its watchdog must trip
        return not ctl[_STOP] and clock() < feed_until and not (parent and os.getppid() != parent)

    def feed() -> None:  # zero torque for a drive whose watchdog only commands feed; every `keepalive` s
        nonlocal next_feed
        # checked right before sending: the host's stop may have come (and its stop frame gone out) while the
        # cycle waited in recv, and moteus's zero torque (position mode) would switch a stopped drive back on.
        # Without a keepalive this is the one end frame (a CiA 402 drive's operation disabled): it always goes.
        if keepalive and not feeding():
            return
        for msg in stop_msgs if ctl[_ESTOP] else end_msgs:
            bus.send(msg)
        next_feed = clock() + keepalive

    feed()
    # The answers to the last triggers. A drive that lags (a simulated one on a loaded host) still answers
    # every trigger, in order: wait while answers keep coming, and count as lost only what stays silent.
    quiet = max(1.0, 20 * period)
    end, last_call = clock() + quiet, clock() + TAIL_LIMIT
    answered = min(counts or [0])
    # A tripped limit ends the record at the sample that tripped: wait for that sample's other frames too (an
    # ODrive's cyclic frames are not answers to triggers, so its rows can run ahead of the commands sent).
    wanted = max(int(ctl[_SENT]), int(ctl[_LIMIT_AT]) + 1 if ctl[_LIMIT] else 0)
    while not ctl[_STOP] and answered < wanted and (left := min(end, last_call) - clock()) > 0:  # host gave up
        msg = bus.recv(timeout=min(left, keepalive) if keepalive else left)
        if keepalive and clock() >= next_feed:
            feed()
        if msg is not None:
            take(msg)
            if min(counts or [0]) > answered:
                answered, end = min(counts or [0]), clock() + quiet
    if keepalive:
        # The stream is over: the host takes the feed over when it is next scheduled, then stops the cycle. Until
        # then (at most keepalive_limit s after the last trigger, and never for a dead host: its drive's watchdog
        # must trip) zero torque goes out from here; frames received meanwhile are no part of the stream.
        ctl[_DONE] = 1
        while feeding():
            bus.recv(timeout=max(0.0, next_feed - clock()))
            if clock() >= next_feed:
                feed()
    ctl[_STOP] = 1


def _realtime_priority() -> int:
    """Ask for SCHED_FIFO (1 if granted, 0 if the OS refuses: then the cycle runs at normal priority)."""
    import os

    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
        return 1
    except (AttributeError, OSError):
        return 0
