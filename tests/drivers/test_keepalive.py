"""The host-clocked cycle's zero-torque keepalive (drivers/host_cycle.py): it feeds a drive's watchdog after the
stream's last command only until the host takes over, never after the host's stop or death, and never for longer
than keepalive_limit; disarm() joins the cycle before its stop, so no keepalive frame re-enables a stopped drive."""

import os
import threading
import time
import uuid

import can
import numpy as np
import pytest

from hilbench.common.runfile.schema import HOST_TIME
from hilbench.drivers import host_cycle as hc
from hilbench.drivers import odrive_can as o
from hilbench.drivers import protocol as p
from hilbench.drivers.moteus_drive import MoteusDrive
from hilbench.drivers.odrive_drive import OdriveDrive
from hilbench.firmware_sim.devices.moteus_sim import SimMoteus
from hilbench.firmware_sim.devices.odrive_sim import TVL_ENDPOINT, SimOdrive
from hilbench.firmware_sim.devices.sim_config import load_sim_config

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]

TX, RX, END = 0x10, 0x11, b"\x00" * 4  # command id, answer id, the zero-torque end frame
FEED = 0.02  # s: the keepalive period the drivers use (host_clocked.FEED_PERIOD)


class FakeBus:
    """A bus the cycle sends on: each command is answered at once (unless ``answer`` is False: a drive that lags);
    ``on_recv(bus)`` runs in each receive once the last command is out and answered, which otherwise waits out its
    timeout. ``log``: (time, what) in order."""

    def __init__(self, on_recv=None, answer: bool = True) -> None:
        self.log: list[tuple[float, str]] = []
        self.answers: list[can.Message] = []
        self.on_recv, self.answer, self.ctl, self.n = on_recv, answer, None, 0

    def send(self, msg: can.Message) -> None:
        kind = "end" if bytes(msg.data) == END else "command"
        self.log.append((time.monotonic(), kind))
        if kind == "command" and self.answer:
            self.answers.append(can.Message(arbitration_id=RX, data=bytes(8), is_extended_id=False))

    def recv(self, timeout: float | None = None):
        if self.answers:
            return self.answers.pop(0)
        if self.on_recv is not None and self.ctl[hc._SENT] >= self.n:
            self.on_recv(self)
        time.sleep(timeout or 0.0)
        return None


def run_cycle(bus: FakeBus, watchdog_timeout: float, parent: int = 0, n: int = 5) -> tuple[np.ndarray, float]:
    """Run the cycle's loop over ``bus`` in a thread until it returns by itself (at most 10 s): its control
    slots and the time of its last trigger."""
    spec = hc.CanCycleSpec(interface="fake", channel="", bus_kwargs={}, rate=1000.0, tx_ids=(TX,), tx_len=(4,),
                           rx_ids=(RX,), stop_data=(END,), end_data=(END,), keepalive=FEED,
                           watchdog_timeout=watchdog_timeout)
    ctl, host_time, scheduled = np.zeros(hc._RX + 1, "i8"), np.zeros(n), np.zeros(n)
    bus.ctl, bus.n = ctl, n
    tx = np.ones((n, 1, 8), "u1")
    received = (np.zeros((1, n, 8), "u1"), np.zeros((1, n)))
    worker = threading.Thread(target=hc._cycle_loop, args=(bus, spec, n, 0.0, ctl, host_time, scheduled, received,
                                                           tx, parent), daemon=True)
    worker.start()
    worker.join(10.0)
    assert not worker.is_alive(), "the keepalive went on feeding a stalled host's drive for 10 s"
    ctl[hc._STOP] = 1
    return ctl, float(host_time[n - 1])


@pytest.mark.device_free
@pytest.mark.parametrize("timeout, limit", [(0.1, 1.5), (0.8, 2.4), (2.0, 3.0), (0.0, 3.0)])
def test_keepalive_limit_is_a_few_watchdog_timeouts_within_bounds(timeout, limit):
    assert hc.keepalive_limit(timeout) == pytest.approx(limit)


@pytest.mark.device_free
def test_a_stalled_host_is_fed_only_up_to_the_keepalive_limit():
    """The host never stops the cycle (stalled): the keepalive ends keepalive_limit after the last trigger, and
    feeds every FEED until then (before: up to TAIL_LIMIT, 60 s)."""
    bus = FakeBus()
    _, last = run_cycle(bus, watchdog_timeout=0.1)
    feeds = np.array([t for t, kind in bus.log if kind == "end"]) - last
    limit = hc.keepalive_limit(0.1)
    assert feeds[-1] <= limit + 1e-3 and feeds[-1] > limit - FEED - 0.1, feeds[-1]
    assert np.max(np.diff(feeds)) < FEED + 0.1  # fed throughout (a loaded host's slack): the descheduled host's case


@pytest.mark.device_free
def test_no_feed_follows_the_hosts_stop_that_came_during_a_receive():
    """The host's stop (and its stop frame) lands while the cycle waits in recv: no zero torque may follow it
    (moteus's zero torque is a position command, which would switch the stopped drive back on)."""
    def stop_once(bus: FakeBus) -> None:
        if bus.ctl[hc._DONE] and not bus.ctl[hc._STOP]:
            bus.ctl[hc._STOP] = 1
            bus.log.append((time.monotonic(), "host stop"))

    bus = FakeBus(stop_once)
    run_cycle(bus, watchdog_timeout=0.1)
    kinds = [kind for _, kind in bus.log]
    assert "host stop" in kinds and "end" not in kinds[kinds.index("host stop"):], kinds[-5:]


@pytest.mark.device_free
def test_no_feed_for_a_host_that_died_while_its_drive_still_answered(monkeypatch):
    """The parent dies after the last trigger, while the cycle still collects answers (the tail): the feed stops
    at once in the tail too (before: fed until the tail ended, the orphan check sat only in the last loop)."""
    real = os.getppid()
    dead: list[float] = []

    def dies(bus: FakeBus) -> None:
        if not dead:
            dead.append(time.monotonic())

    monkeypatch.setattr(os, "getppid", lambda: 1 if dead else real)
    bus = FakeBus(dies, answer=False)  # no answer yet: the cycle waits in its tail (1 s of quiet)
    run_cycle(bus, watchdog_timeout=0.1, parent=real)
    after = [t for t, kind in bus.log if kind == "end" and t > dead[0]]
    assert dead and not after, f"{len(after)} feeds after the host died"


# ---------------------------------------------------------------- against the simulated drives

def odrive_pair():
    channel = uuid.uuid4().hex[:8]
    bus = can.Bus(interface="virtual", channel=channel)
    sim = SimOdrive(bus, 3, load_sim_config(), watchdog_timeout=0.5)
    host = OdriveDrive("virtual", channel, 3, TVL_ENDPOINT, timeout=1.0)
    host.configure(p.Config(sample_rate=1000, current_limit=20.0, torque_constant=0.2, counts_per_rev=1 << 20,
                            watchdog_timeout=0.5))
    return channel, bus, sim, host, 0.5, lambda: sim.error & o.WATCHDOG_TIMER_EXPIRED


def moteus_pair():
    channel = f"m-{uuid.uuid4().hex[:8]}"
    bus = can.Bus(interface="virtual", channel=channel)
    sim = SimMoteus(bus, 1, load_sim_config(), clock="sync")
    host = MoteusDrive("virtual", channel, 1, timeout=1.0)
    host.configure(p.Config(sample_rate=1000, current_limit=20.0, torque_constant=0.2, counts_per_rev=1 << 20,
                            watchdog_timeout=0.5))
    return channel, bus, sim, host, sim.default_timeout, lambda: not sim.energised()


@pytest.fixture(params=["odrive", "moteus"])
def drive(request):
    channel, bus, sim, host, timeout, tripped = (odrive_pair if request.param == "odrive" else moteus_pair)()
    yield request.param, channel, sim, host, timeout, tripped
    host.close()
    sim.close()
    bus.shutdown()


def test_a_host_stalled_after_its_stream_leaves_the_drive_to_its_watchdog(drive):
    """The host stalls for good after its stream's first block: the cycle feeds up to keepalive_limit after the
    last command, then the drive's watchdog trips within its timeout (before: fed for 60 s)."""
    _, _, _, host, timeout, tripped = drive
    host.arm()
    n = 200
    blocks = host.stream(np.full(n, 0.5))
    next(blocks)
    cycle = host._cycle
    while cycle.sent < n:
        time.sleep(0.01)
    last = float(cycle.arrays[HOST_TIME][n - 1])  # the last command (its bus echo where there is one)
    limit = hc.keepalive_limit(0.5)
    while not tripped() and time.monotonic() - last < limit + timeout + 3.0:
        time.sleep(0.005)
    waited = time.monotonic() - last
    blocks.close()
    # fed up to the limit (a 1 s stall leaves the drive fed), then its watchdog (+ the ODrive's heartbeat period)
    assert limit - 0.05 < waited < limit + timeout + 1.0, waited  # 1 s: a loaded host's slack


def test_disarm_during_the_keepalive_sends_no_feed_after_its_stop(drive, monkeypatch):
    """disarm() while the cycle feeds after the stream: the cycle is joined before the stop, so no zero-torque
    frame follows it on the bus. The cycle's bus is made deaf once it only feeds, so that it wakes at its feed
    times only (as a quiet drive's bus does): before, its next feed followed the stop within 20 ms every time."""
    name, channel, sim, host, _, _ = drive
    opened = hc._open_bus

    def deaf_when_done(spec, ctl):
        bus = opened(spec, ctl)
        hear = bus.recv

        def recv(timeout=None):
            if ctl[hc._DONE]:
                time.sleep(timeout or 0.0)
                return None
            return hear(timeout)

        bus.recv = recv
        return bus

    monkeypatch.setattr(hc, "_open_bus", deaf_when_done)
    host.arm()
    blocks = host.stream(np.full(50, 0.5))
    next(blocks)
    cycle = host._cycle
    while not cycle.arrays["ctl"][hc._DONE]:
        time.sleep(0.002)
    listener = can.Bus(interface="virtual", channel=channel)
    try:
        time.sleep(0.05)  # the keepalive feeds
        host.disarm()
        assert not cycle.alive()  # joined before the stop went out, not left to wake after it
        time.sleep(0.1)   # five feed periods
        frames = []
        while (msg := listener.recv(0)) is not None:
            frames.append(msg)
    finally:
        listener.shutdown()
    if name == "odrive":
        torque, idle = o.can_id(3, o.Cmd.SET_INPUT_TORQUE), o.can_id(3, o.Cmd.SET_AXIS_STATE)
        ids = [m.arbitration_id for m in frames]
        assert torque in ids and idle in ids
        assert torque not in ids[ids.index(idle):], "a keepalive frame followed the IDLE command"
    else:
        stop, feed = (bytes(host._message(m).data) for m in (host.controller.make_stop(), host._zero_torque()))
        data = [bytes(m.data) for m in frames]
        assert feed in data and stop in data
        assert feed not in data[data.index(stop):], "a zero-torque position command followed the stop"
        assert not sim.energised()  # still stopped
    blocks.close()
