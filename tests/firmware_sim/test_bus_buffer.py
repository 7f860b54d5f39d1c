"""The simulated device's receive buffer request: the kernel's own report is the oracle."""

import random
from pathlib import Path

import can

from hilbench.firmware_sim.devices.bus_buffer import DEVICE_RECEIVE_BUFFER, widen_device_buffer


def test_the_device_end_gets_the_buffer_or_the_systems_cap_and_a_virtual_bus_is_left_alone():
    group = f"239.{random.randint(1, 254)}.{random.randint(1, 254)}.{random.randint(1, 254)}"
    bus = can.Bus(interface="udp_multicast", channel=group, port=random.randint(40000, 60000), hop_limit=0)
    try:
        cap = int(Path("/proc/sys/net/core/rmem_max").read_text())
        assert widen_device_buffer(bus) >= 2 * min(DEVICE_RECEIVE_BUFFER, cap)  # Linux reports twice the data
    finally:
        bus.shutdown()
    virtual = can.Bus(interface="virtual", channel="no-socket")
    try:
        assert widen_device_buffer(virtual) == 0
    finally:
        virtual.shutdown()
