"""The simulated devices' end of a bus drops malformed frames instead of dying on them.

python-can's ``udp_multicast`` bus raises ``CanOperationError("could not unpack received message")``
for a datagram on its group and port that is not a CAN frame. Raised in the ``can.Notifier`` thread a
simulated drive listens with, it ended that thread, and the drive stopped hearing the bus for good (its
watchdog then faulted a live run). A real CAN controller counts a damaged frame and drops it; so does
this. A failing socket (the cause an ``OSError``) still propagates. The host's end does the same in
``drivers/can_frames.py``; a simulated device shares only protocol definitions with ``drivers``, so the
few lines are kept on both sides.
"""

from __future__ import annotations


def drop_malformed(bus: object) -> list[int]:
    """Make ``bus.recv`` drop and count frames that do not decode; returns the counter (a one-element list,
    also ``bus.malformed_frames``). Idempotent."""
    import can

    existing = getattr(bus, "malformed_frames", None)
    if isinstance(existing, list):
        return existing
    counter = [0]
    inner = bus._recv_internal  # type: ignore[attr-defined]

    def receive(timeout):
        try:
            return inner(timeout)
        except can.CanOperationError as exc:
            if exc.__cause__ is None or isinstance(exc.__cause__, OSError):
                raise
            counter[0] += 1
            return None, False

    bus._recv_internal = receive  # type: ignore[attr-defined]
    bus.malformed_frames = counter  # type: ignore[attr-defined]
    return counter
