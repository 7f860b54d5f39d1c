"""CAN mapping: 11-bit identifier ``type << 5 | direction << 4 | node`` and segmented payloads.

The message type is in the top bits, so an e-stop (type 1) wins arbitration over everything. ``node`` is
1..15; ``direction`` 0 = host to device, 1 = device to host. A message payload is cut into segments of at
most 7 (classic CAN, 8-byte frames) or 63 (CAN FD, 64-byte frames) bytes, each prefixed by one byte
``last << 7 | index`` (index 0..127). Segment 0 starts with the payload length (u16 LE), so CAN FD padding
is removed exactly. CAN has its own CRC; a lost or reordered segment drops the message (counted).
"""

from __future__ import annotations

import struct

from hilbench.common.can import pad_fd
from hilbench.drivers.errors import ProtocolError
from hilbench.drivers.protocol.messages import PROTOCOL_VERSION, Message, MsgType, decode_message

HOST_TO_DEVICE = 0
DEVICE_TO_HOST = 1
_LEN = struct.Struct("<H")


def can_id(msg_type: int, direction: int, node: int) -> int:
    """11-bit arbitration id of a message type sent in ``direction`` to/from ``node`` (1..15)."""
    if not 1 <= node <= 15:
        raise ProtocolError(f"CAN node id must be 1..15, got {node}")
    return (int(msg_type) & 0x3F) << 5 | (direction & 1) << 4 | node


def split_can_id(arbitration_id: int) -> tuple[int, int, int]:
    """``(type, direction, node)`` of an 11-bit id."""
    return (arbitration_id >> 5) & 0x3F, (arbitration_id >> 4) & 1, arbitration_id & 0x0F


def max_payload(fd: bool) -> int:
    """Largest message payload, bytes, that fits 128 segments."""
    return 128 * (63 if fd else 7) - _LEN.size


def encode_can(msg: Message, direction: int, node: int, fd: bool = False) -> list[tuple[int, bytes]]:
    """``(arbitration_id, data)`` frames carrying ``msg``; data is at most 8 (classic) or 64 (FD) bytes."""
    payload = msg.encode()
    if len(payload) > max_payload(fd):
        raise ProtocolError(
            f"{msg.TYPE.name}: payload of {len(payload)} bytes exceeds {max_payload(fd)} on CAN")
    arb = can_id(msg.TYPE, direction, node)
    body = _LEN.pack(len(payload)) + payload
    seg = 63 if fd else 7
    chunks = [body[i: i + seg] for i in range(0, len(body), seg)]
    frames = []
    for i, chunk in enumerate(chunks):
        data = bytes(((0x80 if i == len(chunks) - 1 else 0) | i,)) + chunk
        if fd:
            data = pad_fd(data, 0)
        frames.append((arb, data))
    return frames


class CanReassembler:
    """Collects segments per (type, direction, node) and returns complete messages.

    Only frames for ``direction`` and ``node`` are considered (others are ignored, not counted).
    ``dropped_frames`` counts messages lost to missing or out-of-order segments; ``errors`` counts
    complete payloads that did not decode. Never raises. ``version`` is the protocol agreed at connect (the
    link sets it); it sets the SAMPLES header layout.
    """

    def __init__(self, direction: int, node: int, version: int = PROTOCOL_VERSION) -> None:
        self.version = version
        self.direction = direction
        self.node = node
        self._partial: dict[int, tuple[int, int, bytearray]] = {}  # type -> (next index, length, data)
        self._broken: set[int] = set()  # types whose current message lost a segment (already counted)
        self.frames = 0
        self.dropped_frames = 0
        self.errors = 0
        self.last_error = ""

    def feed(self, arbitration_id: int, data: bytes) -> Message | None:
        msg_type, direction, node = split_can_id(arbitration_id)
        if direction != self.direction or node != self.node or not data:
            return None
        head, chunk = data[0], bytes(data[1:])
        index, last = head & 0x7F, bool(head & 0x80)
        if index == 0:
            self._broken.discard(msg_type)
            if msg_type in self._partial:
                self.dropped_frames += 1  # a new message started before the previous one ended
            if len(chunk) < _LEN.size:
                self._fail(f"type 0x{msg_type:02x}: first segment too short")
                return None
            (length,) = _LEN.unpack(chunk[: _LEN.size])
            entry = (1, length, bytearray(chunk[_LEN.size:]))
        else:
            prev = self._partial.pop(msg_type, None)
            if prev is None or prev[0] != index:
                if msg_type not in self._broken:
                    self.dropped_frames += 1
                    self._broken.add(msg_type)
                return None
            entry = (index + 1, prev[1], prev[2] + chunk)
        if not last:
            self._partial[msg_type] = entry
            return None
        self._partial.pop(msg_type, None)
        _, length, payload = entry
        if len(payload) < length:
            self._fail(f"type 0x{msg_type:02x}: payload shorter than its length field")
            return None
        try:
            msg = decode_message(msg_type, bytes(payload[:length]), self.version)
        except ProtocolError as exc:
            self._fail(str(exc))
            return None
        self.frames += 1
        return msg

    def _fail(self, why: str) -> None:
        self.errors += 1
        self.last_error = why


__all__ = ["HOST_TO_DEVICE", "DEVICE_TO_HOST", "can_id", "split_can_id", "encode_can", "CanReassembler",
           "max_payload", "MsgType"]
