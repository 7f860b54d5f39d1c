"""The host-clocked CAN cycle (drivers/host_cycle.py) on python-can's virtual bus, with a scripted peer.

Two CI failures behind these tests: a run that hung for minutes because the cycle never sent its first
trigger and the stream had no deadline for that; and a limit run whose tripping sample was dropped, because
the cycle stopped collecting before that sample's second frame (an ODrive's frames are not answers to
triggers, so its rows can run ahead of the commands sent)."""

from __future__ import annotations

import struct
import threading
import time
import uuid

import can
import numpy as np
import pytest

from hilbench.drivers import host_cycle
from hilbench.drivers.errors import DeviceTimeoutError
from hilbench.drivers.host_cycle import CanCycle, CanCycleSpec, Guard

pytestmark = pytest.mark.drives
TRIGGER, POS, TORQUE = 0x80, 0x181, 0x281


def spec(channel: str, rate: float = 100.0, guards: tuple[Guard, ...] = ()) -> CanCycleSpec:
    return CanCycleSpec("virtual", channel, {}, rate, (TRIGGER,), (0,), (POS, TORQUE), (b"",), (b"",),
                        guards=guards)


def test_a_cycle_that_never_sends_ends_in_one_line_instead_of_hanging(monkeypatch):
    monkeypatch.setattr(host_cycle, "START_LIMIT", 0.2)
    cycle = CanCycle(spec(f"hc-{uuid.uuid4().hex[:8]}"), np.zeros((10, 1, 8), np.uint8), start_delay=30.0)
    try:
        since = time.monotonic()
        cycle.start()
        cycle.check_started(since, "node 3")  # within the limit: nothing to say
        time.sleep(0.3)
        line = r"^node 3: the host's CAN cycle sent no frame within 0.2 s"
        with pytest.raises(DeviceTimeoutError, match=line) as err:
            cycle.check_started(since, "node 3")
        assert "\n" not in str(err.value)
        assert not cycle.alive() and cycle.sent == 0  # stopped before its first trigger, nothing commanded
    finally:
        cycle.close()


def test_the_sample_that_trips_a_limit_is_collected_whole_even_when_rows_lead_the_triggers():
    channel = f"hc-{uuid.uuid4().hex[:8]}"
    peer = can.Bus(interface="virtual", channel=channel)
    guard = Guard("POSITION_WINDOW", 0, 0, "<f", -1.0, 1.0)
    cycle = CanCycle(spec(channel, rate=10.0, guards=(guard,)), np.zeros((20, 1, 8), np.uint8), start_delay=0.0)

    def drive() -> None:  # answers the first trigger with four samples at once; the fourth is outside
        while (msg := peer.recv(2.0)) is not None and msg.arbitration_id != TRIGGER:
            pass
        for k, x in enumerate((0.1, 0.2, 0.3, 5.0)):
            peer.send(can.Message(arbitration_id=POS, data=struct.pack("<f", x), is_extended_id=False))
            if k == 3:
                time.sleep(0.15)  # the tripping sample's second frame comes late
            peer.send(can.Message(arbitration_id=TORQUE, data=struct.pack("<f", k), is_extended_id=False))

    t = threading.Thread(target=drive, daemon=True)
    t.start()
    try:
        cycle.start()
        cycle.join(10.0)
        t.join(5.0)
        assert cycle.limit == (guard, 3)
        assert cycle.sent < 4  # the rows ran ahead of the triggers
        assert cycle.received(0) == 4 and cycle.received(1) == 4  # the late frame of row 3 was waited for
        torque = cycle.arrays["rx"][1, :4, :4].copy().view("<f4").ravel()
        np.testing.assert_array_equal(torque, [0.0, 1.0, 2.0, 3.0])
    finally:
        cycle.close()
        peer.shutdown()
