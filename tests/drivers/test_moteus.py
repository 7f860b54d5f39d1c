"""moteus: the host over the moteus library's python-can transport against the simulated controller on python-can's
virtual bus (CAN-FD).

The controller runs with ``clock="sync"`` (its plant advances exactly one period per queried command), so what the
host records is checked sample for sample against the C plant run directly (the oracle shares no code with the
register protocol).
"""

import time
import uuid

import can
import numpy as np
import pytest
from moteus.protocol import Mode

from hilbench.common.can import pad_fd
from hilbench.drivers import protocol as p
from hilbench.drivers.device_url import check_device_url
from hilbench.drivers.errors import (
    CommandRefusedError,
    ConfigError,
    DeviceFaultError,
    DeviceTimeoutError,
    DeviceURLError,
    DriverError,
    PortBusyError,
)
from hilbench.drivers.host_clocked import FEED_PERIOD
from hilbench.drivers.moteus_drive import MoteusDrive, reply_layout
from hilbench.firmware_sim.devices.moteus_sim import DEFAULT_TIMEOUT, SimMoteus
from hilbench.firmware_sim.devices.sim_config import load_sim_config, substeps_for
from hilbench.firmware_sim.engine.plant import simulate

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]  # starts a device
KT, CPR = 0.2, 1 << 20  # N*m/A, counts/rev (the simulated controller's defaults)


class Bus:
    """A virtual bus with one simulated moteus controller on it."""

    def __init__(self, controller: int = 1, **options) -> None:
        self.channel = f"m-{uuid.uuid4().hex[:8]}"
        self.bus = can.Bus(interface="virtual", channel=self.channel)
        self.sim_config = load_sim_config()
        self.sim = SimMoteus(self.bus, controller, self.sim_config, clock="sync", **options)
        self.id = controller

    def host(self, **kw) -> MoteusDrive:
        return MoteusDrive("virtual", self.channel, self.id, timeout=1.0, **kw)

    def close(self) -> None:
        self.sim.close()
        self.bus.shutdown()


@pytest.fixture
def bus():
    b = Bus()
    yield b
    b.close()


def config(**kw) -> p.Config:
    return p.Config(**{"sample_rate": 1000, "current_limit": 20.0, "torque_constant": KT, "counts_per_rev": CPR,
                       "watchdog_timeout": 0.5, **kw})


def test_reply_layout_reads_the_frames_own_headers():
    # mode int8 (0x21 0x00), then 4 float32 from register 1 (long form 0x2c 0x04 0x01), then fault int8 (0x21 0x0f)
    frame = bytes([0x21, 0x00, 10, 0x2C, 0x04, 0x01]) + bytes(16) + bytes([0x21, 0x0F, 0, 0x50])
    assert reply_layout(frame) == {0: (2, 0), 1: (6, 3), 2: (10, 3), 3: (14, 3), 4: (18, 3), 0x0F: (24, 0)}
    assert pad_fd(bytes(9)) == bytes(9) + b"\x50" * 3 and len(pad_fd(bytes(49))) == 64


def test_torque_stream_matches_the_plant_sample_for_sample(bus):
    host = bus.host()
    try:
        assert host.info()["model"] == "0x302" and host.state().startswith("stopped")
        host.configure(config())
        host.arm()
        n = 600
        u = 6.0 * np.sin(2 * np.pi * 3 * np.arange(n) / 1000) + 2.0  # A: presliding and sliding
        t_before = time.monotonic()
        blocks = list(host.stream(u))
        t_after = time.monotonic()
        events = host.run_events()
    finally:
        host.close()
    got = {k: np.concatenate([getattr(b, k) for b in blocks]) for k in ("cycle", "counts", "torque", "torque_cmd",
                                                                         "host_time", "status")}
    np.testing.assert_array_equal(got["cycle"], np.arange(n))
    assert np.all(got["status"] == Mode.POSITION)  # torque commands are position mode with kp = kd = 0
    # every host time is command k's own echo from the bus
    assert host.timing.echoed == n and t_before < got["host_time"][0] < got["host_time"][-1] < t_after
    assert events[0][1].startswith(f"host-clocked timing: {n} cycles at 1000 Hz")
    # oracle: the plant at 10 kHz, each float32 torque command held for 10 sub-steps; the controller samples when
    # command k arrives, just before it acts
    applied = np.float32(u * KT).astype(np.float64) / KT
    params = bus.sim_config.plant_for(20.0, KT, CPR)
    dt = 1e-4
    out = simulate(params, np.concatenate([np.zeros(9), np.repeat(applied, 10)]), dt, substeps_for(params, dt))
    k = 9 + 10 * np.arange(n)
    np.testing.assert_array_equal(got["counts"], out.counts[k])
    np.testing.assert_allclose(got["torque"], np.float32(out.current_meas[k] * KT), rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(got["torque_cmd"], applied * KT)
    assert np.ptp(got["counts"]) > CPR / 10  # it really moved


def test_the_watchdog_stops_the_motor_within_its_default_timeout_until_a_fault_clear(bus):
    host = bus.host()
    try:
        host.configure(config())
        host.arm()
        assert bus.sim.energised()
        # the host falls silent: its clock starts before the stop, which joins the feed thread (a feed may go out
        # while it stops, never after; timed after the join, a feed one period before the stop read 0.07999 s)
        silent = time.monotonic()
        host._stop_feed()
        while bus.sim.energised() and time.monotonic() - silent < 2.0:
            time.sleep(0.002)
        waited = time.monotonic() - silent
        assert bus.sim.mode == Mode.TIMEOUT and bus.sim.torque_held == 0.0
        # the last feed left up to one feed period before the host fell silent: the controller's clock started then
        assert DEFAULT_TIMEOUT - FEED_PERIOD <= waited < DEFAULT_TIMEOUT + 0.2, waited
        assert host.faults() == ["mode 11 (timeout): no command within the controller's watchdog timeout"]
        with pytest.raises(CommandRefusedError, match="not in position mode"):
            host.stream(np.zeros(10))
        with pytest.raises(DeviceFaultError, match="`hilbench fault clear --device URL`"):
            host.arm()
        host.clear_faults()
        assert host.faults() == [] and bus.sim.mode == Mode.STOPPED
        host.arm()
        assert bus.sim.mode == Mode.POSITION
    finally:
        host.close()
    assert bus.sim.mode == Mode.STOPPED  # close stops the controller


def test_a_second_host_is_refused_having_sent_nothing(bus):
    first = bus.host()
    try:
        first.configure(config())
        first.arm()
        commands = bus.sim.commands
        with pytest.raises(PortBusyError, match=r"moteus://virtual/.*\?id=1 is in use by another host \(its commands"):
            bus.host()
        time.sleep(0.05)
        # the first host's feed goes on; nothing else reached the controller (its command count grew by the feed)
        assert bus.sim.mode == Mode.POSITION and bus.sim.commands > commands
    finally:
        first.close()


def test_a_host_limit_stops_the_stream_and_zero_torque_follows(bus):
    host = bus.host()
    try:
        host.configure(config(velocity_limit=20.0))
        host.arm()
        with pytest.raises(DeviceFaultError, match=r"stream stopped by the host at sample \d+: OVER_SPEED \(speed "):
            for _ in host.stream(np.full(3000, 8.0)):
                pass
        deadline = time.monotonic() + 5.0  # the controller takes the frame in its own thread: waited for, not slept
        while bus.sim.torque_held != 0.0 and time.monotonic() < deadline:
            time.sleep(0.005)
        assert bus.sim.mode == Mode.POSITION and bus.sim.torque_held == 0.0  # the feed's zero torque
    finally:
        host.close()


def test_position_mode_tracks_the_setpoint_with_the_hosts_gains(bus):
    with pytest.raises(ConfigError, match=r"position mode needs the controller's own position gains"):
        host = bus.host()
        try:
            host.configure(config(mode=p.Mode.POSITION, position_kp=20.0, position_kd=0.2))
        finally:
            host.close()
    host = bus.host(kp=bus.sim.kp, kd=bus.sim.kd)
    kp, kd = 200.0, 1.5  # A/rad, A*s/rad: 40 N*m/rad and 0.3 N*m*s/rad at the motor (zeta about 0.5)
    try:
        host.configure(config(mode=p.Mode.POSITION, position_kp=kp, position_ki=0.0, position_kd=kd))
        host.arm()
        t = np.arange(3000) / 1000
        target = 1.0 * np.sin(2 * np.pi * 0.5 * t)  # rad
        position = np.concatenate([b.position for b in host.stream(target)])
    finally:
        host.close()
    # a PD loop through friction stops where the spring kp*e meets the friction: |e| <= breakaway / (kp*k_t)
    # (0.019 rad here), plus the lag of a 0.5 Hz sine (under 5 mrad); from the first half second on
    bound = bus.sim_config.plant.breakaway / (kp * KT) + 0.005
    error = np.max(np.abs(position[500:] - target[500:]))
    assert error < bound, (error, bound)
    assert np.ptp(position) > 1.9


def test_absent_controller_is_one_line():
    channel = f"m-{uuid.uuid4().hex[:8]}"
    bus = can.Bus(interface="virtual", channel=channel)
    try:
        with pytest.raises(DeviceTimeoutError) as err:
            MoteusDrive("virtual", channel, 9, timeout=0.3)
        assert str(err.value) == "moteus controller 9 did not answer (query) within 0.3 s"
    finally:
        bus.shutdown()


@pytest.mark.parametrize("url, words", [
    ("moteus://virtual/x?id=0", "id must be 1..126"),
    ("moteus://virtual/x?id=127", "id must be 1..126"),
    ("moteus://virtual/x?kp=-1", "kp must be positive"),
    ("moteus://virtual/x?kd=fast", "kd must be a number"),
    ("moteus://virtual/x?node=1", "unknown option(s) node"),
    ("moteus://virtual", "expected moteus://INTERFACE/CHANNEL"),
])
def test_bad_moteus_urls(url, words):
    with pytest.raises(DeviceURLError, match=words.replace("(", r"\(").replace(")", r"\)")):
        check_device_url(url)


def test_sim_moteus_arguments_reach_the_simulator_or_are_one_line():
    import subprocess
    import sys

    from hilbench.bench.cli import build_parser
    from hilbench.bench.cli.commands.sim import firmware_argv
    from hilbench.firmware_sim.__main__ import build_parser as firmware_parser

    args = build_parser().parse_args(["sim", "--moteus", "239.1.2.3", "--interface", "udp_multicast", "--node", "5",
                                      "--clock", "sync", "--udp-port", "45000"])
    parsed = firmware_parser().parse_args(firmware_argv(args)[3:])  # after python -m hilbench.firmware_sim
    assert (parsed.moteus, parsed.node, parsed.clock, parsed.udp_port) == ("239.1.2.3", 5, "sync", 45000)
    refused = subprocess.run([sys.executable, "-m", "hilbench", "sim", "--moteus", "239.1.2.3", "--interface",
                              "udp_multicast", "--node", "127"], capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2
    assert refused.stderr.strip().splitlines() == ["hilbench sim: error: --node must be 1..126 for --moteus, got 127"]


def test_estop_mid_stream_stops_the_controller_and_latches_until_a_fault_clear(bus):
    host = bus.host()
    try:
        host.configure(config())
        host.arm()
        assert host.live_state()["armed"] and not host.live_state()["streaming"]
        stream = host.stream(np.full(5000, 2.0))
        next(stream)
        host.estop()
        with pytest.raises(DeviceFaultError, match=r"left position mode at sample \d+: e-stop \(stop sent\)"):
            for _ in stream:
                pass
        assert bus.sim.mode == Mode.STOPPED and bus.sim.torque_held == 0.0
        assert host.faults() == ["e-stop requested by the host (stop sent)"]
        with pytest.raises(DeviceFaultError, match="e-stop requested; clear it with"):
            host.arm()
        host.clear_faults()
        host.arm()
        assert bus.sim.mode == Mode.POSITION
    finally:
        host.close()


def test_a_bus_that_cannot_open_is_one_line():
    with pytest.raises(DriverError, match=r"^moteus://nonsense/x\?id=1: cannot open the CAN bus: "):
        MoteusDrive("nonsense", "x", 1, timeout=0.3)
