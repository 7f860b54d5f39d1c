"""CiA 402 over CANopen: the host driver against the simulated LocalNode drive on python-can's virtual bus.

The drive runs with ``clock="sync"`` (its plant advances exactly one cycle per SYNC), so what the host
records can be checked sample for sample against the C plant run directly (the oracle shares no code with
the CANopen layers).
"""

import threading
import time
import uuid

import canopen
import h5py
import numpy as np
import pytest

from hilbench.bench.acquisition.protocols import Identification
from hilbench.bench.acquisition.runner import Bench, DeviceSettings
from hilbench.drivers import cia402 as c
from hilbench.drivers import protocol as p
from hilbench.drivers.canopen_drive import CanopenDrive
from hilbench.drivers.device_url import open_device
from hilbench.drivers.errors import (
    CommandRefusedError,
    ConfigError,
    DeviceFaultError,
    DeviceTimeoutError,
    SampleLossError,
)
from hilbench.firmware_sim.devices.cia402_drive import EDS_PATH, SimCia402Drive
from hilbench.firmware_sim.devices.sim_config import load_sim_config, substeps_for
from hilbench.firmware_sim.engine.plant import simulate

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]  # starts a device
KT, RATED, CPR = 0.2, 0.5, 1 << 20  # N*m/A, N*m (EDS 0x6076), counts/rev (EDS 0x608F)


class Bus:
    """A virtual bus with one simulated drive on it."""

    def __init__(self, node: int = 3, **drive_options) -> None:
        self.channel = f"t-{uuid.uuid4().hex[:8]}"
        self.network = canopen.Network()
        self.network.connect(interface="virtual", channel=self.channel)
        self.sim = load_sim_config()
        options = {"sync_timeout": 1.0, **drive_options}  # in-process the GIL can stall the cycle for 0.1 s
        self.drive = SimCia402Drive(self.network, node, self.sim, clock="sync", **options)
        self.node = node

    def host(self, timeout: float = 1.0) -> CanopenDrive:
        return CanopenDrive("virtual", self.channel, self.node, str(EDS_PATH), timeout=timeout)

    def close(self) -> None:
        self.drive.close()
        self.network.disconnect()


@pytest.fixture
def bus():
    b = Bus()
    yield b
    b.close()


def config(rate: int = 1000, **kw) -> p.Config:
    values = {"sample_rate": rate, "current_limit": 20.0, "torque_constant": KT, "counts_per_rev": CPR,
              "watchdog_timeout": 0.5, **kw}
    return p.Config(**values)


def test_stream_matches_the_plant_sample_for_sample(bus):
    host = bus.host()
    try:
        host.configure(config())
        host.arm()
        assert host.power_state() is c.State.OPERATION_ENABLED
        n = 600
        u = 6.0 * np.sin(2 * np.pi * 3 * np.arange(n) / 1000) + 2.0  # A: presliding and sliding
        t_before = time.monotonic()
        blocks = list(host.stream(u))
        t_after = time.monotonic()
    finally:
        host.close()
    got = {k: np.concatenate([getattr(b, k) for b in blocks]) for k in ("cycle", "counts", "torque", "torque_cmd",
                                                                         "host_time")}
    np.testing.assert_array_equal(got["cycle"], np.arange(n))
    # every host time is SYNC k's own echo from the bus (its timestamp on the host's monotonic clock)
    assert host.timing.echoed == n and f"host times from the bus for {n} of {n} cycles" in host.timing.line()
    assert t_before < got["host_time"][0] and got["host_time"][-1] < t_after and np.all(np.diff(got["host_time"]) > 0)
    # oracle: the plant at 10 kHz (the drive's oversampling), the per-mille command held for 10 sub-steps;
    # the drive samples at each SYNC, just before the command received with that SYNC acts
    pm = np.rint(u * KT / RATED * 1000)
    u_applied = pm * RATED / 1000 / KT
    params = bus.sim.plant_for(20.0, KT, CPR)
    dt = 1e-4
    out = simulate(params, np.concatenate([np.zeros(9), np.repeat(u_applied, 10)]), dt, substeps_for(params, dt))
    k = 9 + 10 * np.arange(n)
    np.testing.assert_array_equal(got["counts"], out.counts[k])
    np.testing.assert_allclose(got["torque"], np.rint(out.current_meas[k] * KT / RATED * 1000) * RATED / 1000)
    np.testing.assert_allclose(got["torque_cmd"], pm * RATED / 1000)
    assert np.ptp(got["counts"]) > CPR / 10  # it really moved


def test_a_lost_tpdo_is_reported_as_sample_loss_not_as_the_drive_leaving_operation(bus):
    """The drive does not answer SYNC 300 (a frame lost on a loaded host). The answer to the end-of-stream SYNC,
    sent after SWITCH_ON, then arrives where cycle 599's TPDO should be. It said "left operation enabled at cycle
    599: switched on"; it is the loss of one TPDO, and no sample may carry that state."""
    calls = []

    def lossy(can_id, data, timestamp):
        calls.append(can_id)
        if len(calls) != 300:
            bus.drive._on_sync(can_id, data, timestamp)

    bus.network.unsubscribe(0x80, bus.drive._on_sync)
    bus.network.subscribe(0x80, lossy)
    host = bus.host()
    blocks = []
    try:
        host.configure(config())
        host.arm()
        with pytest.raises(SampleLossError, match=r"1 of 600 SYNCs got no TPDO back .*shifted"):
            for block in host.stream(np.full(600, 1.0)):
                blocks.append(block)
    finally:
        host.close()
        bus.network.unsubscribe(0x80, lossy)
        bus.network.subscribe(0x80, bus.drive._on_sync)  # what the drive unsubscribes when it closes
    status = np.concatenate([b.status for b in blocks])
    assert status.size == 599
    assert all(c.state_of(int(w)) is c.State.OPERATION_ENABLED for w in status)


def test_absent_node_is_one_line_naming_node_and_what_timed_out(bus):
    with pytest.raises(DeviceTimeoutError) as err:
        CanopenDrive("virtual", bus.channel, 9, str(EDS_PATH), timeout=0.3)
    msg = str(err.value)
    assert "node 9" in msg and "0x1000" in msg and "timed out" in msg and "\n" not in msg


def test_drive_without_cst_is_refused_in_one_line():
    b = Bus(supported_modes=0x0000_0085)  # profile position, profile velocity, CSP: no CST
    try:
        with pytest.raises(CommandRefusedError) as err:
            b.host()
        assert "Cyclic Synchronous Torque" in str(err.value) and "0x00000085" in str(err.value)
    finally:
        b.close()


def test_protocol_the_drive_cannot_run_is_refused_before_anything_moves(bus, tmp_path):
    host = bus.host()
    writes = []
    bus.drive.node.add_write_callback(lambda **kw: writes.append(kw["index"]))
    try:
        bench = Bench(host, "canopen://virtual/x?node=3")
        for proto, words in ((Identification(duration=1, mode="velocity", sample_rate=1000, amplitude=1.0),
                              "cannot run velocity mode"),
                             (Identification(duration=1, sample_rate=10000), "at 10000 Hz")):
            with pytest.raises(ConfigError, match=words):
                bench.run(proto, tmp_path / "refused.h5")
        assert not (tmp_path / "refused.h5").exists()
        assert writes == []  # not one SDO reached the drive
        assert bus.drive.state is c.State.SWITCH_ON_DISABLED
    finally:
        host.close()


def test_emcy_mid_run_marks_the_file_faulted_disables_the_drive_and_loses_no_sample(bus, tmp_path):
    host = bus.host()
    bench = Bench(host, "canopen://virtual/x?node=3", DeviceSettings(watchdog_timeout=0.5))
    path = tmp_path / "emcy.h5"

    def inject():
        while bus.drive.cycle < 300:
            time.sleep(0.005)
        bus.drive.fault(0x2310, 0x02)

    threading.Thread(target=inject, daemon=True).start()
    try:
        with pytest.raises(DeviceFaultError, match="EMCY 0x2310 continuous over-current"):
            bench.run(Identification(duration=3, sample_rate=1000, amplitude=4.0), path)
    finally:
        host.close()
    assert bus.drive.state is c.State.FAULT and bus.drive.u_held == 0.0  # no torque applied
    with h5py.File(path) as f:
        assert f.attrs["status"] == "aborted"
        events = [(e["kind"].decode(), e["message"].decode()) for e in f["events"][:]]
        cycle = f["samples/cycle"][:]
        status = f["samples/drive_status"][:].astype(int)
    assert ("fault", "EMCY 0x2310 continuous over-current (device output side) (error register 0x03)") in events
    # every SYNC up to and including the one that reported the fault is in the file, in order
    np.testing.assert_array_equal(cycle, np.arange(cycle.size))
    assert cycle.size >= 300
    assert c.state_of(status[-1]) is c.State.FAULT
    assert all(c.state_of(w) is c.State.OPERATION_ENABLED for w in status[:-1])


def test_estop_is_a_quick_stop(bus):
    host = bus.host()
    try:
        host.configure(config())
        host.arm()
        stream = host.stream(np.full(3000, 1.0))
        next(stream)
        host.estop()
        with pytest.raises(DeviceFaultError, match="quick stop"):
            for _ in stream:
                pass
        assert bus.drive.state is c.State.SWITCH_ON_DISABLED and bus.drive.u_held == 0.0
    finally:
        host.close()


def test_heartbeat_loss_trips_the_drive_within_its_timeout(bus):
    host = bus.host()
    try:
        host.configure(config(watchdog_timeout=0.1))
        host.arm()
        host._heartbeat_task.stop()  # the host goes silent (no SYNC either: not streaming)
        t0 = time.monotonic()
        while bus.drive.state is c.State.OPERATION_ENABLED and time.monotonic() - t0 < 2.0:
            time.sleep(0.002)
        elapsed = time.monotonic() - t0
        assert bus.drive.state is c.State.FAULT and bus.drive.error_code == 0x8130
        assert elapsed < 0.1 + 0.1  # heartbeat timeout plus the last heartbeat's age and monitor period
        host._emcy_event.wait(1.0)
        assert "0x8130" in host.emcy_line()
        host.clear_faults()
        assert host.power_state() is c.State.SWITCH_ON_DISABLED and not host.emcy_line()
    finally:
        host.close()


def test_configuration_reaches_the_object_dictionary(bus):
    host = bus.host()
    try:
        host.configure(config(rate=2000, current_limit=5.0, watchdog_timeout=0.25))
        raw = bus.drive._raw
        assert raw(c.COMM_CYCLE_PERIOD) == 500  # us
        assert raw(c.MAX_TORQUE) == 2000  # 5 A * 0.2 N*m/A = 1 N*m = 2000 per mille of 0.5 N*m
        assert raw(c.CONSUMER_HEARTBEAT, 1) == (127 << 16) | 250
        assert raw(c.PRODUCER_HEARTBEAT) == 100
        assert bus.drive.mode_display == c.MODE_CST
        assert bus.drive.node.nmt.state == "OPERATIONAL"
        tpdos = {m.cob_id: [v.index for v in m.map] for m in bus.drive._tpdos}
        assert tpdos == {0x180 + 3: [c.STATUSWORD, c.TORQUE_ACTUAL], 0x280 + 3: [c.POSITION_ACTUAL, c.VELOCITY_ACTUAL]}
        assert all(m.trans_type == 1 for m in bus.drive._tpdos)
        assert (raw(c.INTERPOLATION_PERIOD, 1), raw(c.INTERPOLATION_PERIOD, 2)) == (5, -4)  # 0.5 ms
        other = config(counts_per_rev=4096)  # the drive's encoder resolution is adopted, and said (issue #25)
        host.configure(other)
        assert other.counts_per_rev == CPR
        assert any("counts_per_rev 4096 replaced by the drive's encoder resolution 0x608F = 1048576" in line
                   for _, line in host.run_events())
    finally:
        host.close()


@pytest.mark.parametrize("url, words", [
    ("canopen://virtual/x?node=3", "eds=FILE is required"),
    ("canopen://virtual/x?node=3&eds=/no/such.eds", "does not exist"),
    (f"canopen://virtual/x?node=300&eds={EDS_PATH}", "node must be 1..126"),
    (f"canopen://virtual?node=3&eds={EDS_PATH}", "INTERFACE/CHANNEL"),
    (f"canopen://virtual/x?node=3&eds={EDS_PATH}&speed=1", "unknown option"),
])
def test_bad_canopen_urls(url, words):
    with pytest.raises(ValueError, match=words):
        open_device(url)


def test_polling_the_drive_state_while_it_is_configured_never_mixes_sdo_transfers(bus):
    # the GUI polls live_state() from its device thread while the run thread configures the drive
    host = bus.host()
    stop, errors = threading.Event(), []

    def poll() -> None:
        while not stop.is_set():
            try:
                host.live_state()
            except Exception as exc:  # noqa: BLE001 - every failure counts
                errors.append(exc)

    poller = threading.Thread(target=poll)
    poller.start()
    try:
        for _ in range(3):
            host.configure(config())
    finally:
        stop.set()
        poller.join()
        host.close()
    assert not errors, errors[0]
