"""Issue #25: zero torque before enable, every time, and a run whose first sample moves uncommanded is flagged.

A CST drive applies 0x6071 as soon as operation is enabled; after a killed run it may still hold the last torque,
in the object or in a received RPDO. The host writes 0x6071 = 0 by SDO and sends one RPDO with zero torque before
the enable transition; the run's first sample (taken at the first SYNC, before any commanded torque acts) is then
checked, and a moving one marks the run UNFIT in its events (the analysis refuses such a record unless allowed).
"""

from __future__ import annotations

import uuid

import can
import canopen
import h5py
import pytest

from hilbench.bench.acquisition.protocols import SteppedSine
from hilbench.drivers import cia402 as c
from hilbench.drivers.canopen_drive import CanopenDrive
from hilbench.firmware_sim.devices.cia402_drive import EDS_PATH, SimCia402Drive
from hilbench.firmware_sim.devices.sim_config import load_sim_config
from tests.drivers.cia402_runs import run_on_sim

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]  # starts a device
ONE = SteppedSine(frequencies=[20.0], amplitudes=[0.5], settle_periods=1, measure_periods=1, sample_rate=1000)


class CarelessHost(CanopenDrive):
    """The host before the fix: nothing zeroes the target torque before enable."""

    def _zero_torque(self) -> None:
        pass


def _run(tmp_path, host_class=CanopenDrive, **sim_options) -> tuple[list[str], float]:
    out = run_on_sim(tmp_path / "r.h5", ONE, host_class=host_class, **sim_options)
    with h5py.File(out) as f:
        events = [m.decode() for m in f["events"]["message"][:]]
        first = float(f["samples/torque"][0])
    return events, first


def _flags(events: list[str]) -> list[str]:
    return [e for e in events if "uncommanded motion" in e]


def test_a_clean_start_is_not_flagged(tmp_path):
    events, first = _run(tmp_path)
    assert _flags(events) == []
    assert first == 0.0  # no torque before the first command acted


def test_a_stale_torque_is_zeroed_before_enable(tmp_path):
    # the drive holds 1000 per mille (the rated torque) from a killed run: the host clears it, the run is clean
    events, first = _run(tmp_path, stale_torque=1000)
    assert _flags(events) == [] and first == 0.0


def test_a_stale_torque_the_host_did_not_zero_flags_the_run(tmp_path):
    # the same drive with the host's zeroing taken out: the first sample shows the rated torque (0.5 N*m)
    events, first = _run(tmp_path, CarelessHost, stale_torque=1000)
    flags = _flags(events)
    # "UNFIT" in an info event: the analysis refuses the record unless --allow-incomplete (analysis/record.py)
    assert len(flags) == 1 and flags[0].startswith("UNFIT: uncommanded motion at the start of the run"), events
    assert first == pytest.approx(0.5, abs=0.05)


def test_an_axis_moving_at_enable_flags_the_run(tmp_path):
    # 20 rad/s at the start, 6.7 % of the default 300 rad/s velocity limit (the check's limit: 1 %)
    events, first = _run(tmp_path, spin=20.0)
    flags = _flags(events)
    assert len(flags) == 1 and flags[0].startswith("UNFIT: uncommanded motion"), events
    speed = float(flags[0].split("shows ")[1].split(" rad/s")[0])
    assert speed == pytest.approx(20.0, rel=0.05)  # one cycle of friction after 20 rad/s


def test_the_first_rpdo_carries_zero_torque_before_the_enable_transition():
    channel = f"z-{uuid.uuid4().hex[:8]}"
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    sim = SimCia402Drive(network, 3, load_sim_config(), clock="sync", sync_timeout=1.0, stale_torque=700)
    listener = can.Bus(interface="virtual", channel=channel)
    try:
        host = CanopenDrive("virtual", channel, 3, str(EDS_PATH), timeout=1.0)
        try:
            from hilbench.drivers import protocol as p

            host.configure(p.Config(sample_rate=1000, current_limit=20.0, torque_constant=0.2,
                                    counts_per_rev=1 << 20, watchdog_timeout=1.0))
            while listener.recv(0) is not None:  # what configure sent
                pass
            host.arm()
            frames = []
            while (msg := listener.recv(0)) is not None:  # what arm sent (and heartbeats)
                frames.append(msg)
        finally:
            host.close()
    finally:
        listener.shutdown()
        sim.close()
        network.disconnect()
    rpdo = [i for i, m in enumerate(frames) if m.arbitration_id == 0x203]
    # SDO downloads to the controlword (0x6040) with enable operation (0x0F)
    enable = [i for i, m in enumerate(frames) if m.arbitration_id == 0x603 and m.data[0] & 0xE0 == 0x20
              and m.data[1:4] == bytes([0x40, 0x60, 0]) and m.data[4] == int(c.Command.ENABLE_OPERATION)]
    assert rpdo and enable and rpdo[0] < enable[0]
    assert int.from_bytes(frames[rpdo[0]].data[2:4], "little", signed=True) == 0
