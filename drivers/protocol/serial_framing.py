"""Serial framing: ``COBS(version | type | payload | crc32) 0x00``.

The CRC is ``zlib.crc32`` (IEEE 802.3) over version, type and payload, little-endian. COBS removes every
0x00 from the frame body, so 0x00 only ever delimits frames and a decoder resynchronises at the next one.
"""

from __future__ import annotations

import struct
import zlib

from cobs import cobs

from hilbench.drivers.errors import ProtocolError
from hilbench.drivers.protocol.messages import (
    FRAME_VERSIONS,
    PROTOCOL_VERSION,
    Config,
    GetIdentity,
    Message,
    SampleBlock,
    decode_message,
)

MAX_FRAME_BYTES = 8192  # decoded frame size limit (header + payload + CRC)
_CRC = struct.Struct("<I")


def encode_frame(msg: Message, version: int | None = None) -> bytes:
    """The bytes to write for ``msg``: COBS-encoded frame followed by the 0x00 delimiter. ``version`` is
    the frame's version byte (1 for a v1 peer, with the v1 CONFIG layout); by default PROTOCOL_VERSION,
    except a GET_IDENTITY probing an older device (host version 1 or 2), which goes out in a frame of that
    version so that such a device reads it."""
    if version is None:
        probe = isinstance(msg, GetIdentity) and msg.host_version < PROTOCOL_VERSION
        version = max(1, msg.host_version) if probe else PROTOCOL_VERSION
    payload = msg.encode(version) if isinstance(msg, Config | SampleBlock) else msg.encode()
    raw = bytes((version, int(msg.TYPE))) + payload
    if len(raw) + 4 > MAX_FRAME_BYTES:
        raise ProtocolError(f"{msg.TYPE.name}: frame of {len(raw) + 4} bytes exceeds {MAX_FRAME_BYTES}")
    return cobs.encode(raw + _CRC.pack(zlib.crc32(raw))) + b"\x00"


def decode_frame(data: bytes, version: int | None = None) -> Message:
    """Message from one COBS-encoded frame without its delimiter. ``version`` is the protocol agreed at
    connect, which sets the payload layouts (None: the frame's own version byte, for golden frames and
    probes). Raises only :class:`ProtocolError`."""
    try:
        raw = cobs.decode(bytes(data))
    except cobs.DecodeError as exc:
        raise ProtocolError(f"bad COBS encoding: {exc}") from exc
    if len(raw) < 6:
        raise ProtocolError(f"frame of {len(raw)} bytes is shorter than header + CRC")
    body, (crc,) = raw[:-4], _CRC.unpack(raw[-4:])
    if zlib.crc32(body) != crc:
        raise ProtocolError("CRC mismatch")
    if body[0] not in FRAME_VERSIONS:
        raise ProtocolError(f"protocol version {body[0]} (this host reads {FRAME_VERSIONS})")
    return decode_message(body[1], body[2:], body[0] if version is None else version)


class FrameDecoder:
    """Streaming decoder: :meth:`feed` arbitrary byte chunks, get the complete messages back.

    Bad frames never raise; they are counted (``crc_errors`` counts every rejected frame: bad COBS, CRC,
    version, payload or oversize) and skipped, and decoding resumes after the next 0x00. ``version`` is the
    protocol agreed at connect (the link sets it once the device has answered GET_IDENTITY); it, not a
    payload's length, sets the SAMPLES header layout.
    """

    def __init__(self, max_frame: int = MAX_FRAME_BYTES, version: int = PROTOCOL_VERSION) -> None:
        self.version = version
        self._buf = bytearray()
        self._max_encoded = max_frame + max_frame // 254 + 2
        self._discarding = False  # inside an oversize frame: drop bytes until the next delimiter
        self.frames = 0
        self.crc_errors = 0
        self.last_error = ""

    def feed(self, chunk: bytes) -> list[Message]:
        """Append ``chunk`` and return the messages of every frame it completes (possibly none)."""
        out: list[Message] = []
        buf = self._buf
        buf += chunk
        start = 0
        while True:
            end = buf.find(0, start)
            if end < 0:
                break
            frame = buf[start:end]
            start = end + 1
            if self._discarding:
                self._discarding = False
                continue
            if not frame:
                continue  # empty frame: line idle / sender resync
            try:
                msg = decode_frame(frame, self.version)
            except ProtocolError as exc:
                self.crc_errors += 1
                self.last_error = str(exc)
                continue
            self.frames += 1
            out.append(msg)
        del buf[:start]
        if len(buf) > self._max_encoded:
            buf.clear()
            self._discarding = True
            self.crc_errors += 1
            self.last_error = "oversize frame"
        return out
