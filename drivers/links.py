"""Links carry protocol messages: ``send(msg)`` and ``recv(timeout) -> Message | None`` (None on timeout).

:class:`SerialLink` frames with COBS+CRC over any pyserial port or URL (``/dev/ttyUSB0``, ``loop://``,
``socket://host:port``, ``rfc2217://...``), opened exclusively. :class:`CanLink` maps messages onto CAN frames over any
python-can interface (socketcan, pcan, kvaser, vector, virtual...). A link is used by one receiving thread;
``send`` may be called from several threads if the caller serialises it (the Amplifier holds a lock).
"""

from __future__ import annotations

import select
import time
from collections import deque
from typing import Protocol

import serial

from hilbench.common.can import enlarge_receive_buffer
from hilbench.drivers import protocol as p
from hilbench.drivers.errors import LinkClosedError, PortBusyError


class Link(Protocol):
    def send(self, msg: p.Message) -> None: ...

    def recv(self, timeout: float | None) -> p.Message | None: ...

    def close(self) -> None: ...

    @property
    def counters(self) -> dict[str, int]: ...

    #: The protocol agreed at connect: the decoder reads payload layouts by it (set by the Amplifier).
    protocol_version: int


class _Decoding:
    """What a link tells of its decoder (``_decoder``: a FrameDecoder or a CanReassembler)."""

    _decoder: p.FrameDecoder | p.CanReassembler

    @property
    def protocol_version(self) -> int:
        """The protocol agreed at connect, in which the decoder reads payload layouts."""
        return self._decoder.version

    @protocol_version.setter
    def protocol_version(self, version: int) -> None:
        self._decoder.version = version

    @property
    def last_error(self) -> str:
        """Why the last malformed frame or message was dropped ('' if none was)."""
        return self._decoder.last_error


class SerialLink(_Decoding):
    """Protocol link over a pyserial port.

    Args:
        url: device path or pyserial URL; ignored when ``port`` is given.
        baudrate: line rate, baud (ignored by ptys and sockets).
        port: an already open pyserial-like object (``read``, ``write``, ``in_waiting``; e.g. a
            :class:`drivers.fault_injection.FaultyPort`).
    """

    def __init__(self, url: str = "", baudrate: int = 2_000_000, *, port=None) -> None:
        if port is None:
            try:
                # exclusive: one owner per device port; a second program is refused here, before it could
                # send anything (closing an Amplifier disarms, which would end the owner's run)
                port = serial.serial_for_url(url, baudrate=baudrate, timeout=0, write_timeout=5.0,
                                             exclusive=True)
            except (serial.SerialException, ValueError) as exc:
                if "exclusively lock" in str(exc):
                    raise PortBusyError(f"serial port {url!r} is in use by another program (one owner per "
                                        f"device port); stop it first") from None
                raise LinkClosedError(f"cannot open serial port {url!r}: {exc}") from exc
        self._port = port
        self._decoder = p.FrameDecoder()
        self._pending: deque[p.Message] = deque()
        self.frames_tx = 0
        try:
            self._fd = port.fileno()
        except (AttributeError, OSError, serial.SerialException, NotImplementedError):
            self._fd = None
        try:
            port.timeout = 0 if self._fd is not None else 0.005
            port.reset_input_buffer()  # drop stale bytes a previous host left unread
            port.write(b"\x00")  # terminate any partial frame on the device side
        except (serial.SerialException, OSError) as exc:
            raise LinkClosedError(f"serial port {url!r}: {exc}") from exc

    def send(self, msg: p.Message) -> None:
        data = p.encode_frame(msg)
        try:
            self._port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise LinkClosedError(f"serial link closed while sending: {exc}") from exc
        self.frames_tx += 1

    def recv(self, timeout: float | None) -> p.Message | None:
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self._pending:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                if self._fd is not None:
                    ready, _, _ = select.select([self._fd], [], [], remaining)
                    if not ready:
                        return None
                    chunk = self._port.read(max(1, self._port.in_waiting))
                else:
                    chunk = self._port.read(max(1, self._port.in_waiting))
            except (serial.SerialException, OSError, ValueError, TypeError) as exc:
                raise LinkClosedError(f"serial link closed: {exc}") from exc
            if chunk:
                self._pending.extend(self._decoder.feed(chunk))
            elif deadline is not None and time.monotonic() >= deadline:
                return None
        return self._pending.popleft()

    def close(self) -> None:
        try:
            self._port.close()
        except (serial.SerialException, OSError):
            pass

    @property
    def counters(self) -> dict[str, int]:
        return {"frames_rx": self._decoder.frames, "frames_tx": self.frames_tx,
                "crc_errors": self._decoder.crc_errors, "dropped_frames": 0}


class CanLink(_Decoding):
    """Protocol link over a python-can bus, talking to device ``node`` (1..15).

    Args:
        interface, channel: python-can interface name and channel (``virtual``/``bench0``,
            ``socketcan``/``can0``...); ignored when ``bus`` is given.
        node: device node id.
        fd: use CAN FD frames (64 bytes) instead of classic 8-byte frames.
        bus: an open ``can.BusABC`` to use instead.
        bus_kwargs: passed to ``can.Bus`` (e.g. ``bitrate``).
    """

    def __init__(self, interface: str = "virtual", channel: str = "bench0", node: int = 1, fd: bool = False,
                 *, bus=None, **bus_kwargs) -> None:
        import can

        self._can = can
        p.can_id(0, 0, node)  # validates the node id
        self.node = node
        self.fd = fd
        if bus is None:
            try:
                bus = can.Bus(interface=interface, channel=channel, fd=fd, **bus_kwargs)
            except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
                raise LinkClosedError(f"cannot open CAN {interface}:{channel}: {exc}") from exc
            enlarge_receive_buffer(bus)
        self._bus = bus
        try:
            bus.set_filters([{"can_id": p.DEVICE_TO_HOST << 4 | node, "can_mask": 0x1F, "extended": False}])
        except (can.CanError, NotImplementedError):
            pass  # the reassembler filters anyway
        self._decoder = p.CanReassembler(p.DEVICE_TO_HOST, node)
        self.frames_tx = 0

    def send(self, msg: p.Message) -> None:
        for arb, data in p.encode_can(msg, p.HOST_TO_DEVICE, self.node, self.fd):
            frame = self._can.Message(arbitration_id=arb, data=data, is_extended_id=False, is_fd=self.fd,
                                      bitrate_switch=self.fd)
            try:
                self._bus.send(frame, timeout=1.0)
            except (self._can.CanError, OSError) as exc:
                raise LinkClosedError(f"CAN send failed: {exc}") from exc
        self.frames_tx += 1

    def recv(self, timeout: float | None) -> p.Message | None:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                frame = self._bus.recv(remaining)
            except (self._can.CanError, OSError) as exc:
                raise LinkClosedError(f"CAN receive failed: {exc}") from exc
            if frame is None:
                return None
            if frame.is_error_frame or frame.is_remote_frame:
                continue
            msg = self._decoder.feed(frame.arbitration_id, bytes(frame.data))
            if msg is not None:
                return msg
            if deadline is not None and time.monotonic() >= deadline:
                return None

    def close(self) -> None:
        try:
            self._bus.shutdown()
        except (self._can.CanError, OSError):
            pass

    @property
    def counters(self) -> dict[str, int]:
        r = self._decoder
        return {"frames_rx": r.frames, "frames_tx": self.frames_tx, "crc_errors": r.errors,
                "dropped_frames": r.dropped_frames}
