"""A malformed frame from the bus is counted and dropped, never fatal.

python-can's ``udp_multicast`` bus decodes every datagram on its group and port as a CAN frame; one that
does not decode (a stray datagram of another program, a truncated one) makes ``recv`` raise
``CanOperationError("could not unpack received message")``. Raised in a ``can.Notifier`` thread, that
ends the thread: the node stops hearing the bus for good. Raised in the host's cycle, it ends the run
with a traceback. A real CAN controller drops a damaged frame and counts it; this does the same.

Only decoding failures are dropped: python-can raises them with the decoder's exception as the cause.
A failure of the socket itself (the interface went down) keeps propagating, as it must.
The simulated devices do the same for their end (``firmware_sim/devices/bus_frames.py``).
"""

from __future__ import annotations


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
