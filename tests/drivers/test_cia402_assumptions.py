"""docs/drives.md "What the host assumes of a drive": one line per object, and exactly the objects the host
touches. Measured on the bus, not read from the code: every SDO the host sends (open, configure, arm, a stream,
faults, history, fault reset, close) and every object it maps into a PDO, against the simulated drive with every
optional object present (factor objects included)."""

from __future__ import annotations

import re
import uuid
from pathlib import Path

import can
import canopen
import numpy as np
import pytest

from hilbench.drivers import protocol as p
from hilbench.drivers.canopen_drive import CanopenDrive
from hilbench.firmware_sim.devices.cia402_drive import SimCia402Drive
from hilbench.firmware_sim.devices.sim_config import load_sim_config
from tests.drivers.test_cia402_drive_objects import _pair, eds_variant

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]  # starts a device
DOC = Path(__file__).resolve().parents[2] / "docs" / "drives.md"


def documented() -> list[int]:
    text = DOC.read_text()
    section = text.split("### What the host assumes of a drive", 1)[1].split("\n#", 1)[0]
    return [int(m, 16) for m in re.findall(r"^- (0x[0-9A-F]{4}) ", section, re.M)]


@pytest.mark.device_free
def test_the_section_lists_each_object_once():
    objects = documented()
    assert len(objects) == len(set(objects)) and len(objects) > 30


def test_the_section_lists_exactly_what_the_host_touches(tmp_path):
    factors = (_pair(0x6091, "Gear ratio", 1, 1) + _pair(0x6092, "Feed constant", 1 << 20, 1)
               + _pair(0x6093, "Position factor", 1, 1) + _pair(0x6094, "Velocity encoder factor", 1, 1))
    eds = eds_variant(tmp_path / "all.eds", objects=factors)
    channel = f"a-{uuid.uuid4().hex[:8]}"
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    sim = SimCia402Drive(network, 3, load_sim_config(), eds=eds, clock="sync", sync_timeout=1.0)
    listener = can.Bus(interface="virtual", channel=channel)
    frames = []
    try:
        host = CanopenDrive("virtual", channel, 3, eds, timeout=1.0)
        try:
            host.configure(p.Config(sample_rate=1000, current_limit=20.0, torque_constant=0.2,
                                    counts_per_rev=1 << 20, watchdog_timeout=1.0, position_min=-100.0,
                                    position_max=100.0))
            host.arm()
            for _ in host.stream(np.zeros(50)):
                pass
            host.faults()
            host.history()
            sim.fault(0x2310)
            host.clear_faults()
        finally:
            host.close()
        while (msg := listener.recv(0)) is not None:
            frames.append(msg)
    finally:
        listener.shutdown()
        sim.close()
        network.disconnect()
    touched = set()
    for m in frames:
        if m.arbitration_id != 0x603 or m.data[0] >> 5 not in (1, 2):  # SDO initiate download / upload
            continue
        index, sub = int.from_bytes(m.data[1:3], "little"), m.data[3]
        touched.add(index)
        if (0x1600 <= index < 0x1800 or 0x1A00 <= index < 0x1C00) and sub and m.data[0] >> 5 == 1:
            mapped = int.from_bytes(m.data[4:8], "little") >> 16
            if mapped:
                touched.add(mapped)  # an object the host maps into a PDO
    assert sorted(f"0x{i:04X}" for i in touched) == sorted(f"0x{i:04X}" for i in documented())
