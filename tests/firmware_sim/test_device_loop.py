"""The simulated device's loop (``firmware_sim.devices.device.serve``) with a scripted transport: the device process
is descheduled for longer than the watchdog timeout while the host keeps talking. A device hears its host in an
interrupt, so that stall must not trip the watchdog; a host that really went silent must."""

import threading
import time

from hilbench.drivers import protocol as p
from hilbench.firmware_sim.devices.core_c import CoreDevice
from hilbench.firmware_sim.devices.device import serve
from hilbench.firmware_sim.devices.sim_config import sim_config_from_dict

SIM = sim_config_from_dict({"plant": {"elements": 2, "seed": 1}})
WATCHDOG = 0.1  # s
STALL = 0.3     # s: three watchdog timeouts


class StallingTransport:
    """Hands the device the host's frames; at poll ``stall_at`` the process is descheduled for ``STALL`` right
    after reading. A live host sends a heartbeat between any two polls (so also in the middle of that stall);
    a silent one sends nothing after its ARM."""

    dropped_frames = 0

    def __init__(self, host_alive: bool, stall_at: int = 3, polls: int = 8) -> None:
        self.host_alive, self.stall_at, self.polls = host_alive, stall_at, polls
        self.pending = [p.Config(sample_rate=1000, current_limit=5.0, torque_constant=0.2, counts_per_rev=4096,
                                 watchdog_timeout=WATCHDOG), p.Arm()]
        self.n = 0
        self.stop = threading.Event()

    def exchange(self, device: CoreDevice, timeout: float) -> None:
        for msg in self.pending:
            device.rx_bytes(p.encode_frame(msg), time.monotonic())
        self.pending.clear()
        self.n += 1
        if self.n == self.stall_at:
            time.sleep(STALL)
        if self.host_alive:
            self.pending.append(p.Heartbeat(0))  # in the pipe, read at the next poll
        if self.n >= self.polls:
            self.stop.set()

    def deliver(self, device: CoreDevice) -> None:
        device.take_bytes()


def run_loop(host_alive: bool) -> dict:
    device = CoreDevice(SIM, "lockstep")
    transport = StallingTransport(host_alive)
    serve(transport, device, stop=transport.stop)  # type: ignore[arg-type]
    return device.status()


def test_a_stall_of_the_device_process_does_not_trip_the_watchdog():
    s = run_loop(host_alive=True)
    assert s["faults"] == 0 and s["state"] == p.State.ARMED, s


def test_a_silent_host_trips_the_watchdog_through_the_same_loop():
    s = run_loop(host_alive=False)
    assert s["faults"] == p.Fault.WATCHDOG and s["state"] == p.State.DISARMED, s
