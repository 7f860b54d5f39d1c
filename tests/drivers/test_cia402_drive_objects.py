"""Issue #25: read what the drive says. The encoder resolution 0x608F is adopted (it was refused), the factor
objects (0x6091 gear ratio with 0x6092 feed constant, or 0x6093 position factor; 0x6094 velocity encoder factor)
give the units of 0x6064 and 0x606C, 0x1005 and 0x1014 give the SYNC and EMCY COB-IDs, and 0x60C2 gets the cycle
period where the drive has it. The simulated drive is configured to each through its EDS.

Oracle: the same stepped sine on the default drive (increments of 2**20 per revolution, default COB-IDs), whose
plant runs the same trajectory SYNC for SYNC (``clock="sync"``): every variant's position and velocity in rad
and rad/s must equal it within one of the variant's units.
"""

from __future__ import annotations

import json
import math
import re
import time
import uuid

import canopen
import h5py
import numpy as np
import pytest

from hilbench.bench.acquisition.protocols import SteppedSine
from hilbench.drivers import cia402 as c
from hilbench.drivers.canopen_drive import CanopenDrive
from hilbench.firmware_sim.devices.cia402_drive import EDS_PATH, SimCia402Drive
from hilbench.firmware_sim.devices.sim_config import load_sim_config
from tests.drivers.cia402_runs import run_on_sim

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]  # starts a device
STEP = SteppedSine(frequencies=[5.0], amplitudes=[15.0], settle_periods=1, measure_periods=1, sample_rate=1000)


@pytest.mark.device_free
@pytest.mark.parametrize("period, expected", [(1e-3, (1, -3)), (5e-4, (5, -4)), (2e-3, (2, -3)),
                                              (0.0125, (125, -4)), (0.25, (25, -2)), (1.0, (1, 0))])
def test_interpolation_period_is_value_times_a_power_of_ten(period, expected):
    value, index = c.interpolation_period(period)
    assert (value, index) == expected and value * 10.0**index == pytest.approx(period, rel=1e-12)


@pytest.mark.device_free
def test_increments_per_unit_closed_forms():
    # 16384 increments/rev, gear 3 motor revs per shaft rev, 3600 units (0.1 degree) per shaft rev
    assert c.increments_per_unit(16384, (3, 1), (3600, 1)) == pytest.approx(16384 * 3 / 3600, rel=1e-15)
    assert c.increments_per_unit(16384, (6, 2), (7200, 2)) == pytest.approx(16384 * 3 / 3600, rel=1e-15)
    assert c.increments_per_unit(16384, (3, 1), (3600, 1), factor=(4096, 1000)) == 4.096  # 0x6093 first
    assert c.increments_per_unit(16384) == 1.0 and c.increments_per_unit(16384, (3, 1)) == 1.0


def _section(index: int, name: str, subs: list[tuple[str, str, int]]) -> str:
    out = f"\n[{index:04X}]\nParameterName={name}\nObjectType=0x9\nSubNumber={len(subs) + 1}\n\n"
    out += (f"[{index:04X}sub0]\nParameterName=Highest sub-index supported\nObjectType=0x7\nDataType=0x0005\n"
            f"AccessType=ro\nDefaultValue=0x{len(subs):02X}\nPDOMapping=0\n")
    for k, (sub_name, data_type, value) in enumerate(subs, 1):
        out += (f"\n[{index:04X}sub{k}]\nParameterName={sub_name}\nObjectType=0x7\nDataType={data_type}\n"
                f"AccessType=rw\nDefaultValue={value}\nPDOMapping=0\n")
    return out


def _pair(index: int, name: str, a: int, b: int) -> str:
    return _section(index, name, [("numerator", "0x0007", a), ("divisor", "0x0007", b)])


def eds_variant(path, encoder: int = 1 << 20, sync: int = 0x80, emcy: str = "$NODEID+0x80",
                objects: str = "", drop_60c2: bool = False) -> str:
    text = EDS_PATH.read_text()
    text = re.sub(r"(\[608Fsub1\][^\[]*DefaultValue=)\d+", rf"\g<1>{encoder}", text)
    text = re.sub(r"(\[1005\][^\[]*DefaultValue=)\S+", rf"\g<1>0x{sync:08X}", text)
    text = re.sub(r"(\[1014\][^\[]*DefaultValue=)\S+", rf"\g<1>{emcy}", text)
    if drop_60c2:
        text = re.sub(r"\[60C2[^\[]*", "", text).replace("34=0x60C2\n", "").replace("SupportedObjects=34",
                                                                                     "SupportedObjects=33")
    path.write_text(text + objects)
    return str(path)


GEAR_FEED = _pair(0x6091, "Gear ratio", 3, 1) + _pair(0x6092, "Feed constant", 3600, 1)
VARIANTS = {
    "default": ({}, 1.0, 1.0),
    "encoder 16384": ({"encoder": 16384}, 1.0, 1.0),
    "gear 3:1, feed 3600/rev": ({"encoder": 16384, "objects": GEAR_FEED}, 16384 * 3 / 3600, 16384 * 3 / 3600),
    "position factor, velocity factor": ({"encoder": 65536, "objects": _pair(0x6093, "Position factor", 256, 1)
                                          + _pair(0x6094, "Velocity encoder factor", 16, 1)}, 256.0, 16.0),
    "SYNC 0x0F0, EMCY 0x0F3": ({"sync": 0x0F0, "emcy": "0x000000F3"}, 1.0, 1.0),
    "no 0x60C2": ({"drop_60c2": True}, 1.0, 1.0),
}


def _run(tmp_path, eds: str) -> tuple[dict, list[str], tuple[int, int] | None, list[int]]:
    seen: dict = {}

    def after(host: CanopenDrive, sim: SimCia402Drive) -> None:
        od = sim.node.object_dictionary
        seen["period"] = (sim._raw(c.INTERPOLATION_PERIOD, 1), sim._raw(c.INTERPOLATION_PERIOD, 2)) \
            if c.INTERPOLATION_PERIOD in od else None
        sim.fault(0x2310, 0x02)  # is the EMCY heard on the drive's COB-ID?
        host._emcy_event.wait(1.0)
        seen["emcy"] = [code for code, _, _ in host._emcy]

    out = run_on_sim(tmp_path / "r.h5", STEP, eds=eds, after=after)
    with h5py.File(out) as f:
        s = f["samples"]
        arrays = {k: s[k][:] for k in ("position", "velocity", "counts")}
        arrays["counts_per_rev"] = json.loads(f["device/calibration"][()])["counts_per_rev"]
        events = [m.decode() for m in f["events"]["message"][:]]
    return arrays, events, seen["period"], seen["emcy"]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    arrays, _, _, _ = _run(tmp_path_factory.mktemp("ref"), str(EDS_PATH))
    return arrays


@pytest.mark.parametrize("name", list(VARIANTS))
def test_the_host_reads_what_the_drive_says(name, reference, tmp_path):
    options, per_unit, per_velocity_unit = VARIANTS[name]
    eds = eds_variant(tmp_path / "v.eds", **options)
    arrays, events, period, emcy = _run(tmp_path, eds)
    encoder = options.get("encoder", 1 << 20)
    # within one of the variant's units (and one increment of the reference)
    unit = 2 * math.pi * per_unit / encoder + 2 * math.pi / 2**20
    np.testing.assert_allclose(arrays["position"], reference["position"], rtol=0, atol=unit)
    velocity_unit = 2 * math.pi * per_velocity_unit / encoder + 2 * math.pi / 2**20
    np.testing.assert_allclose(arrays["velocity"], reference["velocity"], rtol=0, atol=velocity_unit)
    assert np.ptp(reference["position"]) > 100 * unit  # the step moved the axis far more than the tolerance
    adopted = [e for e in events if "units adopted from the drive" in e]
    assert len(adopted) == 1 and f"0x608F = {encoder} increments/rev" in adopted[0], events
    replaced = [e for e in events if "counts_per_rev 1048576 replaced by" in e]
    assert len(replaced) == (encoder != 1 << 20), events
    assert arrays["counts_per_rev"] == encoder  # the run file's calibration says what was used
    if "objects" in options:
        assert f"({per_unit:.6g} increments per position unit)" in adopted[0]
    assert (period is None) == ("drop_60c2" in options)
    if period is not None:
        assert period == (1, -3)  # 1 ms
    else:
        assert any("0x60C2:1 (interpolation time period value) is not in the EDS" in e for e in events), events
    assert emcy == [0x2310]
    if "sync" in options:
        assert any("COB-IDs from the drive: SYNC 0x0F0 (0x1005), EMCY 0x0F3 (0x1014)" in e for e in events)


@pytest.mark.parametrize("restore", [True, False])
def test_a_drive_reacting_to_loss_in_every_state_is_left_without_a_consumer(restore):
    # 0x6007 applied in every state: a host that left 0x1016 armed on close faulted the drive 0.5 s later
    channel = f"o-{uuid.uuid4().hex[:8]}"
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    sim = SimCia402Drive(network, 3, load_sim_config(), clock="sync", sync_timeout=1.0, loss_in_any_state=True)
    try:
        host = CanopenDrive("virtual", channel, 3, str(EDS_PATH), timeout=1.0)
        try:
            from hilbench.drivers import protocol as p

            host.configure(p.Config(sample_rate=1000, current_limit=20.0, torque_constant=0.2,
                                    counts_per_rev=1 << 20, watchdog_timeout=0.3))
            if not restore:
                host._restore.clear()  # the host before the fix
        finally:
            host.close()
        # twice the consumer timeout without a fault; a fault is waited for (the drive's check runs in a thread
        # this loaded process may not schedule within a fixed sleep)
        deadline = time.monotonic() + (0.6 if restore else 10.0)
        while sim.state is not c.State.FAULT and time.monotonic() < deadline:
            time.sleep(0.01)
        assert (sim.state is c.State.FAULT) == (not restore), sim.state
    finally:
        sim.close()
        network.disconnect()
