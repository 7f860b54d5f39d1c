"""Issue #25, CiA 402 drives as they are: behaviours CiA 301/402 allow that only our own simulated drive lacked.

- Enable is a handshake: a drive may apply the RPDO's controlword after sampling (its first TPDO of a stream
  still says "switched on"), or take SYNCs to enable. A stepped sine (one stream per step) failed with "10 of 10
  SYNCs got no TPDO back". The host now allows ``enable_cycles`` (default 4) SYNCs for "operation enabled".
- Optional objects (0x1016 consumer heartbeat, 0x6007 loss reaction) are skipped where the EDS or the drive
  lacks them, saying so, instead of a KeyError or an SDO abort and no run.
"""

from __future__ import annotations

import uuid

import canopen
import h5py
import pytest

from hilbench.bench.acquisition.protocols import SteppedSine
from hilbench.bench.acquisition.runner import Bench, DeviceSettings
from hilbench.drivers import cia402 as c
from hilbench.drivers.canopen_drive import CanopenDrive
from hilbench.drivers.errors import CommandRefusedError
from hilbench.firmware_sim.devices.cia402_drive import EDS_PATH, SimCia402Drive
from hilbench.firmware_sim.devices.sim_config import load_sim_config

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]  # starts a device
STEPS = SteppedSine(frequencies=[20.0, 40.0, 80.0], amplitudes=[2.0, 2.0, 2.0], settle_periods=1, measure_periods=2,
                    sample_rate=1000)


def _drive(eds=EDS_PATH, **options):
    channel = f"e-{uuid.uuid4().hex[:8]}"
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    sim = SimCia402Drive(network, 3, load_sim_config(), eds=eds, clock="sync", sync_timeout=1.0, **options)
    return channel, network, sim


@pytest.mark.parametrize("latency", [0, 1, 3])
@pytest.mark.parametrize("order", ["apply-then-sample", "sample-then-apply"])
def test_a_stepped_sine_runs_whatever_the_drive_takes_to_enable(order, latency, tmp_path):
    channel, network, sim = _drive(order=order, enable_latency=latency)
    out = tmp_path / "steps.h5"
    try:
        host = CanopenDrive("virtual", channel, 3, str(EDS_PATH), timeout=1.0)
        bench = Bench(host, "canopen://virtual", DeviceSettings(counts_per_rev=1 << 20, watchdog_timeout=1.0))
        try:
            result = bench.run(STEPS, out)
        finally:
            host.close()
    finally:
        sim.close()
        network.disconnect()
    total = sum(b - a for a, b in STEPS.segments())
    assert result.status == "completed" and result.samples == total
    with h5py.File(out) as f:
        status = f["samples/drive_status"][:].astype(int)
        events = [str(m) for m in f["events"]["message"][:]]
    states = [c.state_of(w) for w in status]
    late = latency + (order == "sample-then-apply")  # TPDOs per step that report the drive not yet enabled
    not_enabled = sum(s is not c.State.OPERATION_ENABLED for s in states)
    # the first step is armed by SDO (enabled before the first SYNC); each later step re-enables by RPDO
    assert not_enabled == (len(STEPS.segments()) - 1) * late, (not_enabled, late)
    assert all(s in (c.State.OPERATION_ENABLED, c.State.SWITCHED_ON) for s in states)
    assert any("reported operation enabled from cycle" in e for e in events) == (late > 0), events


def test_a_drive_slower_than_the_bound_is_one_line(tmp_path):
    channel, network, sim = _drive(order="sample-then-apply", enable_latency=3)
    try:
        host = CanopenDrive("virtual", channel, 3, str(EDS_PATH), timeout=1.0, enable_cycles=2)
        try:
            bench = Bench(host, "canopen://virtual", DeviceSettings(counts_per_rev=1 << 20, watchdog_timeout=1.0))
            with pytest.raises(CommandRefusedError, match=r"did not report operation enabled within 2 cycles .*"
                                                          r"&enable_cycles=N"):
                bench.run(STEPS, tmp_path / "slow.h5")
        finally:
            host.close()
    finally:
        sim.close()
        network.disconnect()


def _without(objects: tuple[str, ...], path) -> str:
    text = EDS_PATH.read_text()
    for index in objects:
        while f"[{index}" in text:
            start = text.index(f"[{index}")
            end = text.index("\n\n", start) + 2
            text = text[:start] + text[end:]
        text = "\n".join(line for line in text.splitlines() if not line.endswith(f"=0x{index}")) + "\n"
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("who", ["eds", "drive"])
def test_optional_objects_missing_are_skipped_saying_so(who, tmp_path):
    lean = _without(("1016", "6007"), tmp_path / "lean.eds")
    channel, network, sim = _drive(eds=lean if who == "drive" else EDS_PATH)
    try:
        host = CanopenDrive("virtual", channel, 3, lean if who == "eds" else str(EDS_PATH), timeout=1.0)
        bench = Bench(host, "canopen://virtual", DeviceSettings(counts_per_rev=1 << 20, watchdog_timeout=1.0))
        one = SteppedSine(frequencies=[20.0], amplitudes=[1.0], settle_periods=1, measure_periods=1, sample_rate=1000)
        try:
            result = bench.run(one, tmp_path / "r.h5")
        finally:
            host.close()
    finally:
        sim.close()
        network.disconnect()
    assert result.status == "completed" and result.samples == sum(b - a for a, b in one.segments())
    with h5py.File(tmp_path / "r.h5") as f:
        events = [str(m) for m in f["events"]["message"][:]]
    why = "is not in the EDS" if who == "eds" else "is not in the drive (SDO abort 0x06020000)"
    for index in ("0x1016:1 (consumer heartbeat)", "0x6007 (abort connection option (1 = fault))"):
        assert any(index in e and why in e for e in events), events
