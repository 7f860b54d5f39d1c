"""#12 items 1 and 2, black box through the wire protocol against the simulator process: a host that stops
talking mid-stream gets a latched fault and zero current, never a dead device, in either pacing."""

import time

import numpy as np
import pytest

from hilbench.drivers import protocol as p
from hilbench.firmware_sim.devices.core_c import CoreDevice
from hilbench.firmware_sim.devices.sim_config import sim_config_from_dict
from tests.firmware.host import Host
from tests.reliability.wire import Wire

pytestmark = pytest.mark.usefixtures("starts_devices")  # starts a device: the serial realtime part of make test


def test_host_gone_with_the_watchdog_off_latches_underrun_and_the_device_lives(simulator):
    """Item 1: watchdog 0, 1 kHz, the host vanishes mid-stream. A 0.5 ms tick consumes the buffer one
    sample at a time, so the tick after the last setpoint always finds the buffer exactly empty (the
    case that crashed with ``need at least one array to concatenate``)."""
    for trial in range(5):
        proc, path = simulator(pacing="realtime", tick="0.0005")
        wire = Wire(path)
        wire.start_stream(rate=1000, watchdog=0.0, current=0.1, n=300)
        wire.drain(0.1)
        wire.close()  # the host is gone: nothing more arrives, nothing is disarmed
        time.sleep(0.6)  # the 300 setpoints ran out after 0.3 s
        assert proc.poll() is None, f"trial {trial}: the simulator died: {proc.stderr.read().decode()[-300:]}"
        wire = Wire(path)
        wire.request(p.GetIdentity())
        status = wire.status()
        wire.close()
        assert status.faults == p.Fault.BUFFER_UNDERRUN, trial
        assert status.state == p.State.DISARMED
        assert status.current_applied == 0.0
        assert status.fault_index == 300  # the first sample without a setpoint is the zero-current one


def test_lockstep_watchdog_trips_with_an_empty_buffer(simulator):
    """Item 2: lockstep pacing computes setpoints as fast as they come; once the host is gone and the
    buffer is empty, the watchdog still zeroes the current and latches WATCHDOG."""
    timeout = 0.2
    proc, path = simulator(pacing="lockstep")
    wire = Wire(path)
    wire.start_stream(rate=1000, watchdog=timeout, current=0.12, n=500)
    wire.drain(0.05)
    last = wire.status()
    assert last.state == p.State.STREAMING and last.current_applied == pytest.approx(0.12, abs=1e-6)
    wire.close()  # host SIGKILL: no DISARM is ever sent
    t_gone = time.monotonic()
    time.sleep(timeout + 0.3)
    wire = Wire(path)
    wire.request(p.GetIdentity())
    status = wire.status()
    print(f"lockstep: fault {p.describe_faults(status.faults)} at {status.fault_index}, "
          f"silence {status.fault_silence} samples, checked {time.monotonic() - t_gone:.2f} s after")
    assert proc.poll() is None
    assert status.faults == p.Fault.WATCHDOG
    assert status.state == p.State.DISARMED
    assert status.current_applied == 0.0
    assert status.fault_index == 500  # every setpoint ran; the trip sample is the next one
    # host silence in samples at the trip: the timeout (200 samples) plus at most the device loop's 10 ms wait
    assert 200 <= status.fault_silence <= 200 + 10 + 5
    assert wire.request(p.Arm()).result == p.Result.FAULT_LATCHED
    wire.close()


SIM = sim_config_from_dict({"plant": {"elements": 4}})


def _armed(pacing: str, watchdog: float) -> Host:
    host = Host(CoreDevice(SIM, pacing, max_block=128))
    cfg = p.Config(sample_rate=1000, current_limit=5.0, watchdog_timeout=watchdog, torque_constant=0.2,
                   counts_per_rev=4096)
    assert host.send(cfg)[0].result == p.Result.OK
    assert host.send(p.Arm())[0].result == p.Result.OK
    return host


def test_tick_ending_exactly_on_the_trip_sample():
    """Item 1, watchdog path: the tick computes up to the sample before the trip sample; the next tick has
    nothing left but the trip itself."""
    host = _armed("realtime", 0.1)
    host.send(p.SetpointBlock(0, np.full(128, 0.1, dtype=np.float32)), 0.0)
    # trip sample = first k with k/1000 > 0 + 0.1 -> 101; a tick at t = 0.101 computes samples 0..100
    host.tick(0.101)
    s = host.device.status()
    assert s["index"] == 101 and s["state"] == p.State.STREAMING
    # the deadline has passed, but sample 101 (t = 0.101 s, computed once due at 0.102 s like every sample)
    # is not due yet: nothing happens; at 0.1025 s the trip sample is all there is to compute
    assert host.tick(0.1015) == [] and host.device.status()["faults"] == 0
    out = host.tick(0.1025)
    blocks = [m for m in out if isinstance(m, p.SampleBlock)]
    s = host.device.status()
    assert s["faults"] == p.Fault.WATCHDOG and s["state"] == p.State.DISARMED and s["fault_index"] == 101
    assert blocks[-1].first_index == 101 and blocks[-1].current_cmd[-1] == 0.0


def test_underrun_on_an_exactly_empty_buffer_unit():
    host = _armed("realtime", 0.0)
    host.send(p.SetpointBlock(0, np.full(100, 0.1, dtype=np.float32)), 0.0)
    host.tick(0.1)  # all 100 due and buffered
    assert host.device.status()["index"] == 100
    host.tick(0.2)
    s = host.device.status()
    assert s["faults"] == p.Fault.BUFFER_UNDERRUN and s["fault_index"] == 100


def test_lockstep_watchdog_unit_runs_on_every_tick():
    host = _armed("lockstep", 0.2)
    host.send(p.SetpointBlock(0, np.full(50, 0.12, dtype=np.float32)), 0.0)
    host.tick(0.0)
    s = host.device.status()
    assert s["index"] == 50 and s["state"] == p.State.STREAMING and s["current_applied"] == pytest.approx(0.12)
    assert host.tick(0.19) == []  # buffer empty, deadline not reached
    host.tick(0.21)
    s = host.device.status()
    assert s["faults"] == p.Fault.WATCHDOG and s["current_applied"] == 0.0 and s["state"] == p.State.DISARMED


def test_watchdog_deadline_after_the_buffer_runs_dry_in_one_tick_unit():
    """A long tick (a stalled device loop) that holds both the end of the setpoints and the watchdog
    deadline: the underrun comes first in sample order and latches; nothing is taken that is not there."""
    host = _armed("realtime", 0.1)
    host.send(p.SetpointBlock(0, np.full(50, 0.1, dtype=np.float32)), 0.0)
    host.tick(0.3)  # 300 samples due, the watchdog trip sample is 101, only 50 setpoints buffered
    s = host.device.status()
    assert s["faults"] == p.Fault.BUFFER_UNDERRUN and s["fault_index"] == 50
    assert s["index"] == 51 and s["current_applied"] == 0.0


def test_host_gone_during_a_long_device_tick(simulator):
    """Black box: a 100 ms device loop (``--tick 0.1``), a 50 ms watchdog, 20 setpoints, then silence. The
    first tick after the host vanished often covers both the buffer's end and the watchdog deadline (this
    killed the simulator with an IndexError)."""
    for trial in range(4):
        proc, path = simulator(pacing="realtime", tick="0.1")
        wire = Wire(path)
        wire.start_stream(rate=1000, watchdog=0.05, current=0.1, n=20, block=20)
        wire.close()
        time.sleep(0.4)
        assert proc.poll() is None, f"trial {trial}: the simulator died: {proc.stderr.read().decode()[-300:]}"
        wire = Wire(path)
        wire.request(p.GetIdentity())
        status = wire.status()
        wire.close()
        assert status.faults == p.Fault.BUFFER_UNDERRUN and status.fault_index == 20, trial
        assert status.state == p.State.DISARMED and status.current_applied == 0.0

