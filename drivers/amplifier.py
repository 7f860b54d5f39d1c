"""The high-level amplifier client.

    with open_device("sim://?pacing=lockstep") as amp:        # drivers.device_url.open_device
        amp.configure(Config(sample_rate=10000, current_limit=3.0, torque_constant=0.2))
        amp.arm()
        for block in amp.stream(setpoints_in_amperes):
            use(block.time, block.position, block.torque)

Closing always disarms. A receiver thread reads the link; whatever it raises is handed to the caller on the
next call instead of dying silently. Setpoints are checked against the configured limits before anything
is sent. :meth:`Amplifier.estop` reaches the device even while :meth:`Amplifier.stream` runs in another
thread (link writes are serialised by a lock that is only held for one write).
"""

from __future__ import annotations

import collections
import itertools
import math
import queue
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from hilbench.common.physical_bounds import ABSOLUTE_ZERO_DEGC, WINDING_TEMPERATURE_MAX_DEGC, temperature_possible
from hilbench.common.runfile.schema import CURRENT_CMD, DeviceIdentity
from hilbench.drivers import protocol as p
from hilbench.drivers.calibration import Calibration, CountUnwrapper
from hilbench.drivers.device import Capabilities, Device, SampleBlock
from hilbench.drivers.errors import (
    CommandRefusedError,
    ConfigError,
    DeviceFaultError,
    DeviceTimeoutError,
    DriverError,
    LinkClosedError,
    SampleLossError,
    SetpointError,
)
from hilbench.drivers.links import Link

_CLOSED = object()  # wakes waiters when the receiver stops


@dataclass
class Samples(SampleBlock):
    """One block of device samples, host side: counts unwrapped, SI conversions via the calibration.

    Attributes:
        first_index: device sample index of the first sample.
        counts: encoder counts, int64, continuous since CONFIG.
        current_cmd, current_meas: commanded and measured motor current, A.
        status: :class:`drivers.protocol.SampleStatus` bits per sample.
        sample_rate: Hz; calibration: the configured :class:`Calibration`.
    """

    first_index: int
    counts: np.ndarray
    current_cmd: np.ndarray
    current_meas: np.ndarray
    status: np.ndarray
    sample_rate: int
    calibration: Calibration
    temperature: float | None = None  # winding temperature when the block was sent, degC (None: no sensor)

    def __len__(self) -> int:
        return len(self.counts)

    def extra(self) -> dict[str, np.ndarray]:
        """The device's temperature reading held over the block's samples (one reading per block)."""
        if self.temperature is None:
            return {}
        return {"temperature": np.full(len(self.counts), self.temperature)}

    @property
    def index(self) -> np.ndarray:
        """Device sample indices, int64."""
        return self.first_index + np.arange(len(self.counts), dtype=np.int64)

    @property
    def time(self) -> np.ndarray:
        """Device time of each sample, s (index / sample rate; 0 at CONFIG)."""
        return self.index / self.sample_rate

    @property
    def position(self) -> np.ndarray:
        """Load angle, rad."""
        return self.calibration.position(self.counts)

    @property
    def torque(self) -> np.ndarray:
        """Motor torque at the load from the measured current, N*m."""
        return self.calibration.torque(self.current_meas)


def flag_impossible(current_cmd: np.ndarray, current_meas: np.ndarray, temperature: float | None,
                    first_index: int) -> tuple[np.ndarray, np.ndarray, float | None, int, str]:
    """A block's currents (A, float64 copies) and temperature (degC; None: no sensor) with the readings no motor
    can give set to NaN: a non-finite current; a temperature that is non-finite, below absolute zero or above the
    melting point of copper. Also how many were set, and a note on the last one (its value and sample index)."""
    cmd, meas = current_cmd.astype(np.float64), current_meas.astype(np.float64)  # the block's own copies
    # the streaming path: one dot product per array (x.x is finite iff every x is: float32 squares cannot overflow)
    if math.isfinite(cmd.dot(cmd) + meas.dot(meas)) and (temperature is None or temperature_possible(temperature)):
        return cmd, meas, temperature, 0, ""
    bad, note = 0, ""
    for values, name in ((cmd, CURRENT_CMD), (meas, "current")):
        wrong = ~np.isfinite(values)
        if wrong.any():
            bad += int(wrong.sum())
            note = f"{name} {values[wrong][-1]} A at sample {first_index + int(np.flatnonzero(wrong)[-1])}"
            values[wrong] = np.nan
    if temperature is not None and not temperature_possible(temperature):
        bad += 1
        note = f"temperature {temperature} degC at sample {first_index}"
        temperature = math.nan
    return cmd, meas, temperature, bad, note


def check_setpoints(setpoints, config: p.Config) -> np.ndarray:
    """Host-side check of a setpoint array against a configuration; returns it as float64.

    Shape (n,), or (n, 2) in position mode with feed-forward (column 0 angle, rad; column 1 current, A).
    Raises :class:`SetpointError` for a wrong shape or an empty array, NaN/inf, or a value beyond the
    configured current limit (current mode and the feed-forward column, A), velocity limit (velocity mode,
    rad/s) or position window (position mode, rad).
    """
    try:
        values = np.asarray(setpoints, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SetpointError(f"setpoints are not numbers: {exc}") from exc
    m = config.values_per_sample
    shape = "1-D (n,)" if m == 1 else f"(n, {m}) (angle rad, feed-forward current A)"
    if (values.ndim != (1 if m == 1 else 2)) or (m > 1 and values.shape[1] != m) or values.size == 0:
        raise SetpointError(f"setpoints must be a non-empty {shape} array in {config.mode.name.lower()} mode, "
                            f"got shape {values.shape}")
    finite = np.isfinite(values)
    if not finite.all():
        i = int(np.argmax(~finite.reshape(len(values), -1).all(axis=1)))
        raise SetpointError(f"setpoint {i} is {values[i]}; setpoints must be finite")
    if config.mode == p.Mode.POSITION:
        angle = values if m == 1 else values[:, 0]
        outside = (angle < config.position_min) | (angle > config.position_max)
        if outside.any():
            i = int(np.argmax(outside))
            raise SetpointError(f"position setpoint {i} = {angle[i]:.6g} rad is outside the configured window "
                                f"[{config.position_min:.6g}, {config.position_max:.6g}] rad "
                                f"({int(outside.sum())} setpoints outside it)")
        if m == 1:
            return values
        checks = [(values[:, 1], config.current_limit, "A", "current limit (feed-forward column)")]
    elif config.mode == p.Mode.CURRENT:
        checks = [(values, config.current_limit, "A", "current limit")]
    else:
        checks = [(values, config.velocity_limit, "rad/s", "velocity limit")]
    for column, limit, unit, name in checks:
        over = np.abs(column) > limit
        if over.any():
            i = int(np.argmax(over))
            raise SetpointError(f"setpoint {i} = {column[i]:.6g} {unit} exceeds the configured {name} "
                                f"of {limit:.6g} {unit} ({int(over.sum())} setpoints beyond it)")
    return values


class Amplifier(Device):
    """Client of one device on a link. Use as a context manager; ``close()`` always disarms.

    Args:
        link: a connected :class:`drivers.links.Link`.
        timeout: how long to wait for a reply or a sample block, s.
        on_close: called after the link is closed (e.g. stops a simulator process).
    """

    clock = "device"
    capabilities = Capabilities({"current": p.SAMPLE_RATES, "velocity": p.SAMPLE_RATES,
                                 "position": p.SAMPLE_RATES})
    name = "hilbench amplifier"

    def __init__(self, link: Link, timeout: float = 2.0, on_close: Callable[[], None] | None = None) -> None:
        self._link = link
        self.timeout = timeout
        self._on_close = on_close
        self._tx_lock = threading.Lock()
        self._key_locks: dict = collections.defaultdict(threading.Lock)
        self._queues: dict = collections.defaultdict(queue.Queue)
        self._samples: queue.Queue = queue.Queue()
        self._tokens = itertools.count(1)
        self._error: BaseException | None = None
        self._closing = threading.Event()
        self._closed = False
        self._last_tx = 0.0
        self.config: p.Config | None = None
        self.last_status: p.Status | None = None
        self.lost_samples = 0
        self.duplicate_samples = 0
        self.impossible_readings = 0  # readings no motor can give, recorded as NaN (see _flag_impossible)
        self._last_impossible = ""
        self._reported = {"crc_errors": 0, "dropped_frames": 0, "impossible": 0}  # what run_events has told
        self._unwrap = CountUnwrapper()
        self._thread = threading.Thread(target=self._receive, name="amplifier-rx", daemon=True)
        self._thread.start()
        try:
            self.identity: p.Identity = self._identify()
            # from here on the decoder reads payloads in the agreed protocol's layouts, whatever their length
            self._link.protocol_version = self.identity.protocol_version
            self._drain_stale()
            ident = self.identity
            if ident.max_block < 1 or ident.buffer_capacity < ident.max_block:
                # a block of 0 setpoints would make stream() send empty blocks forever
                raise DriverError(f"device reports max_block={ident.max_block} and buffer_capacity="
                                  f"{ident.buffer_capacity} samples; it needs 1 <= max_block <= buffer_capacity")
            reply = self._request(p.GetConfig(), (p.MsgType.CONFIG, p.MsgType.REPLY))
            if isinstance(reply, p.Config):
                self._set_config(reply)
        except BaseException:
            self.close()
            raise

    def _identify(self) -> p.Identity:
        """GET_IDENTITY with this host's protocol version. An older device drops it (its decoder refuses a
        newer frame); asked again the v2 way, then the v1 way, it answers, and is refused in one line that
        names the version it speaks."""
        try:
            ident = self._request(p.GetIdentity(), p.MsgType.IDENTITY, timeout=self.timeout * 2 / 3, attempts=2)
        except DeviceTimeoutError:
            old = None
            for version in range(p.PROTOCOL_VERSION - 1, 0, -1):
                try:
                    old = self._request(p.GetIdentity(version), p.MsgType.IDENTITY,
                                        timeout=self.timeout / 3 / (p.PROTOCOL_VERSION - 1), attempts=1)
                    break
                except DeviceTimeoutError:
                    continue
            if old is None:
                raise DeviceTimeoutError(f"no answer to GET_IDENTITY from the device within "
                                         f"{self.timeout:.3g} s") from None
            raise DriverError(f"device {old.model} (firmware {old.firmware}) speaks protocol "
                              f"{old.protocol_version}; this host needs protocol {p.PROTOCOL_VERSION}: "
                              f"update the device firmware") from None
        if ident.protocol_version != p.PROTOCOL_VERSION:
            raise DriverError(f"device speaks protocol {ident.protocol_version}, this host {p.PROTOCOL_VERSION}")
        return ident

    @property
    def reported_channels(self) -> tuple[str, ...]:
        """``temperature`` when the device's IDENTITY names a winding sensor (protocol v3)."""
        return ("temperature",) if self.identity.sensors & p.Sensor.TEMPERATURE else ()

    # ------------------------------------------------------------------ plumbing
    def _receive(self) -> None:
        link = self._link
        try:
            while not self._closing.is_set():
                msg = link.recv(0.01)
                if msg is not None:
                    self._dispatch(msg)
                period = self._heartbeat_period()
                if time.monotonic() - self._last_tx > period:
                    self._send(p.Heartbeat(0))
        except BaseException as exc:  # handed to the caller, never swallowed
            if not self._closing.is_set():
                self._error = exc
        finally:
            for q in list(self._queues.values()) + [self._samples]:
                q.put(_CLOSED)

    def _drain_stale(self) -> None:
        """Forget everything received before the identity answer: it was meant for a previous host (the
        device answers in order, so whatever a previous connection left in the pipe came first)."""
        for q in list(self._queues.values()) + [self._samples]:
            while not q.empty():
                if q.get_nowait() is _CLOSED:
                    q.put(_CLOSED)
                    break

    def _heartbeat_period(self) -> float:
        wd = self.config.watchdog_timeout if self.config else 0.0
        return max(0.005, wd / 4) if wd > 0 else 0.25

    def _dispatch(self, msg: p.Message) -> None:
        t = msg.TYPE
        if t == p.MsgType.SAMPLES:
            self._samples.put(msg)
        elif t == p.MsgType.STATUS:
            self.last_status = msg
            if msg.token:
                self._queues[("status", msg.token)].put(msg)
        elif t == p.MsgType.REPLY:
            self._queues[(p.MsgType.REPLY, msg.request)].put(msg)
            if msg.request == p.MsgType.GET_CONFIG:
                self._queues[(p.MsgType.CONFIG, p.MsgType.REPLY)].put(msg)
        elif t == p.MsgType.CONFIG:
            self._queues[(p.MsgType.CONFIG, p.MsgType.REPLY)].put(msg)
        else:
            self._queues[t].put(msg)

    def _raise_if_failed(self) -> None:
        if self._error is not None:
            exc = self._error
            if isinstance(exc, DriverError):
                raise exc
            raise LinkClosedError(f"receiver thread failed: {exc!r}") from exc
        if self._closed:
            raise LinkClosedError("the amplifier connection is closed")

    def _send(self, msg: p.Message) -> None:
        with self._tx_lock:
            self._link.send(msg)
            self._last_tx = time.monotonic()

    def _wait(self, q: queue.Queue, timeout: float, what: str):
        try:
            item = q.get(timeout=timeout)
        except queue.Empty:
            self._raise_if_failed()
            raise DeviceTimeoutError(f"no {what} from the device within {timeout:.3g} s") from None
        if item is _CLOSED:
            q.put(_CLOSED)
            self._raise_if_failed()
            raise LinkClosedError("link closed while waiting for the device")
        return item

    def _request(self, msg: p.Message, key, timeout: float | None = None, attempts: int = 3):
        """Send ``msg`` and wait for its answer; every request is idempotent, so a request or answer
        lost on the link is retried (``attempts`` tries within ``timeout``)."""
        self._raise_if_failed()
        timeout = self.timeout if timeout is None else timeout
        with self._key_locks[key]:
            q = self._queues[key]
            for attempt in range(attempts):
                while not q.empty():  # stale answers of an attempt that timed out
                    if q.get_nowait() is _CLOSED:
                        q.put(_CLOSED)
                        break
                self._send(msg)
                try:
                    return self._wait(q, timeout / attempts, f"answer to {msg.TYPE.name}")
                except DeviceTimeoutError:
                    if attempt == attempts - 1:
                        raise DeviceTimeoutError(f"no answer to {msg.TYPE.name} from the device within "
                                                 f"{timeout:.3g} s ({attempts} attempts)") from None

    def _command(self, msg: p.Message) -> p.Reply:
        reply = self._request(msg, (p.MsgType.REPLY, msg.TYPE))
        name = msg.TYPE.name
        if reply.result == p.Result.FAULT_LATCHED:
            raise DeviceFaultError(f"{name} refused: faults latched ({p.describe_faults(reply.faults)}); "
                                   f"clear them with `hilbench fault clear --device URL` first", reply.faults)
        if reply.result == p.Result.NOT_CONFIGURED:
            raise CommandRefusedError(f"{name} refused: the device is not configured (a run configures it)")
        if reply.result == p.Result.INVALID_CONFIG:
            raise ConfigError(f"{name} refused by the device: invalid configuration")
        if reply.result != p.Result.OK:
            raise CommandRefusedError(f"{name} refused: {p.Result(reply.result).name} "
                                      f"(state does not allow it; disarm first?)")
        return reply

    def _set_config(self, config: p.Config) -> None:
        self.config = config
        self.calibration = Calibration(config.torque_constant, config.counts_per_rev, config.ratio)
        self._unwrap.reset()

    # ------------------------------------------------------------------ API
    def configure(self, config: p.Config) -> None:
        """Check ``config`` host-side (:class:`ConfigError` with every problem), then send it.
        Resets the device sample index and encoder count to 0."""
        problems = config.problems()
        if problems:
            raise ConfigError("; ".join(problems))
        self._command(config)
        self._set_config(config)

    def arm(self) -> None:
        """Enable the power stage (zero current until setpoints stream). Refused while faults are latched."""
        self._command(p.Arm())

    def disarm(self) -> None:
        """Zero the current and disable the power stage; ends a running stream."""
        self._command(p.Disarm())

    def estop(self) -> None:
        """Emergency stop: zero current now and latch the ESTOP fault. Safe to call from any thread."""
        self._command(p.EStop())

    def clear_faults(self) -> None:
        """Clear every latched fault (the only way to clear them)."""
        self._command(p.ClearFaults())

    def info(self) -> DeviceIdentity:
        i = self.identity
        return DeviceIdentity(model=i.model, serial=i.serial, firmware=i.firmware,
                              details={"protocol_version": i.protocol_version, "buffer_capacity": i.buffer_capacity,
                                       "max_block": i.max_block, "sensors": int(i.sensors)})

    def state(self) -> str:
        return p.State(self.status().state).name

    def faults(self) -> list[str]:
        status = self.status()
        if not status.faults:
            return []
        return [f"{p.describe_faults(status.faults)} (first at sample {status.fault_index})"]

    def status(self) -> p.Status:
        """A fresh :class:`drivers.protocol.Status` (state, faults, counters) from the device."""
        token = next(self._tokens) & 0xFFFFFFFF or 1
        return self._request(p.Heartbeat(token), ("status", token))

    @property
    def counters(self) -> dict[str, int]:
        """Host counters (``host_*``: link CRC errors, which count every malformed frame dropped, dropped
        frames, lost and duplicate samples, impossible readings recorded as NaN) and the device's counters
        from its last status (``device_*``)."""
        out = {f"host_{k}": v for k, v in self._link.counters.items()}
        out["host_lost_samples"] = self.lost_samples
        out["host_duplicate_samples"] = self.duplicate_samples
        out["host_impossible_readings"] = self.impossible_readings
        s = self.last_status
        if s is not None:
            for k in ("crc_errors", "dropped_frames", "rx_frames", "tx_frames"):
                out[f"device_{k}"] = getattr(s, k)
        return out

    def stream(self, setpoints, block: int | None = None, allow_loss: bool = False) -> Iterator[Samples]:
        """Stream ``setpoints`` (A in current mode, rad/s in velocity mode, rad in position mode; sent as
        float32) to an armed device and yield its sample blocks in device time, one device sample per
        setpoint. In position mode with feed-forward, ``setpoints`` is (n, 2): angle (rad), current (A).

        Flow control: never more setpoints in flight than the device reports free. Sample blocks lost on
        the link are counted in ``lost_samples``; unless ``allow_loss``, :class:`SampleLossError` is raised
        once the stream has ended. Raises :class:`DeviceFaultError` after yielding the block in which a
        fault, e-stop or disarm ended the stream early. Leaving the loop early disarms the device.
        """
        cfg = self.config
        if cfg is None:
            raise CommandRefusedError("configure() the device before streaming")
        values = check_setpoints(setpoints, cfg).astype(np.float32)
        status = self.status()
        if status.faults:
            raise DeviceFaultError(f"cannot stream: faults latched ({p.describe_faults(status.faults)})",
                                   status.faults)
        if status.state != p.State.ARMED:
            state = p.State(status.state).name
            raise CommandRefusedError(f"cannot stream: device is {state}, not armed")
        block = min(block or self.identity.max_block, self.identity.max_block)
        return self._stream(values, block, status, allow_loss)

    def _stream(self, values: np.ndarray, block: int, status: p.Status,
                allow_loss: bool) -> Iterator[Samples]:
        cfg = self.config
        n_total = len(values)
        sensing = bool(self.reported_channels)
        while not self._samples.empty():
            if self._samples.get_nowait() is _CLOSED:
                self._samples.put(_CLOSED)
                break
        start = status.index
        free, dev_received = status.free, 0
        sent = seq = 0
        next_index = start
        wait = self.timeout + block / cfg.sample_rate
        finished = False
        lost_before = self.lost_samples
        try:
            while next_index < start + n_total:
                while sent < n_total:
                    n = min(block, n_total - sent)
                    if free - (sent - dev_received) < n:
                        break
                    self._send(p.SetpointBlock(seq, values[sent: sent + n].reshape(-1), end=sent + n == n_total))
                    sent += n
                    seq += 1
                try:
                    blk = self._wait(self._samples, wait, "sample block")
                except DeviceTimeoutError:
                    self._after_silence(start + n_total, next_index)  # raises unless the device is done
                    break
                free, dev_received = blk.free, blk.received
                if blk.first_index + len(blk) <= next_index:
                    self.duplicate_samples += len(blk)
                    continue
                if blk.first_index > next_index:
                    self.lost_samples += blk.first_index - next_index
                next_index = blk.first_index + len(blk)
                cmd, meas, temperature, bad, note = flag_impossible(
                    blk.current_cmd, blk.current_meas, blk.temperature if sensing else None, blk.first_index)
                if bad:
                    self.impossible_readings += bad
                    self._last_impossible = note
                yield Samples(blk.first_index, self._unwrap(blk.counts), cmd, meas, blk.status.copy(),
                              cfg.sample_rate, self.calibration, temperature)
                if len(blk) and blk.status[-1] & p.SampleStatus.END and next_index < start + n_total:
                    finished = True
                    why = p.describe_faults(blk.faults) if blk.faults else "disarmed"
                    raise DeviceFaultError(f"stream ended by the device at sample {next_index - 1}: {why}",
                                           blk.faults)
            finished = True
            lost = self.lost_samples - lost_before
            if lost and not allow_loss:
                raise SampleLossError(f"{lost} of {n_total} samples were lost on the link "
                                      f"(host CRC errors: {self._link.counters['crc_errors']})")
        finally:
            if not finished and self._error is None and not self._closed:
                try:
                    self.disarm()
                except DriverError:
                    pass

    def run_events(self) -> list[tuple[str, str]]:
        """Since the previous call: malformed frames the link counted and dropped, and impossible readings
        recorded as NaN, one ``info`` event each (none when there were none)."""
        counters = self._link.counters
        now = {"crc_errors": counters.get("crc_errors", 0), "dropped_frames": counters.get("dropped_frames", 0),
               "impossible": self.impossible_readings}
        new = {k: now[k] - self._reported[k] for k in now}
        self._reported = now
        out = []
        if new["crc_errors"] or new["dropped_frames"]:
            why = getattr(self._link, "last_error", "")
            out.append(("info", f"link: {new['crc_errors']} malformed frame(s) counted and dropped, "
                                f"{new['dropped_frames']} message(s) lost to missing segments"
                                + (f" (last: {why})" if why else "")))
        if new["impossible"]:
            out.append(("info", f"{new['impossible']} impossible reading(s) recorded as NaN (non-finite current; "
                                f"temperature outside {ABSOLUTE_ZERO_DEGC:g}..{WINDING_TEMPERATURE_MAX_DEGC:g} degC "
                                f"or non-finite); last: {self._last_impossible}"))
        return out

    def _after_silence(self, end: int, next_index: int) -> None:
        """No sample block for a while: ask the device. If it completed the stream, the missing tail was
        lost on the link (counted, returns None); otherwise the device is stuck: DeviceTimeoutError."""
        status = self.status()
        if status.state != p.State.STREAMING and status.index >= end:
            self.lost_samples += end - next_index
            return None
        if status.faults:
            raise DeviceFaultError(f"stream ended by the device: {p.describe_faults(status.faults)} "
                                   f"(its last sample block was lost)", status.faults)
        raise DeviceTimeoutError(f"device stopped producing samples at {next_index} (state "
                                 f"{p.State(status.state).name}, index {status.index})")

    def close(self) -> None:
        """Disarm (if the link still works), stop the receiver and close the link. Idempotent."""
        if self._closed:
            return
        try:
            if self._error is None and self._thread.is_alive():
                self._command(p.Disarm())
        except DriverError:
            pass
        finally:
            self._closed = True
            self._closing.set()
            self._thread.join(timeout=2.0)
            self._link.close()
            if self._on_close is not None:
                self._on_close()

    def __enter__(self) -> Amplifier:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
