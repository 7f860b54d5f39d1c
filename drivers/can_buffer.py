"""A socket receive buffer that rides out a stalled process on a socket-based CAN bus.

python-can's ``udp_multicast`` and ``socketcan`` buses read a kernel socket. Its default receive buffer
(``net.core.rmem_default``, 208 KiB here) holds about 200 datagrams: some 50 ms of a 1 kHz CiA 402 cycle,
where every member of the group sees the SYNC, the RPDO and both TPDOs. A process descheduled for longer
than that loses frames, and a lost TPDO is a lost sample. Measured here with two CPU hogs on two cores
and no realtime priority: 1 889 to 3 672 of 15 000 TPDOs lost in each of five 15 s runs at the default
buffer (docs/drives.md). The simulated devices make the same request for their end (firmware_sim/devices/bus_buffer.py).
"""

from __future__ import annotations

import os
import socket

RECEIVE_BUFFER = 8 << 20  # bytes: several seconds of that cycle's datagrams
_SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)  # Linux: lets a privileged process pass rmem_max


def enlarge_receive_buffer(bus: object, size: int = RECEIVE_BUFFER) -> int:
    """Ask for a receive buffer of ``size`` bytes on ``bus``'s socket (a python-can bus, or a canopen
    Network's ``bus``); returns the size the kernel granted (bytes, as it reports it: twice what it keeps
    for data), or 0 for a bus without a socket (``virtual``, vendor interfaces). Unprivileged, the kernel caps
    the request at ``net.core.rmem_max``."""
    try:
        fd = bus.fileno()  # type: ignore[attr-defined]
    except (AttributeError, NotImplementedError):
        return 0
    if not isinstance(fd, int) or fd < 0:
        return 0
    with socket.socket(fileno=os.dup(fd)) as sock:
        for option in (_SO_RCVBUFFORCE, socket.SO_RCVBUF):
            try:
                sock.setsockopt(socket.SOL_SOCKET, option, size)
                break
            except OSError:
                continue
        return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
