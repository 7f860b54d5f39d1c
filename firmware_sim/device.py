"""The simulated amplifier as a process: transports (pseudo-terminal, python-can bus) and the serve loop.

The serve loop waits for host frames until the next tick, hands them to :class:`Firmware`, then lets the
firmware compute the samples due and sends everything it returns. Nothing of the simulator configuration
is written anywhere but the wire protocol's own messages.
"""

from __future__ import annotations

import errno
import os
import select
import threading
import time
import tty

from hilbench.drivers import protocol as p
from hilbench.firmware_sim.firmware import Firmware

TX_BUFFER_LIMIT = 1 << 18  # bytes queued towards a host that does not read; beyond it frames are dropped


class PtyTransport:
    """Serves the protocol on the master side of a new pseudo-terminal; hosts open :attr:`path`.

    The device keeps a slave descriptor open itself, so a host may disconnect and reconnect without the
    master seeing a hang-up; frames that a disconnected host cannot take are dropped (counted). A new
    host starts with GET_IDENTITY: the frames still queued for the previous one are then discarded.
    """

    max_block = 512

    def __init__(self) -> None:
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self._slave)
        self._decoder = p.FrameDecoder()
        self._tx = bytearray()
        self._tx_starts: list[int] = []  # offsets of the frames queued in _tx
        self.dropped_frames = 0
        self.frames_tx = 0

    def poll(self, timeout: float) -> list[p.Message]:
        wlist = [self.master] if self._tx else []
        readable, writable, _ = select.select([self.master], wlist, [], max(0.0, timeout))
        if writable:
            self._flush()
        if not readable:
            return []
        chunks = []
        while True:
            try:
                chunk = os.read(self.master, 1 << 16)
            except BlockingIOError:
                break
            except OSError as exc:
                if exc.errno == errno.EIO:  # no host end open (cannot happen while we hold the slave)
                    time.sleep(0.01)
                    break
                raise
            if not chunk:
                break
            chunks.append(chunk)
        msgs = self._decoder.feed(b"".join(chunks)) if chunks else []
        if any(m.TYPE == p.MsgType.GET_IDENTITY for m in msgs):
            self._discard_backlog()
        return msgs

    def _discard_backlog(self) -> None:
        """Drop the queued frames that have not started to go out (a partly written one is finished)."""
        if len(self._tx_starts) > 1:
            self.dropped_frames += len(self._tx_starts) - 1
            del self._tx[self._tx_starts[1]:]
            del self._tx_starts[1:]

    def send(self, msgs: list[p.Message]) -> None:
        for msg in msgs:
            if len(self._tx) > TX_BUFFER_LIMIT:
                self.dropped_frames += 1
                continue
            self._tx_starts.append(len(self._tx))
            self._tx += p.encode_frame(msg)
            self.frames_tx += 1
        self._flush()

    def _flush(self) -> None:
        while self._tx:
            try:
                n = os.write(self.master, self._tx)
            except BlockingIOError:
                return
            del self._tx[:n]
            self._tx_starts = [s - n for s in self._tx_starts if s - n > 0] or ([0] if self._tx else [])
            if self._tx and self._tx_starts[0] != 0:
                self._tx_starts.insert(0, 0)  # the partly written frame

    @property
    def crc_errors(self) -> int:
        return self._decoder.crc_errors

    def close(self) -> None:
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


class CanTransport:
    """Serves the protocol as CAN node ``node`` on a python-can bus (classic frames, or CAN FD)."""

    def __init__(self, bus, node: int = 1, fd: bool = False) -> None:
        import can

        self._can = can
        self.bus = bus
        self.node = node
        self.fd = fd
        self.max_block = 512 if fd else 60
        self._reassembler = p.CanReassembler(p.HOST_TO_DEVICE, node)
        self.frames_tx = 0
        self.dropped_frames_tx = 0

    def poll(self, timeout: float) -> list[p.Message]:
        out = []
        frame = self.bus.recv(max(0.0, timeout))
        while frame is not None:
            if not (frame.is_error_frame or frame.is_remote_frame):
                msg = self._reassembler.feed(frame.arbitration_id, bytes(frame.data))
                if msg is not None:
                    out.append(msg)
            frame = self.bus.recv(0.0)
        return out

    def send(self, msgs: list[p.Message]) -> None:
        for msg in msgs:
            try:
                for arb, data in p.encode_can(msg, p.DEVICE_TO_HOST, self.node, self.fd):
                    self.bus.send(self._can.Message(arbitration_id=arb, data=data, is_extended_id=False,
                                                    is_fd=self.fd, bitrate_switch=self.fd), timeout=0.1)
                self.frames_tx += 1
            except self._can.CanError:
                self.dropped_frames_tx += 1

    @property
    def crc_errors(self) -> int:
        return self._reassembler.errors

    @property
    def dropped_frames(self) -> int:
        return self._reassembler.dropped_frames + self.dropped_frames_tx

    def close(self) -> None:
        self.bus.shutdown()


def serve(transport, firmware: Firmware, tick: float = 0.004, stop: threading.Event | None = None) -> None:
    """Run the device until ``stop`` is set (forever when None).

    ``tick`` (s) is the realtime loop period: the samples due are computed in blocks every tick. In
    lockstep the loop only waits when there is nothing buffered to compute.
    """
    next_tick = time.monotonic()
    base_dropped = 0
    while stop is None or not stop.is_set():
        now = time.monotonic()
        if firmware.pacing == "realtime":
            timeout = next_tick - now
        else:
            timeout = 0.0 if firmware.busy else 0.01
        for msg in transport.poll(timeout):
            transport.send(firmware.handle(msg, time.monotonic()))
        now = time.monotonic()
        if firmware.pacing == "lockstep" or now >= next_tick:
            transport.send(firmware.advance(now))
            next_tick = max(next_tick + tick, now)
        c = firmware.counters
        c["crc_errors"] = transport.crc_errors
        c["tx_frames"] = transport.frames_tx
        dropped = transport.dropped_frames
        c["dropped_frames"] += dropped - base_dropped
        base_dropped = dropped
