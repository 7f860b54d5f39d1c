"""Messages of the hilbench wire protocol: pure classes with ``encode()`` / ``decode(payload)``.

Every message has a one-byte :class:`MsgType` and a little-endian payload; the framing (serial COBS+CRC
or CAN segments) is added by :mod:`drivers.protocol.serial_framing` / :mod:`drivers.protocol.can_framing`.
See ``docs/protocol.md`` for the byte layouts. Decoding raises only :class:`drivers.errors.ProtocolError`.
"""

from __future__ import annotations

import enum
import math
import struct
from typing import ClassVar

import numpy as np

from hilbench.drivers.errors import ProtocolError

#: Protocol this host speaks (v2: position mode, the CONFIG gains, GET_IDENTITY carries the host's version;
#: v3: IDENTITY names the device's sensors, a SAMPLES header carries the winding temperature).
PROTOCOL_VERSION = 3
#: Frame versions a decoder accepts: the host still reads a v1 device's answers (to refuse it clearly).
FRAME_VERSIONS = (1, 2, 3)
SAMPLE_RATES = (1000, 2000, 5000, 10000, 20000)  # Hz, the only rates a device accepts


class MsgType(enum.IntEnum):
    """Message type byte. Low values win CAN arbitration, so e-stop is 1."""

    ESTOP = 0x01
    DISARM = 0x02
    ARM = 0x03
    CLEAR_FAULTS = 0x04
    CONFIG = 0x05
    GET_CONFIG = 0x06
    GET_IDENTITY = 0x07
    IDENTITY = 0x08
    HEARTBEAT = 0x09
    STATUS = 0x0A
    REPLY = 0x0B
    SETPOINTS = 0x0C
    SAMPLES = 0x0D


class Mode(enum.IntEnum):
    CURRENT = 0  # setpoints are motor current, A
    VELOCITY = 1  # setpoints are encoder-shaft velocity, rad/s (device runs its velocity PI loop)
    POSITION = 2  # setpoints are encoder-shaft angle, rad (+ feed-forward current, A); device PID loop (v2)


class State(enum.IntEnum):
    UNCONFIGURED = 0
    DISARMED = 1
    ARMED = 2  # power stage on, zero current, waiting for the first setpoint block
    STREAMING = 3


class Fault(enum.IntFlag):
    """Latched faults: set by the device, cleared only by CLEAR_FAULTS."""

    OVER_CURRENT = 0x01
    OVER_SPEED = 0x02
    POSITION_WINDOW = 0x04
    WATCHDOG = 0x08
    BUFFER_UNDERRUN = 0x10
    ESTOP = 0x20


class Sensor(enum.IntFlag):
    """What a device measures beyond the encoder and the current (IDENTITY, protocol v3)."""

    TEMPERATURE = 0x01  # winding temperature in every SAMPLES header, degC


class SampleStatus(enum.IntFlag):
    """Per-sample status bits of a sample block."""

    ENABLED = 0x01  # the power stage drove the commanded current during this sample
    FAULT = 0x02  # a fault was latched at this sample; its current command is zero
    END = 0x04  # last sample of the stream (end of setpoints, fault, e-stop or disarm)


class Result(enum.IntEnum):
    """Result code of a REPLY."""

    OK = 0
    FAULT_LATCHED = 1
    NOT_CONFIGURED = 2
    INVALID_CONFIG = 3
    BAD_STATE = 4


def describe_faults(faults: int) -> str:
    """Human-readable list of fault bits, e.g. ``'OVER_CURRENT|WATCHDOG'`` (``'none'`` if zero)."""
    names = [f.name for f in Fault if faults & f]
    return "|".join(names) if names else "none"


class Message:
    """Base class: value semantics over ``__slots__`` (python-can style)."""

    __slots__ = ()
    TYPE: ClassVar[MsgType]

    def encode(self) -> bytes:
        return b""

    @classmethod
    def decode(cls, payload: bytes) -> Message:
        if payload:
            raise ProtocolError(f"{cls.TYPE.name}: expected an empty payload, got {len(payload)} bytes")
        return cls()

    def _values(self) -> tuple:
        return tuple(getattr(self, s) for s in self.__slots__)

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        for a, b in zip(self._values(), other._values(), strict=True):
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                if not np.array_equal(a, b):
                    return False
            elif a != b and not (isinstance(a, float) and math.isnan(a) and math.isnan(b)):
                return False
        return True

    __hash__ = None  # mutable value objects

    def __repr__(self) -> str:
        fields = ", ".join(f"{s}={getattr(self, s)!r}" for s in self.__slots__)
        return f"{type(self).__name__}({fields})"


def _unpack(st: struct.Struct, payload: bytes, name: str) -> tuple:
    if len(payload) != st.size:
        raise ProtocolError(f"{name}: expected {st.size} payload bytes, got {len(payload)}")
    return st.unpack(payload)


class EStop(Message):
    __slots__ = ()
    TYPE = MsgType.ESTOP


class Disarm(Message):
    __slots__ = ()
    TYPE = MsgType.DISARM


class Arm(Message):
    __slots__ = ()
    TYPE = MsgType.ARM


class ClearFaults(Message):
    __slots__ = ()
    TYPE = MsgType.CLEAR_FAULTS


class GetConfig(Message):
    __slots__ = ()
    TYPE = MsgType.GET_CONFIG


class GetIdentity(Message):
    """Who are you? A v2 host sends its protocol version (u16); a v1 host sends nothing (``host_version``
    1), and a v2 device then answers as a v1 device."""

    __slots__ = ("host_version",)
    TYPE = MsgType.GET_IDENTITY
    _ST = struct.Struct("<H")

    def __init__(self, host_version: int = PROTOCOL_VERSION) -> None:
        self.host_version = int(host_version)

    def encode(self) -> bytes:
        return self._ST.pack(self.host_version) if self.host_version >= 2 else b""

    @classmethod
    def decode(cls, payload: bytes) -> GetIdentity:
        return cls(1) if not payload else cls(*_unpack(cls._ST, payload, "GET_IDENTITY"))


class Identity(Message):
    """Who the device is: strings of at most 255 UTF-8 bytes, its buffer and block sizes (samples) and, from
    protocol v3, its :class:`Sensor` flags (one byte after the block size)."""

    __slots__ = ("model", "serial", "firmware", "protocol_version", "buffer_capacity", "max_block", "sensors")
    TYPE = MsgType.IDENTITY
    _TAIL = struct.Struct("<HIH")
    _TAIL_V3 = struct.Struct("<HIHB")

    def __init__(self, model: str, serial: str, firmware: str, protocol_version: int = PROTOCOL_VERSION,
                 buffer_capacity: int = 8192, max_block: int = 256, sensors: int = 0) -> None:
        self.model = model
        self.serial = serial
        self.firmware = firmware
        self.protocol_version = protocol_version
        self.buffer_capacity = buffer_capacity
        self.max_block = max_block
        self.sensors = Sensor(sensors)

    def encode(self) -> bytes:
        out = bytearray()
        for text in (self.model, self.serial, self.firmware):
            raw = text.encode("utf-8")
            if len(raw) > 255:
                raise ProtocolError("IDENTITY: strings are limited to 255 UTF-8 bytes")
            out += bytes([len(raw)]) + raw
        if self.protocol_version >= 3:
            return bytes(out) + self._TAIL_V3.pack(self.protocol_version, self.buffer_capacity, self.max_block,
                                                   int(self.sensors))
        return bytes(out) + self._TAIL.pack(self.protocol_version, self.buffer_capacity, self.max_block)

    @classmethod
    def decode(cls, payload: bytes) -> Identity:
        texts, pos = [], 0
        for _ in range(3):
            if pos >= len(payload):
                raise ProtocolError("IDENTITY: truncated")
            n = payload[pos]
            raw = payload[pos + 1: pos + 1 + n]
            if len(raw) != n:
                raise ProtocolError("IDENTITY: truncated string")
            try:
                texts.append(raw.decode("utf-8"))
            except UnicodeDecodeError as exc:
                raise ProtocolError("IDENTITY: string is not UTF-8") from exc
            pos += 1 + n
        tail = payload[pos:]
        if len(tail) == cls._TAIL_V3.size:
            version, capacity, block, sensors = _unpack(cls._TAIL_V3, tail, "IDENTITY")
            if version < 3 or sensors & ~int(Sensor.TEMPERATURE):
                raise ProtocolError(f"IDENTITY: a sensors byte (0x{sensors:02x}) from a protocol {version} device")
            return cls(*texts, version, capacity, block, sensors)
        return cls(*texts, *_unpack(cls._TAIL, tail, "IDENTITY"))


#: Position-loop defaults (protocol v2), tuned on the simulated DC motor (J 0.0022 kg*m^2, Kt 0.2 N*m/A,
#: presliding stiffness about 3000 N*m/rad) at 2**16 counts/rev: see docs/protocol.md, "Position mode".
POSITION_GAINS = {"position_kp": 3000.0, "position_ki": 300000.0, "position_kd": 5.0, "position_i_limit": 5.0,
                  "position_d_cutoff": 300.0}


class Config(Message):
    """Device configuration. Units at the encoder (motor) shaft: A, rad/s, rad, s.

    ``position_min``/``position_max`` may be infinite (window off); ``watchdog_timeout`` = 0 turns the
    watchdog off (it is on by default). Calibration (``torque_constant`` N*m/A, ``counts_per_rev``,
    ``ratio`` motor revolutions per load revolution) is stored by the device, used for its velocity and
    position checks, and used by the host to convert samples to load-side N*m and rad.

    Position mode (protocol v2): ``position_kp`` A/rad, ``position_ki`` A/(rad*s), ``position_kd`` A*s/rad,
    ``position_i_limit`` A (bound of the integral term), ``position_d_cutoff`` Hz (low-pass of the
    derivative, 0 = unfiltered), ``feedforward``: each sample's setpoint is (angle rad, current A).
    """

    __slots__ = ("sample_rate", "mode", "current_limit", "velocity_limit", "position_min", "position_max",
                 "watchdog_timeout", "torque_constant", "counts_per_rev", "ratio", "position_kp", "position_ki",
                 "position_kd", "position_i_limit", "position_d_cutoff", "feedforward")
    TYPE = MsgType.CONFIG
    _ST_V1 = struct.Struct("<IBdddddd I d")
    _ST = struct.Struct("<IBdddddd I d ddddd B")
    GAINS = ("position_kp", "position_ki", "position_kd", "position_i_limit", "position_d_cutoff")

    def __init__(self, sample_rate: int = 10000, mode: Mode | int = Mode.CURRENT, current_limit: float = 5.0,
                 velocity_limit: float = 200.0, position_min: float = -math.inf,
                 position_max: float = math.inf, watchdog_timeout: float = 0.5, torque_constant: float = 0.1,
                 counts_per_rev: int = 16384, ratio: float = 1.0,
                 position_kp: float = POSITION_GAINS["position_kp"],
                 position_ki: float = POSITION_GAINS["position_ki"],
                 position_kd: float = POSITION_GAINS["position_kd"],
                 position_i_limit: float = POSITION_GAINS["position_i_limit"],
                 position_d_cutoff: float = POSITION_GAINS["position_d_cutoff"],
                 feedforward: bool = False) -> None:
        self.sample_rate = int(sample_rate)
        self.mode = Mode(mode) if mode in (0, 1, 2) else mode
        self.current_limit = float(current_limit)
        self.velocity_limit = float(velocity_limit)
        self.position_min = float(position_min)
        self.position_max = float(position_max)
        self.watchdog_timeout = float(watchdog_timeout)
        self.torque_constant = float(torque_constant)
        self.counts_per_rev = int(counts_per_rev)
        self.ratio = float(ratio)
        self.position_kp = float(position_kp)
        self.position_ki = float(position_ki)
        self.position_kd = float(position_kd)
        self.position_i_limit = float(position_i_limit)
        self.position_d_cutoff = float(position_d_cutoff)
        self.feedforward = bool(feedforward)

    @property
    def values_per_sample(self) -> int:
        """Setpoint values per device sample: 2 (angle, feed-forward current) in position mode with
        feed-forward, else 1."""
        return 2 if self.mode == Mode.POSITION and self.feedforward else 1

    def problems(self) -> list[str]:
        """Everything wrong with this configuration, as one-line messages (empty list = valid)."""
        out = []
        if self.sample_rate not in SAMPLE_RATES:
            rates = ", ".join(map(str, SAMPLE_RATES))
            out.append(f"sample rate {self.sample_rate} Hz is not one of {rates} Hz")
        if self.mode not in (Mode.CURRENT, Mode.VELOCITY, Mode.POSITION):
            out.append(f"mode {self.mode!r} is not 0 (current), 1 (velocity) or 2 (position)")
        units = {"position_kp": "A/rad", "position_ki": "A/(rad*s)", "position_kd": "A*s/rad",
                 "position_i_limit": "A", "position_d_cutoff": "Hz"}
        for name, unit in units.items():
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                out.append(f"{name} must be finite and >= 0 {unit}, got {value}")
        if self.position_d_cutoff >= self.sample_rate / 2:
            out.append(f"position_d_cutoff {self.position_d_cutoff} Hz must be below Nyquist "
                       f"({self.sample_rate / 2} Hz)")
        if self.mode == Mode.POSITION and not self.position_kp > 0:
            out.append(f"position mode needs position_kp > 0 A/rad, got {self.position_kp}")
        if self.feedforward and self.mode != Mode.POSITION:
            out.append("feedforward is a position-mode option (mode 2)")
        for name in ("current_limit", "velocity_limit", "torque_constant", "ratio"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                out.append(f"{name} must be finite and > 0, got {value}")
        if math.isnan(self.position_min) or math.isnan(self.position_max) \
                or not self.position_min < self.position_max:
            out.append(f"position window [{self.position_min}, {self.position_max}] rad is empty or NaN")
        if not (math.isfinite(self.watchdog_timeout) and self.watchdog_timeout >= 0):
            out.append(f"watchdog_timeout must be >= 0 s (0 = off), got {self.watchdog_timeout}")
        if not 0 < self.counts_per_rev < 2**32:
            out.append(f"counts_per_rev must be in 1..2**32-1, got {self.counts_per_rev}")
        return out

    def encode(self, version: int = PROTOCOL_VERSION) -> bytes:
        """The v2 layout (106 bytes), or with ``version=1`` the v1 layout (65 bytes; no position mode)."""
        head = (self.sample_rate, int(self.mode), self.current_limit, self.velocity_limit, self.position_min,
                self.position_max, self.watchdog_timeout, self.torque_constant, self.counts_per_rev, self.ratio)
        try:
            if version == 1:
                if self.mode == Mode.POSITION or self.feedforward:
                    raise ProtocolError("CONFIG: protocol v1 has no position mode")
                return self._ST_V1.pack(*head)
            return self._ST.pack(*head, *(getattr(self, g) for g in self.GAINS), int(self.feedforward))
        except struct.error as exc:
            raise ProtocolError(f"CONFIG: cannot encode: {exc}") from exc

    @classmethod
    def decode(cls, payload: bytes) -> Config:
        """Either layout: a v1 CONFIG (65 bytes) has no position loop (gains 0, no feed-forward)."""
        if len(payload) == cls._ST_V1.size:
            return cls(*_unpack(cls._ST_V1, payload, "CONFIG"), **dict.fromkeys(cls.GAINS, 0.0))
        *head, flags = _unpack(cls._ST, payload, "CONFIG")
        if flags & ~1:
            raise ProtocolError(f"CONFIG: unknown flags 0x{flags:02x}")
        return cls(*head, feedforward=bool(flags & 1))


class Heartbeat(Message):
    """Host keep-alive; the device answers with a STATUS echoing ``token``."""

    __slots__ = ("token",)
    TYPE = MsgType.HEARTBEAT
    _ST = struct.Struct("<I")

    def __init__(self, token: int = 0) -> None:
        self.token = int(token)

    def encode(self) -> bytes:
        return self._ST.pack(self.token & 0xFFFFFFFF)

    @classmethod
    def decode(cls, payload: bytes) -> Heartbeat:
        return cls(*_unpack(cls._ST, payload, "HEARTBEAT"))


class Status(Message):
    """Device status and counters. ``index`` is the next device sample index; ``fault_index`` the sample at
    which the first latched fault tripped and ``fault_silence`` how many samples the host had been silent
    then (both 0 without fault); ``current_applied`` the current command of the last sample, A."""

    __slots__ = ("token", "state", "faults", "index", "free", "received", "fault_index", "fault_silence",
                 "current_applied", "crc_errors", "dropped_frames", "rx_frames", "tx_frames")
    TYPE = MsgType.STATUS
    _ST = struct.Struct("<IBHQIQQQfIIII")

    def __init__(self, token: int = 0, state: int = State.UNCONFIGURED, faults: int = 0, index: int = 0,
                 free: int = 0, received: int = 0, fault_index: int = 0, fault_silence: int = 0,
                 current_applied: float = 0.0, crc_errors: int = 0, dropped_frames: int = 0,
                 rx_frames: int = 0, tx_frames: int = 0) -> None:
        self.token = token
        self.state = state
        self.faults = faults
        self.index = index
        self.free = free
        self.received = received
        self.fault_index = fault_index
        self.fault_silence = fault_silence
        self.current_applied = current_applied
        self.crc_errors = crc_errors
        self.dropped_frames = dropped_frames
        self.rx_frames = rx_frames
        self.tx_frames = tx_frames

    def encode(self) -> bytes:
        return self._ST.pack(self.token & 0xFFFFFFFF, int(self.state), int(self.faults), self.index,
                             self.free, self.received, self.fault_index, self.fault_silence,
                             self.current_applied,
                             *(v & 0xFFFFFFFF for v in (self.crc_errors, self.dropped_frames,
                                                        self.rx_frames, self.tx_frames)))

    @classmethod
    def decode(cls, payload: bytes) -> Status:
        return cls(*_unpack(cls._ST, payload, "STATUS"))


class Reply(Message):
    """The device's answer to a command (CONFIG, ARM, DISARM, ESTOP, CLEAR_FAULTS)."""

    __slots__ = ("request", "result", "faults")
    TYPE = MsgType.REPLY
    _ST = struct.Struct("<BBH")

    def __init__(self, request: int, result: int = Result.OK, faults: int = 0) -> None:
        self.request = request
        self.result = result
        self.faults = faults

    def encode(self) -> bytes:
        return self._ST.pack(int(self.request), int(self.result), int(self.faults))

    @classmethod
    def decode(cls, payload: bytes) -> Reply:
        return cls(*_unpack(cls._ST, payload, "REPLY"))


class SetpointBlock(Message):
    """Setpoints for consecutive device samples: ``seq`` counts blocks from 0 after ARM (u32, wraps);
    ``end`` marks the last block of a stream. ``values`` are float32 on the wire (A, rad/s or rad); in
    position mode with feed-forward two per sample, interleaved (angle rad, current A)."""

    __slots__ = ("seq", "end", "values")
    TYPE = MsgType.SETPOINTS
    _ST = struct.Struct("<IB")

    def __init__(self, seq: int, values: np.ndarray, end: bool = False) -> None:
        self.seq = seq
        self.end = bool(end)
        self.values = np.asarray(values, dtype="<f4")

    def encode(self) -> bytes:
        return self._ST.pack(self.seq & 0xFFFFFFFF, 1 if self.end else 0) + self.values.tobytes()

    @classmethod
    def decode(cls, payload: bytes) -> SetpointBlock:
        head, body = payload[: cls._ST.size], payload[cls._ST.size:]
        seq, flags = _unpack(cls._ST, head, "SETPOINTS")
        if flags & ~1 or len(body) % 4:
            raise ProtocolError("SETPOINTS: bad flags or a body that is not whole float32 values")
        return cls(seq, np.frombuffer(body, dtype="<f4"), end=bool(flags & 1))


class SampleBlock(Message):
    """Consecutive device samples ``first_index .. first_index+n-1`` (struct of arrays on the wire).

    ``counts`` int32 encoder counts (wrap modulo 2**32, unwrap host-side), ``current_cmd`` and
    ``current_meas`` float32 A, ``status`` uint16 :class:`SampleStatus` bits. The header carries the
    device's flow-control state: ``free`` setpoint slots and ``received`` setpoints since ARM, and its
    latched ``faults`` and ``state`` after the block; from protocol v3 also ``temperature``, the winding
    temperature when the block was sent (float32 degC, NaN when the device has no sensor).
    """

    __slots__ = ("seq", "first_index", "free", "received", "faults", "state", "counts", "current_cmd",
                 "current_meas", "status", "temperature")
    TYPE = MsgType.SAMPLES
    _ST = struct.Struct("<IQIQHB")
    _TEMPERATURE = struct.Struct("<f")
    SAMPLE_BYTES = 14

    def __init__(self, seq: int, first_index: int, free: int, received: int, faults: int, state: int,
                 counts: np.ndarray, current_cmd: np.ndarray, current_meas: np.ndarray,
                 status: np.ndarray, temperature: float = math.nan) -> None:
        self.seq = seq
        self.first_index = first_index
        self.free = free
        self.received = received
        self.faults = faults
        self.state = state
        self.counts = np.asarray(counts).astype("<i4", copy=False)
        self.current_cmd = np.asarray(current_cmd, dtype="<f4")
        self.current_meas = np.asarray(current_meas, dtype="<f4")
        self.status = np.asarray(status, dtype="<u2")
        self.temperature = float(temperature)
        if not len(self.counts) == len(self.current_cmd) == len(self.current_meas) == len(self.status):
            raise ProtocolError("SAMPLES: arrays of different lengths")

    def __len__(self) -> int:
        return len(self.counts)

    def encode(self, version: int = PROTOCOL_VERSION) -> bytes:
        head = self._ST.pack(self.seq & 0xFFFFFFFF, self.first_index, self.free, self.received,
                             int(self.faults), int(self.state))
        if version >= 3:
            head += self._TEMPERATURE.pack(self.temperature)
        return b"".join((head, self.counts.tobytes(), self.current_cmd.tobytes(),
                         self.current_meas.tobytes(), self.status.tobytes()))

    @classmethod
    def header_bytes(cls, version: int) -> int:
        """Header size of a SAMPLES payload in protocol ``version``: 27 bytes, 31 from v3 (temperature)."""
        return cls._ST.size + (cls._TEMPERATURE.size if version >= 3 else 0)

    @classmethod
    def decode(cls, payload: bytes, version: int = PROTOCOL_VERSION) -> SampleBlock:
        """The header layout is the one of ``version``, the protocol agreed at connect, never guessed from the
        payload's length: a v3 block cut by 4 bytes would otherwise read as a v2 block with invented counts."""
        size = cls.header_bytes(version)
        if len(payload) < size or (len(payload) - size) % cls.SAMPLE_BYTES:
            raise ProtocolError(f"SAMPLES: {len(payload)} bytes are not a protocol {version} header of {size} "
                                f"bytes and whole samples of {cls.SAMPLE_BYTES}")
        fields = cls._ST.unpack_from(payload)
        temperature = cls._TEMPERATURE.unpack_from(payload, cls._ST.size)[0] if version >= 3 else math.nan
        body = payload[size:]
        n = len(body) // cls.SAMPLE_BYTES
        counts = np.frombuffer(body, "<i4", n, 0)
        cmd = np.frombuffer(body, "<f4", n, 4 * n)
        meas = np.frombuffer(body, "<f4", n, 8 * n)
        status = np.frombuffer(body, "<u2", n, 12 * n)
        return cls(*fields, counts, cmd, meas, status, temperature)


MESSAGE_CLASSES: dict[int, type[Message]] = {
    cls.TYPE: cls for cls in (EStop, Disarm, Arm, ClearFaults, Config, GetConfig, GetIdentity, Identity,
                              Heartbeat, Status, Reply, SetpointBlock, SampleBlock)
}


def encode_message(msg: Message) -> tuple[int, bytes]:
    """``(type byte, payload)`` of a message."""
    return int(msg.TYPE), msg.encode()


def decode_message(msg_type: int, payload: bytes, version: int = PROTOCOL_VERSION) -> Message:
    """Message from its type byte and payload in protocol ``version`` (the one agreed at connect; it sets
    the SAMPLES header layout); raises :class:`ProtocolError` for anything invalid, and nothing else."""
    cls = MESSAGE_CLASSES.get(msg_type)
    if cls is None:
        raise ProtocolError(f"unknown message type 0x{msg_type:02x}")
    if cls is SampleBlock:
        return SampleBlock.decode(bytes(payload), version)
    return cls.decode(bytes(payload))


def make_setpoint_blocks(values: np.ndarray, block: int) -> list[SetpointBlock]:
    """Split setpoints into blocks of at most ``block`` samples, seq 0.., the last one ``end``. ``values``
    is (n,) or, with several values per sample, (n, m): each block carries its rows flattened (interleaved)."""
    values = np.asarray(values, dtype="<f4")
    n = len(values)
    starts = range(0, max(n, 1), block)
    return [SetpointBlock(i, values[s: s + block].reshape(-1), end=(s + block >= n)) for i, s in enumerate(starts)]
