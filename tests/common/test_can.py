"""The CAN helpers both ends of a bus share (hilbench.common.can): the receive buffer asked for on socket-based
buses (the kernel's own report is the oracle)."""

import random
from pathlib import Path

import can

from hilbench.common.can import RECEIVE_BUFFER, enlarge_receive_buffer


def test_a_udp_multicast_bus_gets_the_buffer_or_the_systems_cap():
    group = f"239.{random.randint(1, 254)}.{random.randint(1, 254)}.{random.randint(1, 254)}"
    bus = can.Bus(interface="udp_multicast", channel=group, port=random.randint(40000, 60000), hop_limit=0)
    try:
        default = int(Path("/proc/sys/net/core/rmem_default").read_text())
        cap = int(Path("/proc/sys/net/core/rmem_max").read_text())
        granted = enlarge_receive_buffer(bus)
        # Linux reports twice what it keeps for data; unprivileged, the request is capped at rmem_max
        assert granted >= 2 * min(RECEIVE_BUFFER, cap) and granted >= 2 * default
    finally:
        bus.shutdown()


def test_a_bus_without_a_socket_is_left_alone():
    bus = can.Bus(interface="virtual", channel="no-socket")
    try:
        assert enlarge_receive_buffer(bus) == 0
    finally:
        bus.shutdown()
