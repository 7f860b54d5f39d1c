"""ODrive over CAN Simple: encodings, and the host driver against the simulated ODrive (virtual bus, and a
separate process on udp_multicast)."""

import math
import random
import select
import subprocess
import sys
import time
import uuid

import can
import h5py
import numpy as np
import pytest

from hilbench.drivers import odrive_can as o
from hilbench.drivers import protocol as p
from hilbench.drivers.device_url import open_device
from hilbench.drivers.errors import CommandRefusedError, DeviceFaultError, DeviceTimeoutError
from hilbench.drivers.odrive_drive import OdriveDrive
from hilbench.firmware_sim.devices.odrive_sim import TVL_ENDPOINT, SimOdrive
from hilbench.firmware_sim.devices.sim_config import load_sim_config

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]  # starts a device
@pytest.mark.device_free  # no drive: the parallel part
def test_ids_and_errors():
    assert o.can_id(3, o.Cmd.SET_INPUT_TORQUE) == 0x06E  # 3 << 5 | 0x0E
    assert o.split_id(0x06E) == (3, 0x0E)
    assert o.describe_errors(0x4800) == "watchdog timer expired, e-stop requested"
    assert o.describe_errors(0x10800) == "watchdog timer expired, 0x00010000"


def test_simulated_torque_mode_velocity_limiter_is_what_the_host_turns_off():
    bus = can.Bus(interface="virtual", channel=uuid.uuid4().hex)
    sim = SimOdrive(bus, 1, load_sim_config())
    try:
        sim.input_torque, sim.vel_limit = 1.0, 10.0  # N*m, turns/s
        w = 2 * math.pi
        assert sim._torque(5 * w) == 1.0             # far from the limit: untouched
        assert sim._torque(9.5 * w) == pytest.approx(0.5)  # half way through the last 10 %: halved
        assert sim._torque(-9.5 * w) == 1.0          # braking torque is not limited
        assert sim._torque(11 * w) == 0.0
        sim.tvl = False
        assert sim._torque(9.5 * w) == 1.0
    finally:
        sim.close()
        bus.shutdown()


@pytest.fixture
def odrive():
    channel = uuid.uuid4().hex[:8]
    bus = can.Bus(interface="virtual", channel=channel)
    sim = SimOdrive(bus, 3, load_sim_config(), watchdog_timeout=1.0)  # in-process the GIL can stall 0.1 s
    host = OdriveDrive("virtual", channel, 3, TVL_ENDPOINT, timeout=1.0)
    yield sim, host
    host.close()
    sim.close()
    bus.shutdown()


def config(**kw) -> p.Config:
    return p.Config(**{"sample_rate": 1000, "current_limit": 20.0, "torque_constant": 0.2,
                       "counts_per_rev": 1 << 20, "watchdog_timeout": 0.5, **kw})


def test_stream_commands_reach_the_axis_and_samples_come_back(odrive):
    sim, host = odrive
    host.configure(config(velocity_limit=300.0))  # rad/s
    assert sim.tvl is False and sim.current_limit == 20.0
    assert sim.vel_limit == pytest.approx(300 / (2 * math.pi), rel=1e-6)  # turns/s, float32 on the wire
    host.arm()
    u = np.linspace(-6.0, 6.0, 1500)  # A
    blocks = list(host.stream(u))
    cmd = np.concatenate([b.torque_cmd for b in blocks])
    position = np.concatenate([b.position for b in blocks])
    cycle = np.concatenate([b.cycle for b in blocks])
    np.testing.assert_array_equal(cycle, np.arange(cycle.size))
    assert cycle.size > 0.5 * u.size  # the drive's ticks during the stream (its own clock)
    # every torque target the drive reports is a command the host sent (float32), or 0 before the first
    sent = set((u * 0.2).astype(np.float32).tolist()) | {0.0}
    assert set(cmd.astype(np.float32).tolist()) <= sent
    assert np.ptp(position) > 0.1  # rad: it moved
    assert host.timing is not None and host.timing.cycles == u.size


@pytest.mark.device_free  # no drive: the parallel part
def test_absent_odrive_is_one_line():
    channel = uuid.uuid4().hex[:8]
    bus = can.Bus(interface="virtual", channel=channel)
    try:
        with pytest.raises(DeviceTimeoutError) as err:
            OdriveDrive("virtual", channel, 9, TVL_ENDPOINT, timeout=0.3)
        assert str(err.value) == "ODrive node 9 did not answer: no heartbeat (CAN id 0x121) within 0.3 s"
    finally:
        bus.shutdown()


def test_watchdog_latches_until_clear_errors(odrive):
    sim, host = odrive
    sim.watchdog_timeout = 0.2
    host.configure(config())
    host.arm()
    host._stop_feed()  # the host falls silent
    host._wait_heartbeat(lambda: host.axis_error != 0, "watchdog")
    assert host.axis_error == o.WATCHDOG_TIMER_EXPIRED and sim.state == o.AxisState.IDLE
    with pytest.raises(CommandRefusedError, match="watchdog timer expired"):
        host.stream(np.zeros(10))
    with pytest.raises(DeviceFaultError, match="`hilbench fault clear --device URL`"):
        host.arm()
    host.clear_faults()
    host.arm()
    assert sim.state == o.AxisState.CLOSED_LOOP_CONTROL


def test_a_host_descheduled_as_its_stream_ends_leaves_the_axis_fed(odrive):
    """Only host commands feed the ODrive's watchdog. After the cycle's last command the host's own feed took over
    when the stream loop next ran; a host descheduled then for longer than the watchdog timeout (a loaded machine:
    the run file's writer, here the consumer of the stream, stalled) left the axis unfed, and it latched
    WATCHDOG_TIMER_EXPIRED after a complete run (the next run refused to arm). The cycle now repeats zero torque
    from its last command until the host has taken over."""
    sim, host = odrive
    host.configure(config())
    host.arm()
    n = 300  # 0.3 s at 1 kHz
    blocks = host.stream(np.full(n, 0.5))
    got = len(next(blocks))
    time.sleep(n / 1000 + 2 * sim.watchdog_timeout)  # the whole stream and twice the timeout after it, unscheduled
    assert sim.error == 0 and sim.state == o.AxisState.CLOSED_LOOP_CONTROL, o.describe_errors(sim.error)
    got += sum(len(b) for b in blocks)
    assert got == n and host.axis_error == 0
    assert sim.input_torque == 0.0  # the stream's end: zero torque, still fed
    host.disarm()


def test_estop_mid_stream(odrive):
    sim, host = odrive
    host.configure(config())
    host.arm()
    stream = host.stream(np.full(5000, 2.0))
    next(stream)
    host.estop()
    with pytest.raises(DeviceFaultError, match="e-stop requested"):
        for _ in stream:
            pass
    assert sim.state == o.AxisState.IDLE and sim.error & o.ESTOP_REQUESTED


@pytest.mark.parametrize("url, words", [
    ("odrive://virtual/x?node=1", "tvl_endpoint=ID is required"),
    ("odrive://virtual/x?node=64&tvl_endpoint=394", "node must be 0..63"),
])
def test_bad_odrive_urls(url, words):
    with pytest.raises(ValueError, match=words):
        open_device(url)


def test_cli_run_against_the_odrive_process(tmp_path):
    port = random.randint(40000, 60000)
    group = f"239.{random.randint(1, 254)}.{random.randint(1, 254)}.{random.randint(1, 254)}"
    sim = subprocess.Popen([sys.executable, "-m", "hilbench", "sim", "--odrive", group, "--interface", "udp_multicast",
                            "--node", "2", "--udp-port", str(port)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
    try:
        ready, _, _ = select.select([sim.stdout], [], [], 60)
        assert ready, "the simulated ODrive did not start"
        url = sim.stdout.readline().strip()
        assert url == f"odrive://udp_multicast/{group}?node=2&tvl_endpoint={TVL_ENDPOINT}&port={port}"
        out = tmp_path / "od.h5"
        done = subprocess.run([sys.executable, "-m", "hilbench", "run", "identify", "--device", url,
                               "--sample-rate", "1000", "--duration", "3", "--quiet", "-o", str(out)],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        refused = subprocess.run([sys.executable, "-m", "hilbench", "run", "identify", "--device", url,
                                  "--sample-rate", "2000", "--quiet", "-o", str(tmp_path / "r.h5")],
                                 capture_output=True, text=True, timeout=120)
        assert refused.returncode == 2 and "cannot run current mode at 2000 Hz" in refused.stderr
    finally:
        sim.terminate()
        sim.wait(10)
    with h5py.File(out) as f:
        assert f.attrs["status"] == "completed"
        n = f["samples/t"].size
        host_time = f["samples/host_time"][:]
        events = [e["message"].decode() for e in f["events"][:]]
    assert 2700 < n <= 3000 and np.all(np.diff(host_time) >= 0)
    assert any(e.startswith("host-clocked timing: 3000 cycles at 1000 Hz") for e in events)
