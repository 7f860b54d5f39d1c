"""A protocol run by the bench on the simulated CiA 402 drive over a private ``virtual`` bus (for the tests)."""

from __future__ import annotations

import uuid
from collections.abc import Callable
from pathlib import Path

import canopen

from hilbench.bench.acquisition.runner import Bench, DeviceSettings
from hilbench.drivers.canopen_drive import CanopenDrive
from hilbench.firmware_sim.devices.cia402_drive import EDS_PATH, SimCia402Drive
from hilbench.firmware_sim.devices.sim_config import load_sim_config


def run_on_sim(out: Path, protocol, eds: str = str(EDS_PATH), host_class: type = CanopenDrive,
               after: Callable[[CanopenDrive, SimCia402Drive], None] | None = None, **sim_options) -> Path:
    """Run ``protocol`` into ``out`` (checked completed); ``after(host, sim)`` runs before both close."""
    channel = f"r-{uuid.uuid4().hex[:8]}"
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    sim = SimCia402Drive(network, 3, load_sim_config(), eds=eds, clock="sync", sync_timeout=1.0, **sim_options)
    try:
        host = host_class("virtual", channel, 3, eds, timeout=1.0)
        try:
            result = Bench(host, "canopen://virtual", DeviceSettings(counts_per_rev=1 << 20, watchdog_timeout=1.0)
                           ).run(protocol, out)
            if after is not None:
                after(host, sim)
        finally:
            host.close()
    finally:
        sim.close()
        network.disconnect()
    assert result.status == "completed"
    return out
