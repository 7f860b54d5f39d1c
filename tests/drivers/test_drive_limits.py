"""Issue #30 item 2, the rule: every limit the bench accepts is enforced on every device. The position window and
the velocity limit were silently ignored on both drives (a run with a +-1 mrad window completed at 0.223 rad;
one with 0.5 rad/s at 9.48 rad/s on CiA 402, 18.2 rad/s on the ODrive). Now the host writes the drive's own limit
objects and also checks position and speed on every cycle: the first sample outside ends the stream (zero torque,
then disable), and the run ends ``aborted`` with a ``fault`` event named as on ``sim://``.

One test per limit per drive, through the runner (``Bench.run``) on python-can's virtual bus."""

from __future__ import annotations

import math
import uuid

import can
import canopen
import h5py
import numpy as np
import pytest

from hilbench.bench.acquisition.protocols import Identification
from hilbench.bench.acquisition.runner import Bench, DeviceSettings
from hilbench.common.runfile import open_run
from hilbench.drivers import cia402 as c
from hilbench.drivers import odrive_can as o
from hilbench.drivers import protocol as p
from hilbench.drivers.canopen_drive import CanopenDrive
from hilbench.drivers.errors import DeviceFaultError
from hilbench.drivers.odrive_drive import OdriveDrive
from hilbench.firmware_sim.devices.cia402_drive import EDS_PATH, SimCia402Drive
from hilbench.firmware_sim.devices.odrive_sim import TVL_ENDPOINT, SimOdrive
from hilbench.firmware_sim.devices.sim_config import load_sim_config

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]  # starts a device
CPR = 1 << 20
LIMITS = {"position": {"position_min": -0.001, "position_max": 0.001}, "velocity": {"velocity_limit": 0.5}}


class Drive:
    """A simulated drive of ``kind`` on a fresh virtual bus, and the host driver connected to it."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.channel = f"lim-{uuid.uuid4().hex[:8]}"
        if kind == "canopen":
            self.network = canopen.Network()
            self.network.connect(interface="virtual", channel=self.channel)
            self.sim = SimCia402Drive(self.network, 3, load_sim_config(), clock="sync", sync_timeout=1.0)
            self.host = CanopenDrive("virtual", self.channel, 3, str(EDS_PATH), timeout=1.0)
        else:
            self.bus = can.Bus(interface="virtual", channel=self.channel)
            self.sim = SimOdrive(self.bus, 3, load_sim_config(), watchdog_timeout=1.0)
            self.host = OdriveDrive("virtual", self.channel, 3, TVL_ENDPOINT, timeout=1.0)

    def close(self) -> None:
        self.host.close()
        self.sim.close()
        if self.kind == "canopen":
            self.network.disconnect()
        else:
            self.bus.shutdown()


@pytest.mark.parametrize("limit", ["position", "velocity"])
@pytest.mark.parametrize("kind", ["canopen", "odrive"])
def test_a_limit_ends_the_run_with_the_sim_fault_name(kind, limit, tmp_path):
    drive = Drive(kind)
    settings = DeviceSettings(current_limit=20.0, counts_per_rev=CPR, watchdog_timeout=1.0, **LIMITS[limit])
    out = tmp_path / "run.h5"
    name = "POSITION_WINDOW" if limit == "position" else "OVER_SPEED"
    try:
        bench = Bench(drive.host, f"{kind}://virtual/{drive.channel}", settings)
        stopped = rf"stream stopped by the host at (cycle|sample) \d+: {name} "
        with pytest.raises(DeviceFaultError, match=stopped) as err:
            bench.run(Identification(duration=3.0, amplitude=10.0, sample_rate=1000), out)
        assert err.value.faults == p.Fault[name]
        # the drive's own limits were configured too
        if kind == "canopen":
            low, high = (drive.host._read(c.SOFTWARE_POSITION_LIMIT, sub) for sub in (1, 2))
            rpm = drive.host._read(c.MAX_MOTOR_SPEED)
            if limit == "position":  # increments, rounded outwards
                assert (low, high) == (math.floor(-0.001 * CPR / (2 * math.pi)), math.ceil(0.001 * CPR / (2 * math.pi)))
            else:
                assert rpm == math.ceil(0.5 * 60 / (2 * math.pi)) and (low, high) == (-(2**31), 2**31 - 1)
            assert drive.sim.state is not c.State.OPERATION_ENABLED and drive.sim.target_pm == 0
        else:
            assert drive.sim.vel_limit == pytest.approx(settings.velocity_limit / (2 * math.pi), rel=1e-6)
            assert drive.sim.state == o.AxisState.IDLE and drive.sim.input_torque == 0.0
    finally:
        drive.close()
    with open_run(out) as run:
        assert run.status == "aborted"
        faults = [str(e["message"]) for e in run.events if e["kind"] == "fault"]
        # the host's stop first; the drive's own limit (the same sample) may fault it too: its EMCY follows
        assert faults and name in faults[0], faults
        n = run.n_samples
    with h5py.File(out) as f:
        position, velocity = f["samples/position"][:], f["samples/velocity"][:]
    assert 0 < n < 3000  # it stopped early, and kept every sample it received
    if limit == "position":  # every sample inside the window but the last, the one that tripped
        assert np.all(np.abs(position[:-1]) <= 0.001 + 1e-12) and abs(position[-1]) > 0.001
    else:  # every speed the drive reported within the limit but the last
        assert np.all(np.abs(velocity[:-1]) <= 0.5 + 1e-6) and abs(velocity[-1]) > 0.5
    print(f"{kind} {limit}: stopped after {n} samples, last position {position[-1]:.6g} rad, "
          f"speed {velocity[-1]:.6g} rad/s")


def test_the_simulated_cia402_drive_enforces_its_software_position_limit_itself():
    """The drive's own limit, without the host's check: 0x607D narrowed after configure (as another tool or a
    drive's own setting would), the host's window left open. The drive faults with EMCY 0x8612."""
    drive = Drive("canopen")
    try:
        host = drive.host
        host.configure(p.Config(sample_rate=1000, current_limit=20.0, torque_constant=0.2, counts_per_rev=CPR,
                                watchdog_timeout=1.0))
        host._write(c.SOFTWARE_POSITION_LIMIT, -100, 1)
        host._write(c.SOFTWARE_POSITION_LIMIT, 100, 2)
        host.arm()
        with pytest.raises(DeviceFaultError, match="EMCY 0x8612 reference limit"):
            for _ in host.stream(np.full(3000, 8.0)):
                pass
        assert drive.sim.state is c.State.FAULT and abs(drive.sim.meas[0]) > 100
        assert host.faults()[0].startswith("0x603F error code 0x8612 reference limit")
    finally:
        drive.close()
