"""Watchdog, e-stop, limit trips and buffer underrun, end to end against the simulator process."""

import math
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from hilbench.drivers import protocol as p
from hilbench.drivers.amplifier import Amplifier
from hilbench.drivers.errors import DeviceFaultError
from hilbench.drivers.links import SerialLink

ROOT = Path(__file__).resolve().parents[2]

KILLED_HOST = r"""
import sys, numpy as np
from hilbench.drivers.amplifier import Amplifier
from hilbench.drivers.links import SerialLink
from hilbench.drivers import protocol as p
amp = Amplifier(SerialLink(sys.argv[1]))
amp.configure(p.Config(sample_rate=1000, current_limit=3.0, watchdog_timeout=0.2, torque_constant=0.2,
                       counts_per_rev=4096))
amp.arm()
for blk in amp.stream(np.full(60000, 0.5)):
    print(blk.first_index + len(blk) - 1, flush=True)
"""


def collect(amp, setpoints):
    blocks = []
    with pytest.raises(DeviceFaultError) as info:
        for blk in amp.stream(setpoints):
            blocks.append(blk)
    return blocks, info.value


@pytest.mark.usefixtures("starts_devices")  # a real-time simulator: the serial part
def test_watchdog_after_sigkill_of_the_host(simulator, sim_toml):
    rate, timeout = 1000, 0.2
    _, path = simulator(pacing="realtime", config=sim_toml())
    host = subprocess.Popen([sys.executable, "-c", KILLED_HOST, path], stdout=subprocess.PIPE)
    last_seen = -1
    for line in host.stdout:
        last_seen = int(line)
        if last_seen >= 300:  # 0.3 s into the stream
            break
    host.send_signal(signal.SIGKILL)
    host.wait()
    host.stdout.close()
    assert last_seen >= 300
    time.sleep(0.5)
    with Amplifier(SerialLink(path)) as amp:  # a new host connection
        status = amp.status()
        print(f"watchdog: silence {status.fault_silence} samples, fault at {status.fault_index}, "
              f"host last saw {last_seen}")
        assert status.faults == p.Fault.WATCHDOG
        assert status.state == p.State.DISARMED
        assert status.current_applied == 0.0
        # the current was zeroed within the watchdog timeout plus one sample period of host silence
        # (device time; the floors of the two time->index conversions allow one more sample)
        assert status.fault_silence <= math.ceil(timeout * rate) + 1 + 1
        assert status.fault_silence >= math.floor(timeout * rate)
        # and in device time after the last block the killed host saw: the host's last message is at most
        # a heartbeat period (0.05 s) plus a device tick before that, slack 0.1 s for scheduling
        assert (status.fault_index - last_seen) / rate <= timeout + 1 / rate + 0.1
        with pytest.raises(DeviceFaultError, match="WATCHDOG.*hilbench fault clear"):
            amp.arm()
        amp.clear_faults()
        assert amp.status().faults == 0
        amp.arm()
        blocks = list(amp.stream(np.full(200, 0.1)))
        assert sum(len(b) for b in blocks) == 200


@pytest.mark.usefixtures("starts_devices")  # a real-time simulator: the serial part
def test_estop_from_another_thread_during_stream(simulator, sim_toml):
    _, path = simulator(pacing="realtime", config=sim_toml())
    with Amplifier(SerialLink(path)) as amp:
        amp.configure(p.Config(sample_rate=2000, current_limit=3.0, torque_constant=0.2, counts_per_rev=4096))
        amp.arm()
        blocks = []

        def consume():
            try:
                for blk in amp.stream(np.full(20000, 1.0)):  # 10 s; e-stop comes after ~0.2 s
                    blocks.append(blk)
            except DeviceFaultError as exc:
                blocks.append(exc)

        worker = threading.Thread(target=consume)
        worker.start()
        while sum(len(b) for b in blocks if not isinstance(b, Exception)) < 400:
            time.sleep(0.005)
        t0 = time.monotonic()
        amp.estop()
        worker.join(timeout=5)
        assert not worker.is_alive() and time.monotonic() - t0 < 1.0
        error = blocks.pop()
        assert isinstance(error, DeviceFaultError) and error.faults == p.Fault.ESTOP
        last = blocks[-1]
        assert last.current_cmd[-1] == 0.0
        assert last.status[-1] == p.SampleStatus.FAULT | p.SampleStatus.END
        assert np.all(np.concatenate([b.current_cmd for b in blocks])[:-1] == 1.0)
        status = amp.status()
        assert status.faults == p.Fault.ESTOP and status.current_applied == 0.0
        with pytest.raises(DeviceFaultError, match="ESTOP"):
            amp.arm()
        amp.clear_faults()
        amp.arm()


def test_over_speed_trip(simulator, sim_toml):
    _, path = simulator(pacing="lockstep", config=sim_toml(noise_current=0.0))
    limit = 5.0
    with Amplifier(SerialLink(path)) as amp:
        config = p.Config(sample_rate=5000, current_limit=8.0, velocity_limit=limit, torque_constant=0.2,
                          counts_per_rev=4096)
        amp.configure(config)
        amp.arm()
        blocks, error = collect(amp, np.full(20000, 7.0))
    assert error.faults == p.Fault.OVER_SPEED
    counts = np.concatenate([b.counts for b in blocks])
    cmd = np.concatenate([b.current_cmd for b in blocks])
    # independent recomputation of the documented estimate: 1 ms window (W = 5 samples at 5 kHz), the
    # motor at rest at the first count before the stream
    w = 5
    k = np.arange(len(counts))
    v = (counts - counts[np.maximum(k - w, 0)]) * 2 * math.pi / 4096 / (w / 5000)
    j = len(counts) - 1
    assert abs(v[j]) > limit and np.all(np.abs(v[:j]) <= limit)
    assert cmd[j] == 0.0 and np.all(cmd[:j] == 7.0)


def test_position_window_trip(simulator, sim_toml):
    _, path = simulator(pacing="lockstep", config=sim_toml(noise_current=0.0))
    with Amplifier(SerialLink(path)) as amp:
        amp.configure(p.Config(sample_rate=5000, current_limit=8.0, velocity_limit=1e4, position_min=-0.1,
                               position_max=0.05, torque_constant=0.2, counts_per_rev=4096))
        amp.arm()
        blocks, error = collect(amp, np.full(20000, 7.0))
    assert error.faults == p.Fault.POSITION_WINDOW
    position = np.concatenate([b.position for b in blocks])
    assert position[-1] > 0.05 and np.all(position[:-1] <= 0.05)
    assert blocks[-1].current_cmd[-1] == 0.0


def test_over_current_trip_on_measured_current(simulator, sim_toml):
    # injected current noise of 0.3 A rms around 0.5 A must exceed the 1 A limit within 2000 samples
    # (P(no excursion) = Phi(0.5/0.3)^2000 ~ 1e-41)
    _, path = simulator(pacing="lockstep", config=sim_toml(noise_current=0.3))
    with Amplifier(SerialLink(path)) as amp:
        amp.configure(p.Config(sample_rate=1000, current_limit=1.0, torque_constant=0.2, counts_per_rev=4096))
        amp.arm()
        blocks, error = collect(amp, np.full(2000, 0.5))
    assert error.faults == p.Fault.OVER_CURRENT
    meas = np.concatenate([b.current_meas for b in blocks])
    assert abs(meas[-1]) > 1.0 and np.all(np.abs(meas[:-1]) <= 1.0)
    assert blocks[-1].current_cmd[-1] == 0.0


def test_over_current_trip_on_a_command_beyond_the_limit(simulator):
    # the host refuses such setpoints; a raw link bypasses it to check the device's own limit
    _, path = simulator(pacing="lockstep")
    link = SerialLink(path)
    try:
        link.send(p.Config(sample_rate=1000, current_limit=1.0))
        link.send(p.Arm())
        link.send(p.SetpointBlock(0, np.array([0.5, 0.9, 1.5, 0.5]), end=True))
        blk = wait_for(link, p.SampleBlock)
        assert blk.first_index == 0 and len(blk) == 3
        assert list(blk.current_cmd) == [0.5, np.float32(0.9), 0.0]
        assert blk.faults == p.Fault.OVER_CURRENT
    finally:
        link.close()


def wait_for(link, cls, timeout=3.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        msg = link.recv(0.1)
        if isinstance(msg, cls):
            return msg
    raise AssertionError(f"no {cls.__name__} within {timeout} s")


@pytest.mark.usefixtures("starts_devices")  # a real-time simulator: the serial part
def test_buffer_underrun(simulator):
    _, path = simulator(pacing="realtime")
    link = SerialLink(path)
    try:
        link.send(p.Config(sample_rate=1000, current_limit=2.0, watchdog_timeout=2.0))
        link.send(p.Arm())
        link.send(p.SetpointBlock(0, np.full(100, 0.3), end=False))  # 0.1 s of setpoints, then nothing
        samples = []
        while not samples or not samples[-1].status[-1] & p.SampleStatus.END:
            samples.append(wait_for(link, p.SampleBlock))
        counts = sum(len(s) for s in samples)
        cmd = np.concatenate([s.current_cmd for s in samples])
        assert counts == 101  # the 100 setpoints, then the first sample without one: zero current
        assert np.all(cmd[:100] == np.float32(0.3)) and cmd[100] == 0.0
        assert samples[-1].faults == p.Fault.BUFFER_UNDERRUN
        assert samples[-1].status[-1] == p.SampleStatus.FAULT | p.SampleStatus.END
    finally:
        link.close()


@pytest.mark.usefixtures("starts_devices")  # a real-time simulator: the serial part
def test_idle_armed_device_trips_watchdog_without_host_traffic(simulator):
    _, path = simulator(pacing="realtime")
    link = SerialLink(path)
    try:
        link.send(p.Config(sample_rate=1000, watchdog_timeout=0.05))
        link.send(p.Arm())
        t0 = time.monotonic()
        status = wait_for(link, p.Status, timeout=2.0)  # unsolicited, when the fault latches
        assert status.faults == p.Fault.WATCHDOG and status.state == p.State.DISARMED
        assert time.monotonic() - t0 < 0.05 + 0.5
    finally:
        link.close()


@pytest.mark.usefixtures("starts_devices")  # a real-time simulator: the serial part
def test_new_host_is_not_confused_by_what_a_dead_host_left_unread(simulator):
    # host A never reads: its replies and ~0.6 s of sample blocks pile up in the pty and the device
    _, path = simulator(pacing="realtime")
    link = SerialLink(path)
    link.send(p.Config(sample_rate=20000, current_limit=2.0, watchdog_timeout=2.0))
    link.send(p.Arm())
    for seq in range(16):
        link.send(p.SetpointBlock(seq, np.full(512, 0.2)))  # 0.41 s of setpoints, no end flag
    time.sleep(0.6)
    link.close()
    with Amplifier(SerialLink(path)) as amp:
        # the stale Reply(ARM, OK) of host A must not answer this ARM: the device has a latched fault
        with pytest.raises(DeviceFaultError, match="BUFFER_UNDERRUN"):
            amp.arm()
        assert amp.status().faults == p.Fault.BUFFER_UNDERRUN
        assert amp.counters["host_crc_errors"] <= 1  # at most the one frame cut by the flush
