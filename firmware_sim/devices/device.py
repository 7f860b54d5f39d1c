"""The simulated amplifier as a process: transports (pseudo-terminal, python-can bus) and the serve loop of
the firmware core (:class:`firmware_sim.devices.core_c.CoreDevice`).

The transports carry the core's bytes and CAN frames unparsed: COBS, CRC, codec and CAN segmentation are the
C core's, as on a board. The serve loop waits for host bytes until the next tick, hands them to the core, lets
it compute the samples due and writes what it produced. Nothing of the simulator configuration is written
anywhere but the wire protocol's own messages.
"""

from __future__ import annotations

import errno
import os
import select
import threading
import time
import tty

from hilbench.firmware_sim.devices.core_c import CoreDevice

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
        self._tx = bytearray()
        self._tx_starts: list[int] = []  # offsets of the frames queued in _tx
        self.dropped_frames = 0
        self.frames_tx = 0

    def exchange(self, device: CoreDevice, timeout: float) -> None:
        """Wait up to ``timeout`` s for host bytes and hand them to the device."""
        wlist = [self.master] if self._tx else []
        readable, writable, _ = select.select([self.master], wlist, [], max(0.0, timeout))
        if writable:
            self._flush()
        if not readable:
            return
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
        if chunks:
            before = device.identity_requests
            device.rx_bytes(b"".join(chunks), time.monotonic())
            if device.identity_requests != before:  # a new host: drop what the previous one left unread
                self._discard_backlog()

    def _discard_backlog(self) -> None:
        """Drop the queued frames that have not started to go out (a partly written one is finished)."""
        if len(self._tx_starts) > 1:
            self.dropped_frames += len(self._tx_starts) - 1
            del self._tx[self._tx_starts[1]:]
            del self._tx_starts[1:]

    def deliver(self, device: CoreDevice) -> None:
        """Queue the device's output frames (0x00-delimited) and write what the pty takes."""
        out = device.take_bytes()
        start = 0
        while start < len(out):
            end = out.index(0, start) + 1
            if len(self._tx) > TX_BUFFER_LIMIT:
                self.dropped_frames += 1
            else:
                self._tx_starts.append(len(self._tx))
                self._tx += out[start:end]
                self.frames_tx += 1
            start = end
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

    def close(self) -> None:
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


class CanTransport:
    """Serves the protocol as CAN node ``node`` on a python-can bus (classic frames, or CAN FD); the core
    segments and reassembles."""

    def __init__(self, bus, node: int = 1, fd: bool = False) -> None:
        import can

        self._can = can
        self.bus = bus
        self.node = node
        self.fd = fd
        self.max_block = 512 if fd else 60
        self.frames_tx = 0
        self.dropped_frames = 0

    def exchange(self, device: CoreDevice, timeout: float) -> None:
        frame = self.bus.recv(max(0.0, timeout))
        while frame is not None:
            if not (frame.is_error_frame or frame.is_remote_frame):
                device.rx_can(frame.arbitration_id, bytes(frame.data), time.monotonic())
            frame = self.bus.recv(0.0)

    def deliver(self, device: CoreDevice) -> None:
        for arb, data in device.take_can():
            try:
                self.bus.send(self._can.Message(arbitration_id=arb, data=data, is_extended_id=False,
                                                is_fd=self.fd, bitrate_switch=self.fd), timeout=0.1)
                self.frames_tx += 1
            except self._can.CanError:
                self.dropped_frames += 1

    def close(self) -> None:
        self.bus.shutdown()


def serve(transport: PtyTransport | CanTransport, device: CoreDevice, tick: float = 0.004,
          stop: threading.Event | None = None) -> None:
    """Run the device until ``stop`` is set (forever when None).

    ``tick`` (s) is the realtime loop period; in lockstep the loop waits only when nothing is buffered.
    The core checks its watchdog on every pass, whatever the pacing and the buffer hold.
    """
    next_tick = time.monotonic()
    reported = 0
    while stop is None or not stop.is_set():
        now = time.monotonic()
        if device.pacing == "realtime":
            timeout = next_tick - now
        else:
            timeout = 0.0 if device.busy else 0.01
        transport.exchange(device, timeout)
        now = time.monotonic()
        if device.pacing == "lockstep" or now >= next_tick:
            # A real device hears the host in an interrupt; this process may have been descheduled since
            # it last read. Whatever the host sent before `now` is read before the watchdog is judged at `now`.
            transport.exchange(device, 0.0)
            device.tick(now)
            next_tick = max(next_tick + tick, now)
        transport.deliver(device)
        dropped = transport.dropped_frames
        device.count_dropped(dropped - reported)
        reported = dropped
