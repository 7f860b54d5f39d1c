"""The amplifier firmware, independent of the transport: ``handle(msg, now)`` and ``advance(now)``
return the messages to send. Time ``now`` is the host-independent monotonic clock, seconds.

The plant (:class:`firmware_sim.plant.Plant`) runs in blocks with its state carried across, so a stream
is bit-identical to one direct run of the same setpoints. The plant advances only while streaming.

Pacing:
- ``realtime``: sample k of a stream is due at ``t0 + (k-k0)/rate`` (t0 = arrival of its first setpoint
  block); the samples due are computed each tick; running out of setpoints is a BUFFER_UNDERRUN fault.
- ``lockstep``: samples are computed as soon as setpoints are buffered (as fast as flow control allows);
  the watchdog still runs on the wall clock.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from hilbench.drivers import protocol as p
from hilbench.firmware_sim.plant import Plant
from hilbench.firmware_sim.safety import SafetyMonitor, watchdog_trip_index
from hilbench.firmware_sim.sim_config import SimConfig

FIRMWARE_VERSION = "hilbench-sim 0.1.0"
PACINGS = ("realtime", "lockstep")


class Firmware:
    """Device state machine: configuration, arming, setpoint buffer, plant, safety and counters.

    Args:
        sim: simulator configuration (plant and injected effects, never reported).
        pacing: ``"realtime"`` or ``"lockstep"``.
        max_block: largest setpoint block accepted and sample block sent, samples (transport dependent).
    """

    def __init__(self, sim: SimConfig, pacing: str = "realtime", max_block: int = 512) -> None:
        if pacing not in PACINGS:
            raise ValueError(f"pacing must be one of {PACINGS}, got {pacing!r}")
        self.sim = sim
        self.pacing = pacing
        self.max_block = max_block
        self.capacity = sim.buffer_capacity
        self.state = p.State.UNCONFIGURED
        self.config: p.Config | None = None
        self.plant: Plant | None = None
        self.safety: SafetyMonitor | None = None
        self.index = 0  # next device sample index
        self.current_applied = 0.0
        self._buffer: deque[np.ndarray] = deque()
        self._buffered = 0
        self._end_seen = False
        self._expected_seq = 0
        self.received = 0  # setpoints received in this stream
        self._sample_seq = 0
        self._t0 = 0.0
        self._k0 = 0
        self.last_rx = -math.inf
        self._pending_faults = 0  # faults latched outside a stream (reported with a STATUS)
        self.counters = {"crc_errors": 0, "dropped_frames": 0, "rx_frames": 0, "tx_frames": 0}

    # ------------------------------------------------------------------ messages
    def identity(self) -> p.Identity:
        return p.Identity(self.sim.model, self.sim.serial, FIRMWARE_VERSION, p.PROTOCOL_VERSION,
                          self.capacity, self.max_block)

    def status(self, token: int = 0) -> p.Status:
        s = self.safety
        return p.Status(token, self.state, s.faults if s else self._pending_faults, self.index,
                        self.capacity - self._buffered, self.received, s.fault_index if s else 0,
                        s.fault_silence if s else 0, self.current_applied, **self.counters)

    @property
    def busy(self) -> bool:
        """Streaming with setpoints buffered: lockstep pacing has work to do right now."""
        return self.state == p.State.STREAMING and self._buffered > 0

    @property
    def faults(self) -> int:
        return self.safety.faults if self.safety else self._pending_faults

    def handle(self, msg: p.Message, now: float) -> list[p.Message]:
        """Apply one host message received at ``now``; return the replies."""
        self.last_rx = now
        self.counters["rx_frames"] += 1
        T = p.MsgType
        t = msg.TYPE
        if t == T.HEARTBEAT:
            return [self.status(msg.token)]
        if t == T.SETPOINTS:
            return self._on_setpoints(msg, now)
        if t == T.GET_IDENTITY:
            return [self.identity()]
        if t == T.GET_CONFIG:
            return [self.config] if self.config else [p.Reply(t, p.Result.NOT_CONFIGURED, self.faults)]
        if t == T.ESTOP:
            out = self._stop(p.Fault.ESTOP)
            return out + [p.Reply(t, p.Result.OK, self.faults)]
        if t == T.DISARM:
            out = self._stop(0)
            return out + [p.Reply(t, p.Result.OK, self.faults)]
        if t == T.CLEAR_FAULTS:
            if self.safety:
                self.safety.clear()
            self._pending_faults = 0
            return [p.Reply(t, p.Result.OK, 0)]
        if t == T.CONFIG:
            return [self._configure(msg)]
        if t == T.ARM:
            return [self._arm()]
        return [p.Reply(t, p.Result.BAD_STATE, self.faults)]  # device-to-host types sent to the device

    def _configure(self, cfg: p.Config) -> p.Reply:
        if self.state in (p.State.ARMED, p.State.STREAMING):
            return p.Reply(p.MsgType.CONFIG, p.Result.BAD_STATE, self.faults)
        if cfg.problems() or cfg.mode == p.Mode.POSITION:  # position mode: the C core only
            return p.Reply(p.MsgType.CONFIG, p.Result.INVALID_CONFIG, self.faults)
        faults = self.faults
        params = self.sim.plant_for(cfg.current_limit, cfg.torque_constant, cfg.counts_per_rev)
        mode = "current" if cfg.mode == p.Mode.CURRENT else "velocity"
        self.plant = Plant(params, 1.0 / cfg.sample_rate, self.sim.substeps_at(cfg.sample_rate), mode)
        old = self.safety
        self.safety = SafetyMonitor(cfg)
        if old is not None:  # latched faults survive a reconfiguration
            self.safety.faults, self.safety.fault_index = old.faults, old.fault_index
            self.safety.fault_silence = old.fault_silence
        else:
            self.safety.faults = faults
        self.config = cfg
        self.index = 0
        self.current_applied = 0.0
        self.state = p.State.DISARMED
        return p.Reply(p.MsgType.CONFIG, p.Result.OK, self.faults)

    def _arm(self) -> p.Reply:
        if self.state == p.State.UNCONFIGURED:
            return p.Reply(p.MsgType.ARM, p.Result.NOT_CONFIGURED, self.faults)
        if self.faults:
            return p.Reply(p.MsgType.ARM, p.Result.FAULT_LATCHED, self.faults)
        if self.state == p.State.DISARMED:
            self._reset_stream()
            self.state = p.State.ARMED
        return p.Reply(p.MsgType.ARM, p.Result.OK, 0)

    def _reset_stream(self) -> None:
        self._buffer.clear()
        self._buffered = 0
        self._end_seen = False
        self._expected_seq = 0
        self.received = 0
        self.safety.reset_history()

    def _on_setpoints(self, blk: p.SetpointBlock, now: float) -> list[p.Message]:
        if self.state not in (p.State.ARMED, p.State.STREAMING) or self._end_seen:
            self.counters["dropped_frames"] += 1  # late blocks after a fault or disarm
            return []
        if blk.seq != self._expected_seq or len(blk.values) > self.max_block \
                or self._buffered + len(blk.values) > self.capacity or not np.all(np.isfinite(blk.values)):
            # a lost block, an overflow or garbage: the device cannot keep the stream in time
            self.counters["dropped_frames"] += 1
            return self._stop(p.Fault.BUFFER_UNDERRUN) if self.state == p.State.STREAMING else \
                self._latch_idle(p.Fault.BUFFER_UNDERRUN)
        self._expected_seq = (self._expected_seq + 1) & 0xFFFFFFFF
        self.received += len(blk.values)
        if len(blk.values):
            self._buffer.append(blk.values.astype(np.float64))
            self._buffered += len(blk.values)
        self._end_seen = blk.end
        if self.state == p.State.ARMED:
            self.state = p.State.STREAMING
            self._t0, self._k0 = now, self.index
        return []

    def _latch_idle(self, faults: int) -> list[p.Message]:
        self.safety.latch(faults, self.index, 0)
        self.state = p.State.DISARMED
        return [self.status()]

    # ------------------------------------------------------------------ sample production
    def _take(self, n: int) -> np.ndarray:
        if n <= 0:  # a fault latched with nothing buffered (host gone, or a tick ending on the trip sample)
            return np.zeros(0)
        parts, need = [], n
        while need:
            head = self._buffer[0]
            if len(head) <= need:
                parts.append(self._buffer.popleft())
                need -= len(head)
            else:
                parts.append(head[:need])
                self._buffer[0] = head[need:]
                need = 0
        self._buffered -= n
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    def _silence(self, k: int) -> int:
        """Samples between the host's last message and sample k (realtime clock)."""
        rate = self.config.sample_rate
        return k - (self._k0 + math.floor((self.last_rx - self._t0) * rate))

    def advance(self, now: float) -> list[p.Message]:
        """Compute the samples due at ``now``; return the sample blocks (and a STATUS after a fault)."""
        if self.state == p.State.ARMED:
            return self._check_idle_watchdog(now)
        if self.state != p.State.STREAMING:
            return []
        cfg = self.config
        rate = cfg.sample_rate
        if self.pacing == "realtime":
            due = math.floor((now - self._t0) * rate) - (self.index - self._k0)
            wd = watchdog_trip_index(self.last_rx, cfg.watchdog_timeout, self._t0, self._k0, rate)
        else:
            due = min(self._buffered, 4 * self.max_block)
            expired = cfg.watchdog_timeout > 0 and now - self.last_rx > cfg.watchdog_timeout
            wd = self.index if expired else None
        # the watchdog runs on every tick: an expired deadline trips even with nothing due or buffered
        tripped = wd is not None and wd <= self.index
        out: list[p.Message] = []
        while (due > 0 or tripped) and self.state == p.State.STREAMING:
            n = min(due, self.max_block)
            pending = 0
            if wd is not None and wd < self.index + max(n, 1):
                n, pending = max(0, wd - self.index), p.Fault.WATCHDOG
            if n > self._buffered:  # the setpoints run out first: that ends the stream, or is the fault
                n, pending = self._buffered, 0 if self._end_seen else p.Fault.BUFFER_UNDERRUN
            if n == 0 and not pending:
                break
            out.append(self._execute(self._take(n), pending, now))
            due -= n + (1 if pending else 0)
            if self._end_seen and self._buffered == 0 and self.state == p.State.STREAMING:
                self._finish_stream(out)
        if self.safety.faults and out:
            out.append(self.status())
        return out

    def _check_idle_watchdog(self, now: float) -> list[p.Message]:
        timeout = self.config.watchdog_timeout
        if timeout > 0 and now - self.last_rx > timeout:
            self.safety.latch(p.Fault.WATCHDOG, self.index, 0)
            self.state = p.State.DISARMED
            return [self.status()]
        return []

    def _finish_stream(self, out: list[p.Message]) -> None:
        last = out[-1]
        if len(last):
            last.status[-1] |= p.SampleStatus.END
        self.state = p.State.ARMED
        self.current_applied = 0.0
        self._reset_stream()
        last.state = self.state

    def _execute(self, u: np.ndarray, pending: int, now: float) -> p.SampleBlock:
        """Run setpoints ``u`` then, if ``pending`` faults, one zero-current sample that latches them.
        A limit trip inside ``u`` cuts the block there instead."""
        plant, safety = self.plant, self.safety
        saved = plant.get_state()
        res = plant.run(u)
        j, trip = safety.first_trip(res.counts, res.current_meas, u)
        if trip:
            plant.set_state(saved)
            res = plant.run(u[:j])
            pending = trip
        parts = [res]
        if pending:
            parts.append(self._zero_sample())
        counts = np.concatenate([r.counts for r in parts])
        cmd = np.concatenate([r.current_cmd for r in parts])
        meas = np.concatenate([r.current_meas for r in parts])
        status = np.full(len(counts), p.SampleStatus.ENABLED, dtype=np.uint16)
        safety.accept(counts)
        first = self.index
        self.index += len(counts)
        self.current_applied = float(cmd[-1]) if len(cmd) else self.current_applied
        if pending:
            status[-1] = p.SampleStatus.FAULT | p.SampleStatus.END
            silence = self._silence(self.index - 1) if self.pacing == "realtime" else \
                round((now - self.last_rx) * self.config.sample_rate)
            safety.latch(pending, self.index - 1, silence)
            self.state = p.State.DISARMED
            self._reset_stream()
        return self._block(first, counts, cmd, meas, status)

    def _zero_sample(self):
        """One sample with the current command forced to zero (power stage off), in any mode."""
        plant = self.plant
        mode = plant.mode
        plant.mode = "current"
        try:
            return plant.run(np.zeros(1))
        finally:
            plant.mode = mode

    def _block(self, first: int, counts, cmd, meas, status) -> p.SampleBlock:
        blk = p.SampleBlock(self._sample_seq, first, self.capacity - self._buffered, self.received,
                            self.faults, self.state, counts.astype(np.int32), cmd, meas, status)
        self._sample_seq = (self._sample_seq + 1) & 0xFFFFFFFF
        return blk

    def _stop(self, faults: int) -> list[p.Message]:
        """E-stop (``faults`` = ESTOP) or disarm (0): zero current now, one final sample if streaming."""
        out: list[p.Message] = []
        if self.state == p.State.STREAMING:
            res = self._zero_sample()
            self.safety.accept(res.counts)
            status = np.array([p.SampleStatus.END | (p.SampleStatus.FAULT if faults else 0)], dtype=np.uint16)
            first = self.index
            self.index += 1
            if faults:
                self.safety.latch(faults, first, 0)
            self.state = p.State.DISARMED
            self._reset_stream()
            out.append(self._block(first, res.counts, res.current_cmd, res.current_meas, status))
        elif faults and self.safety is not None:
            self.safety.latch(faults, self.index, 0)
        elif faults:
            self._pending_faults |= int(faults)
        if self.state != p.State.UNCONFIGURED:
            self.state = p.State.DISARMED
        self.current_applied = 0.0
        return out
