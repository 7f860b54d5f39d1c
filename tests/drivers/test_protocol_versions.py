"""Protocol v1/v2/v3 compatibility, bytes on the wire: a v1 host still works with the v3 firmware core; a v3
host refuses a v1 device in one line; position-mode setpoints are checked host-side before anything moves."""

from __future__ import annotations

import math
import queue
import zlib

import numpy as np
import pytest
from cobs import cobs

from hilbench.drivers import protocol as p
from hilbench.drivers.amplifier import Amplifier
from hilbench.drivers.device_url import open_device
from hilbench.drivers.errors import DriverError, SetpointError
from hilbench.firmware_sim.devices.core_c import CoreDevice
from hilbench.firmware_sim.devices.sim_config import load_sim_config


def v1_frame(msg: p.Message) -> bytes:
    """What a v1 host writes: version byte 1, the v1 payloads (empty GET_IDENTITY, 65-byte CONFIG)."""
    return p.encode_frame(msg, 1)


def v1_host_reads(data: bytes) -> list[p.Message]:
    """A v1 host's decoder: frames whose version byte is not 1 are rejected (counted as errors here)."""
    out = []
    for chunk in data.split(b"\x00")[:-1]:
        raw = cobs.decode(chunk)
        assert zlib.crc32(raw[:-4]) == int.from_bytes(raw[-4:], "little")
        assert raw[0] == 1, f"a v1 host cannot read a frame of version {raw[0]}"
        out.append(p.decode_message(raw[1], raw[2:-4], 1))  # a v1 host reads the v1 layouts
    return out


def test_a_v1_host_works_with_the_v3_core():
    dev = CoreDevice(load_sim_config(), pacing="lockstep")
    now = 1.0

    def exchange(msg: p.Message) -> list[p.Message]:
        dev.rx_bytes(v1_frame(msg), now)
        dev.tick(now)
        return v1_host_reads(dev.take_bytes())

    (ident,) = exchange(p.GetIdentity(1))
    assert ident.protocol_version == 1 and ident.firmware.endswith("3.0.0")
    config = p.Config(sample_rate=1000, mode=p.Mode.CURRENT, current_limit=3.0, torque_constant=0.2,
                      counts_per_rev=4096, **dict.fromkeys(p.Config.GAINS, 0.0))
    assert len(config.encode(1)) == 65
    assert exchange(config) == [p.Reply(p.MsgType.CONFIG, p.Result.OK, 0)]
    assert exchange(p.GetConfig()) == [config]  # echoed in the v1 layout
    assert exchange(p.Arm()) == [p.Reply(p.MsgType.ARM, p.Result.OK, 0)]
    blocks = exchange(p.SetpointBlock(0, np.full(50, 0.5, dtype=np.float32), end=True))
    samples = [b for b in blocks if isinstance(b, p.SampleBlock)]
    assert sum(len(b) for b in samples) == 50 and samples[-1].status[-1] & p.SampleStatus.END
    np.testing.assert_array_equal(np.concatenate([b.current_cmd for b in samples]), 0.5)
    # position mode cannot be said in v1: a v1 CONFIG with mode 2 has no gains and is refused
    assert exchange(p.Disarm()) == [p.Reply(p.MsgType.DISARM, p.Result.OK, 0)]
    position = p.Config(sample_rate=1000, mode=p.Mode.CURRENT, counts_per_rev=4096)
    raw = bytearray(position.encode(1))
    raw[4] = 2
    body = bytes([1, p.MsgType.CONFIG]) + bytes(raw)
    dev.rx_bytes(cobs.encode(body + zlib.crc32(body).to_bytes(4, "little")) + b"\x00", now)
    assert v1_host_reads(dev.take_bytes()) == [p.Reply(p.MsgType.CONFIG, p.Result.INVALID_CONFIG, 0)]


class V1Device:
    """A protocol-v1 device as a link: it reads only version-1 frames with v1 payloads (a v2 GET_IDENTITY
    carries two bytes, which v1 rejects, as the old firmware did) and answers v1."""

    counters = {"crc_errors": 0}

    def __init__(self) -> None:
        self.out: queue.Queue = queue.Queue()
        self.rejected = 0

    def send(self, msg: p.Message) -> None:
        frame = cobs.decode(p.encode_frame(msg)[:-1])
        if frame[0] != 1 or (msg.TYPE == p.MsgType.GET_IDENTITY and len(frame) != 6):
            self.rejected += msg.TYPE == p.MsgType.GET_IDENTITY  # (v2 heartbeats are dropped too)
            return
        if msg.TYPE == p.MsgType.GET_IDENTITY:
            self.out.put(p.Identity("HB-OLD", "OLD-1", "hilbench-sim 1.0.0", 1, 8192, 512))
        elif msg.TYPE == p.MsgType.GET_CONFIG:
            self.out.put(p.Reply(p.MsgType.GET_CONFIG, p.Result.NOT_CONFIGURED, 0))
        elif msg.TYPE == p.MsgType.DISARM:
            self.out.put(p.Reply(p.MsgType.DISARM, p.Result.OK, 0))

    def recv(self, timeout):
        try:
            return self.out.get(timeout=timeout)
        except queue.Empty:
            return None

    def close(self) -> None:
        pass


def test_a_v3_host_refuses_a_v1_device_in_one_line():
    link = V1Device()
    with pytest.raises(DriverError) as info:
        Amplifier(link, timeout=0.3)
    text = str(info.value)
    assert "\n" not in text
    assert text == ("device HB-OLD (firmware hilbench-sim 1.0.0) speaks protocol 1; this host needs protocol 3: "
                    "update the device firmware")
    assert link.rejected == 3  # the two v3 GET_IDENTITY attempts and the v2 probe


class V2Device(V1Device):
    """A protocol-v2 device (firmware core 2.x) as a link: it reads frames of version 1 and 2 only, and a v2
    GET_IDENTITY (host version 2) makes it answer as a v2 device."""

    def send(self, msg: p.Message) -> None:
        frame = cobs.decode(p.encode_frame(msg)[:-1])
        if frame[0] > 2:
            self.rejected += msg.TYPE == p.MsgType.GET_IDENTITY
            return
        if msg.TYPE == p.MsgType.GET_IDENTITY:
            version = 2 if len(frame) == 8 else 1
            self.out.put(p.Identity("HB-SIM-1", "SIM-0001", "hilbench-sim c-core 2.0.0", version, 8192, 512))
        elif msg.TYPE == p.MsgType.DISARM:
            self.out.put(p.Reply(p.MsgType.DISARM, p.Result.OK, 0))


def test_a_v3_host_names_the_version_of_a_v2_device_it_refuses():
    link = V2Device()
    with pytest.raises(DriverError) as info:
        Amplifier(link, timeout=0.3)
    assert str(info.value) == ("device HB-SIM-1 (firmware hilbench-sim c-core 2.0.0) speaks protocol 2; this host "
                               "needs protocol 3: update the device firmware")
    assert link.rejected == 2  # the two v3 attempts; the v2 probe was answered


@pytest.fixture(scope="module")
def position_amp():
    with open_device("sim://?pacing=lockstep") as amp:
        amp.configure(p.Config(sample_rate=1000, mode=p.Mode.POSITION, current_limit=4.0, torque_constant=0.2,
                               counts_per_rev=1 << 16, position_min=-0.1, position_max=0.1, feedforward=True))
        amp.arm()
        yield amp


@pytest.mark.parametrize("setpoints, message", [
    (np.zeros(10), r"\(n, 2\) \(angle rad, feed-forward current A\) array in position mode"),
    (np.column_stack([np.zeros(5), [0, 0, 4.5, 0, 0]]), "setpoint 2 = 4.5 A exceeds the configured current "
                                                         r"limit \(feed-forward column\) of 4 A"),
    (np.column_stack([[0, 0.05, 0.2, 0.3], np.zeros(4)]), r"position setpoint 2 = 0.2 rad is outside the "
                                                          r"configured window \[-0.1, 0.1\] rad \(2 setpoints"),
    (np.array([[0.0, 0.0], [math.nan, 0.0]]), "setpoint 1 is"),
])
def test_position_setpoints_are_checked_before_anything_moves(position_amp, setpoints, message):
    before = position_amp.status()
    with pytest.raises(SetpointError, match=message):
        position_amp.stream(setpoints)
    after = position_amp.status()
    assert after.index == before.index and after.state == p.State.ARMED and after.received == 0


def test_position_stream_with_feedforward_round_trip(position_amp):
    """Held at 0 rad with a feed-forward of 0.3 A on a motor at rest: the command is kp*e + I + 0.3 A with
    e = 0 at the first sample (the motor starts at its zero), so exactly 0.3 A."""
    blocks = list(position_amp.stream(np.column_stack([np.zeros(20), np.full(20, 0.3)])))
    cmd = np.concatenate([b.current_cmd for b in blocks])
    assert cmd.size == 20 and cmd[0] == pytest.approx(0.3, abs=1e-7)
