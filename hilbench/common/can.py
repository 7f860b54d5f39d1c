"""CAN helpers both ends of a python-can bus use: the host's drivers and the simulated devices.

**A socket receive buffer that rides out a stalled process.** python-can's ``udp_multicast`` and ``socketcan``
buses read a kernel socket. Its default receive buffer (``net.core.rmem_default``, 208 KiB here) holds about
200 datagrams: some 50 ms of a 1 kHz CiA 402 cycle, where every member of the group sees the SYNC, the RPDO
and both TPDOs. A process descheduled for longer than that loses frames, and a lost TPDO (or SYNC) is a lost
sample. Measured here with two CPU hogs on two cores and no realtime priority: 1 889 to 3 672 of 15 000 TPDOs
lost in each of five 15 s runs at the default buffer (docs/drives.md).

**A malformed frame is counted and dropped, never fatal.** python-can's ``udp_multicast`` bus decodes every
datagram on its group and port as a CAN frame; one that does not decode (a stray datagram of another program,
a truncated one) makes ``recv`` raise ``CanOperationError("could not unpack received message")``. Raised in a
``can.Notifier`` thread, that ends the thread: the node stops hearing the bus for good (a simulated drive's
watchdog then faults a live run). Raised in the host's cycle, it ends the run with a traceback. A real CAN
controller drops a damaged frame and counts it; this does the same. Only decoding failures are dropped:
python-can raises them with the decoder's exception as the cause. A failure of the socket itself (the
interface went down) keeps propagating, as it must.
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


class MalformedFrames:
    """How many malformed frames a bus dropped (``count``), and the last reason."""

    def __init__(self) -> None:
        self.count = 0
        self.last = ""


def is_malformed(exc: BaseException) -> bool:
    """Whether a python-can receive error is a frame that did not decode (not a failing socket)."""
    import can

    cause = exc.__cause__
    return isinstance(exc, can.CanOperationError) and cause is not None and not isinstance(cause, OSError)


def drop_malformed_frames(bus: object) -> MalformedFrames:
    """Make ``bus.recv`` drop (and count) frames that do not decode instead of raising; idempotent.
    Returns the counter, also kept as ``bus.malformed_frames``."""
    existing = getattr(bus, "malformed_frames", None)
    if isinstance(existing, MalformedFrames):
        return existing
    counter = MalformedFrames()
    inner = bus._recv_internal  # type: ignore[attr-defined]

    def receive(timeout):
        try:
            return inner(timeout)
        except Exception as exc:
            if not is_malformed(exc):
                raise
            counter.count += 1
            counter.last = f"{exc}: {exc.__cause__}"
            return None, False  # BusABC.recv keeps waiting for the rest of its timeout

    bus._recv_internal = receive  # type: ignore[attr-defined]
    bus.malformed_frames = counter  # type: ignore[attr-defined]
    return counter


#: The payload lengths a CAN-FD frame can have (its DLC codes 0-15), bytes.
FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


def pad_fd(data: bytes, fill: int = 0x50) -> bytes:
    """``data`` padded to the next CAN-FD payload length with ``fill`` (0x50: the moteus protocol's no-op,
    which moteus's own transports pad with)."""
    size = next((n for n in FD_LENGTHS if n >= len(data)), None)
    if size is None:
        raise ValueError(f"{len(data)} bytes do not fit a CAN-FD frame (64 at most)")
    return bytes(data) + bytes([fill]) * (size - len(data))
