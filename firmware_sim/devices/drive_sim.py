"""What every simulated host-clocked drive shares: its process's ``serve()`` and the plant's zero-order-hold step.

Each simulated drive (CiA 402, ODrive, moteus) is a real protocol peer in its own process: ``serve`` asks for
real-time scheduling, opens the python-can bus (``udp_multicast`` on this host only), makes its socket buffer
large and its receiver deaf to malformed frames, builds the drive on it, prints the URL a host connects with,
and runs until ``stop``. :func:`hold_step` advances the plant over one control period with the previous
input held, as the plant's sampling convention says (docs/architecture.md).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable

import numpy as np

from hilbench.common.can import drop_malformed_frames, enlarge_receive_buffer
from hilbench.firmware_sim.engine.plant import Plant

RT_PRIORITY = 20  # SCHED_FIFO priority of a simulated drive's process, where the OS allows it


def hold_step(plant: Plant, u_held: float, u_new: float, steps: int):
    """Advance ``plant`` by ``steps`` plant steps (>= 1): ``u_held`` (A) acts over all but the last step, whose
    row is measured now, before ``u_new`` acts (it is held from then until the next call). Returns the plant's
    output rows; the last one is the sample of this instant."""
    u = np.full(steps, u_held)
    u[-1] = u_new
    return plant.run(u)


def serve(interface: str, channel: str, port: int | None, stop: threading.Event | None,
          start: Callable[[object], tuple[str, Callable[[], None]]], **bus_kwargs) -> int:
    """Run a simulated drive on a python-can bus until ``stop`` is set (or Ctrl-C).

    ``start(bus)`` builds the drive on the open bus and returns the URL a host connects with (printed as the
    first line, with ``&port=`` where one was given) and what closes the drive; the bus is shut down after.
    ``bus_kwargs`` go to ``can.Bus`` (``fd=True`` for a CAN-FD drive)."""
    try:  # a drive's control loop is real-time: ask the OS for SCHED_FIFO (runs without it when refused)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
    except (AttributeError, OSError):
        pass
    import can

    kwargs: dict = {"hop_limit": 0} if interface == "udp_multicast" else {}  # udp_multicast: this host only
    kwargs.update(bus_kwargs)
    if port is not None:
        kwargs["port"] = port
    bus = can.Bus(interface=interface, channel=channel, **kwargs)
    enlarge_receive_buffer(bus)
    drop_malformed_frames(bus)  # a stray datagram must not end the notifier thread (the drive would go deaf)
    url, close = start(bus)
    print(url + (f"&port={port}" if port else ""), flush=True)
    stop = stop or threading.Event()
    try:
        while not stop.wait(0.2):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        close()
        bus.shutdown()
    return 0
