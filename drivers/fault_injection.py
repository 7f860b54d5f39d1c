"""A pyserial-port wrapper that damages bytes on purpose, to test CRC rejection and resynchronisation.

Wrap a port and hand it to :class:`drivers.links.SerialLink`::

    link = SerialLink(port=FaultyPort(serial.serial_for_url(path), p_write=0.1, seed=3))

Each ``write`` call (one frame) is damaged with probability ``p_write`` and each ``read`` call with
probability ``p_read``, by one of: drop a byte, flip bits of a byte, insert a byte. With
``keep_delimiters`` the damage never creates, removes or moves a 0x00, so every damaged write spoils
exactly one frame. ``damaged_writes`` / ``damaged_reads`` count what was done.

``inject``: whole frames (with their 0x00) slipped into what ``read`` returns, each with probability
``p_inject`` per read that holds a delimiter, right after the last one, so the frames around them stay intact:
CRC-valid frames that a decoder must refuse (a payload of the wrong length, a v3 block cut short) are sent "by
the device". ``injected`` counts them.
"""

from __future__ import annotations

import random
from collections.abc import Sequence


class FaultyPort:
    def __init__(self, port, p_write: float = 0.0, p_read: float = 0.0, seed: int = 0,
                 keep_delimiters: bool = False, inject: Sequence[bytes] = (), p_inject: float = 0.0) -> None:
        self._port = port
        self.inject = list(inject)
        self.p_inject = p_inject
        self.injected = 0
        self.p_write = p_write
        self.p_read = p_read
        self.keep_delimiters = keep_delimiters
        self._rng = random.Random(seed)
        self.damaged_writes = 0
        self.damaged_reads = 0
        self.log: list[str] = []

    def damage(self, data: bytes) -> bytes:
        """``data`` with one byte dropped, flipped or inserted (at least one byte long)."""
        rng = self._rng
        buf = bytearray(data)
        candidates = [i for i, b in enumerate(buf) if b != 0 or not self.keep_delimiters]
        kind = rng.choice(("drop", "flip", "insert")) if candidates else "insert"
        if kind == "insert":
            # with keep_delimiters insert before an existing byte: never after the frame's final 0x00
            pos = rng.randrange(len(buf)) if self.keep_delimiters and buf else rng.randrange(len(buf) + 1)
            value = rng.randrange(1, 256) if self.keep_delimiters else rng.randrange(256)
            buf.insert(pos, value)
        else:
            pos = rng.choice(candidates)
            if kind == "drop":
                del buf[pos]
            else:
                mask = rng.randrange(1, 256)
                while self.keep_delimiters and buf[pos] ^ mask == 0:
                    mask = rng.randrange(1, 256)
                buf[pos] ^= mask
        self.log.append(f"{kind}@{pos}")
        return bytes(buf)

    def write(self, data: bytes) -> int | None:
        if data and self.p_write and self._rng.random() < self.p_write:
            self.damaged_writes += 1
            data = self.damage(data)
        return self._port.write(data)

    def read(self, size: int = 1) -> bytes:
        data = self._port.read(size)
        if data and self.p_read and self._rng.random() < self.p_read:
            self.damaged_reads += 1
            data = self.damage(data)
        boundary = data.rfind(b"\x00") + 1  # after the last delimiter read: between two frames
        if self.inject and boundary and self._rng.random() < self.p_inject:
            data = data[:boundary] + self.inject[self.injected % len(self.inject)] + data[boundary:]
            self.injected += 1
        return data

    def __getattr__(self, name):  # in_waiting, fileno, timeout, reset_input_buffer, close ...
        return getattr(self._port, name)

    def __setattr__(self, name, value):
        if name == "timeout":
            self._port.timeout = value
        else:
            super().__setattr__(name, value)
