"""The device link over CAN: python-can's virtual bus (simulator in a thread) and SocketCAN (if present)."""

import socket
import threading
import uuid

import numpy as np
import pytest

from hilbench.drivers import protocol as p
from hilbench.drivers.device_url import open_device
from hilbench.drivers.errors import DeviceFaultError, SetpointError
from hilbench.firmware_sim.devices.core_c import CoreDevice
from hilbench.firmware_sim.devices.device import CanTransport, serve
from hilbench.firmware_sim.devices.sim_config import load_sim_config
from hilbench.firmware_sim.engine.plant import simulate

pytestmark = pytest.mark.usefixtures("starts_devices")  # starts a device: the serial realtime part of make test


@pytest.fixture
def virtual_device(sim_toml):
    """A simulated amplifier on a fresh python-can virtual channel, served from a thread (the virtual
    interface only connects buses within one process)."""
    import can

    started = []

    def start(node=1, fd=False, pacing="lockstep"):
        channel = f"hil-{uuid.uuid4().hex[:8]}"
        path = sim_toml(seed=5)
        bus = can.Bus(interface="virtual", channel=channel, fd=fd)
        transport = CanTransport(bus, node, fd)
        stop = threading.Event()
        device = CoreDevice(load_sim_config(path), pacing, "can-fd" if fd else "can", node, transport.max_block)
        thread = threading.Thread(target=serve, args=(transport, device),
                                  kwargs={"stop": stop, "tick": 0.002}, daemon=True)
        thread.start()
        started.append((stop, thread, transport))
        return channel, path

    yield start
    for stop, thread, transport in started:
        stop.set()
        thread.join(timeout=2)
        transport.close()


@pytest.mark.parametrize("fd", [False, True], ids=["classic", "fd"])
def test_can_virtual_end_to_end_1_khz_bit_identical(virtual_device, fd):
    channel, path = virtual_device(node=3, fd=fd)
    rate = 1000
    setpoints = 4.5 * np.sin(2 * np.pi * 1.5 * np.arange(5 * rate) / rate)  # 5 s
    config = p.Config(sample_rate=rate, current_limit=6.0, torque_constant=0.2, counts_per_rev=4096,
                      watchdog_timeout=0.5)
    with open_device(f"can://virtual/{channel}?node=3&fd={int(fd)}") as amp:
        assert amp.identity.serial == "SIM-TEST"
        assert amp.identity.max_block == (512 if fd else 60)
        amp.configure(config)
        amp.arm()
        blocks = list(amp.stream(setpoints))
        counters = amp.counters
    index = np.concatenate([b.index for b in blocks])
    assert np.array_equal(index, np.arange(len(setpoints)))  # no lost or duplicated samples
    assert counters["host_dropped_frames"] == 0 and counters["host_crc_errors"] == 0
    sim = load_sim_config(path)
    params = sim.plant_for(6.0, config.torque_constant, config.counts_per_rev)
    ref = simulate(params, setpoints.astype(np.float32).astype(np.float64), 1 / rate, substeps=sim.substeps)
    assert np.array_equal(np.concatenate([b.counts for b in blocks]), ref.counts)
    assert np.array_equal(np.concatenate([b.current_meas for b in blocks]),
                          ref.current_meas.astype(np.float32).astype(np.float64))
    assert np.ptp(ref.counts) > 100


def test_can_virtual_other_node_does_not_answer(virtual_device):
    channel, _ = virtual_device(node=2)
    from hilbench.drivers.errors import DeviceTimeoutError

    with pytest.raises(DeviceTimeoutError):
        open_device(f"can://virtual/{channel}?node=4", timeout=0.3)


def test_can_virtual_estop_and_host_checks(virtual_device):
    channel, _ = virtual_device(pacing="realtime")
    with open_device(f"can://virtual/{channel}?node=1") as amp:
        amp.configure(p.Config(sample_rate=1000, current_limit=2.0, torque_constant=0.2))
        amp.arm()
        with pytest.raises(SetpointError, match="exceeds"):
            amp.stream([3.0])
        stream = amp.stream(np.full(5000, 0.5))
        next(stream)
        amp.estop()
        with pytest.raises(DeviceFaultError, match="ESTOP"):
            for _ in stream:
                pass
        assert amp.status().faults == p.Fault.ESTOP


def _socketcan_bus(channel="vcan0"):
    if not hasattr(socket, "AF_CAN"):
        pytest.skip("the kernel/Python lacks AF_CAN (SocketCAN)")
    import can

    try:
        return can.Bus(interface="socketcan", channel=channel)
    except (OSError, can.CanError) as exc:
        pytest.skip(f"no SocketCAN interface {channel}: {exc}")


def test_socketcan_end_to_end_with_simulator_process(sim_toml):
    import subprocess
    import sys
    from pathlib import Path

    _socketcan_bus().shutdown()
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.Popen([sys.executable, "-m", "hilbench.firmware_sim", "--can", "vcan0", "--node", "5",
                             "--pacing", "lockstep", "--config", sim_toml()],
                            cwd=root, stdout=subprocess.PIPE)
    try:
        proc.stdout.readline()
        with open_device("can://socketcan/vcan0?node=5") as amp:
            amp.configure(p.Config(sample_rate=1000, current_limit=6.0, torque_constant=0.2))
            amp.arm()
            blocks = list(amp.stream(np.full(2000, 1.0)))
        assert np.array_equal(np.concatenate([b.index for b in blocks]), np.arange(2000))
    finally:
        proc.terminate()
        proc.wait()
        proc.stdout.close()
