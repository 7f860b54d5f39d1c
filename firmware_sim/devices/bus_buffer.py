"""The simulated devices' end of a socket-based CAN bus asks for a large receive buffer.

A simulated drive reads its bus from a Python thread. While this process is descheduled, the host's frames
wait in the kernel socket, and what overflows its default buffer (208 KiB here, about 50 ms of a 1 kHz
CiA 402 cycle) is lost: a SYNC missed is a sample missed. The host's end makes the same request in
``drivers/can_buffer.py``. Each end owns its socket, and a simulated device shares only protocol
definitions with ``drivers`` (docs/architecture.md), so the few lines are kept on both sides.
"""

from __future__ import annotations

import os
import socket

DEVICE_RECEIVE_BUFFER = 8 << 20  # bytes


def widen_device_buffer(bus: object) -> int:
    """Request ``DEVICE_RECEIVE_BUFFER`` bytes for ``bus``'s socket (SO_RCVBUFFORCE where privileged, else
    SO_RCVBUF, capped by net.core.rmem_max); the kernel's reported size, or 0 when the bus has no socket."""
    try:
        fd = bus.fileno()  # type: ignore[attr-defined]
    except (AttributeError, NotImplementedError):
        fd = -1
    if not isinstance(fd, int) or fd < 0:
        return 0
    sock = socket.socket(fileno=os.dup(fd))
    try:
        try:
            sock.setsockopt(socket.SOL_SOCKET, getattr(socket, "SO_RCVBUFFORCE", 33), DEVICE_RECEIVE_BUFFER)
        except OSError:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, DEVICE_RECEIVE_BUFFER)
        return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    finally:
        sock.close()
