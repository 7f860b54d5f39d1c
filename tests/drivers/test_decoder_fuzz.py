"""Every decoder of the device link fuzzed: random payloads and CRC-valid (well-formed) frames of wrong contents
raise nothing but ProtocolError, and the streaming decoders (documented "never raises") raise nothing at all.

Before the fix a SAMPLES payload of 28-30 bytes raised struct.error through decode_message, FrameDecoder.feed and
CanReassembler.feed (352 of 200 000 random payloads, 41 of 50 000 CRC-valid frames) and killed the link's receiver
thread. Seeded numpy generators; each decoder gets >= 200 000 random payloads and >= 50 000 valid frames.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest
from cobs import cobs

from hilbench.drivers import cia402 as c
from hilbench.drivers import odrive_can as o
from hilbench.drivers import protocol as p
from hilbench.drivers.errors import ProtocolError
from tests.drivers.protocol_examples import canonical_messages

RANDOM_PAYLOADS = 200_000
VALID_FRAMES = 50_000
TYPES = np.arange(0, 16, dtype=np.uint8)  # the 13 message types and 3 unknown ones


def random_payloads(rng: np.random.Generator, n: int, longest: int = 120) -> list[bytes]:
    """``n`` payloads of random bytes, lengths uniform in 0..longest (every header size and its neighbours)."""
    lengths = rng.integers(0, longest + 1, n)
    pool = rng.integers(0, 256, int(lengths.sum()), dtype=np.uint8).tobytes()
    ends = np.cumsum(lengths)
    return [pool[e - k: e] for e, k in zip(ends.tolist(), lengths.tolist(), strict=True)]


def near_valid_payloads(rng: np.random.Generator, n: int) -> list[tuple[int, int, bytes]]:
    """``n`` (version, type, payload) close to real ones: a canonical message of some version, cut or extended
    by up to 6 bytes and with a few bytes overwritten, so that the length checks and the fields behind them
    are what is hit (a SAMPLES of 28-30 bytes, a v3 block 4 bytes short, a CONFIG one byte long...)."""
    seeds = [(v, int(m.TYPE), m.encode(v) if isinstance(m, p.Config | p.SampleBlock) else m.encode())
             for v in (1, 2, 3) for m in canonical_messages(v).values()]
    picks = rng.integers(0, len(seeds), n)
    cuts = rng.integers(-6, 7, n)
    out = []
    for k, cut in zip(picks.tolist(), cuts.tolist(), strict=True):
        version, msg_type, payload = seeds[k]
        raw = bytearray(payload[: max(0, len(payload) + cut)] if cut < 0 else payload + rng.bytes(cut))
        for _ in range(int(rng.integers(0, 3))):
            if raw:
                raw[int(rng.integers(0, len(raw)))] = int(rng.integers(0, 256))
        out.append((version, msg_type, bytes(raw)))
    return out


def decode_or_refuse(decode, *args) -> bool:
    """True if decoded, False if refused with ProtocolError; any other exception fails the test."""
    try:
        decode(*args)
    except ProtocolError:
        return False
    return True


def test_messages_refuse_random_payloads_with_protocol_error_only():
    rng = np.random.default_rng(40)
    types = rng.choice(TYPES, RANDOM_PAYLOADS).tolist()
    versions = rng.integers(1, 4, RANDOM_PAYLOADS).tolist()
    payloads = random_payloads(rng, RANDOM_PAYLOADS)
    decoded = sum(decode_or_refuse(p.decode_message, t, b, v) for t, b, v in zip(types, payloads, versions,
                                                                                  strict=True))
    assert 0 < decoded < RANDOM_PAYLOADS  # the empty-payload commands and lucky lengths decode, most do not


def test_messages_refuse_near_valid_payloads_with_protocol_error_only():
    rng = np.random.default_rng(41)
    cases = near_valid_payloads(rng, VALID_FRAMES * 2)
    decoded = sum(decode_or_refuse(p.decode_message, t, b, v) for v, t, b in cases)
    assert 0 < decoded < len(cases)


@pytest.mark.parametrize("n", [28, 29, 30])
def test_samples_of_28_to_30_bytes_are_refused_in_every_framing(n):
    payload = bytes(range(n))
    raw = bytes((3, p.MsgType.SAMPLES)) + payload
    frame = cobs.encode(raw + struct.pack("<I", zlib.crc32(raw))) + b"\x00"
    dec = p.FrameDecoder()
    assert dec.feed(frame) == [] and dec.crc_errors == 1 and "SAMPLES" in dec.last_error
    reassembler = p.CanReassembler(p.DEVICE_TO_HOST, 1)
    frames = segments(p.MsgType.SAMPLES, payload, fd=True, node=1)
    assert [reassembler.feed(arb, data) for arb, data in frames][-1] is None and reassembler.errors == 1


def crc_valid_frame(version: int, msg_type: int, payload: bytes) -> bytes:
    raw = bytes((version, msg_type)) + payload
    return cobs.encode(raw + struct.pack("<I", zlib.crc32(raw))) + b"\x00"


def test_frame_decoder_never_raises_on_crc_valid_frames_and_counts_each_refusal():
    rng = np.random.default_rng(42)
    cases = near_valid_payloads(rng, VALID_FRAMES // 2) + [
        (v, t, b) for v, t, b in zip(rng.integers(1, 4, VALID_FRAMES // 2).tolist(),
                                     rng.choice(TYPES, VALID_FRAMES // 2).tolist(),
                                     random_payloads(rng, VALID_FRAMES // 2), strict=True)]
    stream = b"".join(crc_valid_frame(v, t, b) for v, t, b in cases)
    for version in (2, 3):
        dec = p.FrameDecoder(version=version)
        got = []
        for i in range(0, len(stream), 4096):  # arbitrary chunking
            got += dec.feed(stream[i: i + 4096])
        assert dec.frames == len(got) and dec.frames + dec.crc_errors == len(cases)
        assert 0 < dec.crc_errors < len(cases)
        expected = sum(decode_or_refuse(p.decode_message, t, b, version) for _, t, b in cases)
        assert dec.frames == expected  # each frame decoded exactly when its payload does: none lost, none invented


def test_frame_decoder_never_raises_on_random_bytes():
    rng = np.random.default_rng(43)
    dec = p.FrameDecoder()
    chunks = random_payloads(rng, RANDOM_PAYLOADS, longest=64)
    for chunk in chunks:  # random bytes: mostly bad COBS or CRC, now and then a frame boundary
        dec.feed(chunk)
    assert dec.crc_errors > 1000
    ok = dec.feed(b"\x00" + p.encode_frame(p.Heartbeat(5)))  # still decodes a good frame after all that
    assert ok == [p.Heartbeat(5)]


def segments(msg_type: int, payload: bytes, fd: bool, node: int) -> list[tuple[int, bytes]]:
    """The CAN frames of a message with this raw payload (the segmentation of encode_can, written out)."""
    arb = p.can_id(msg_type, p.DEVICE_TO_HOST, node)
    body = struct.pack("<H", len(payload)) + payload
    size = 63 if fd else 7
    chunks = [body[i: i + size] for i in range(0, len(body), size)][:128]
    return [(arb, bytes(((0x80 if i == len(chunks) - 1 else 0) | i,)) + chunk) for i, chunk in enumerate(chunks)]


def test_can_reassembler_never_raises_on_random_frames_or_well_formed_bad_messages():
    rng = np.random.default_rng(44)
    reassembler = p.CanReassembler(p.DEVICE_TO_HOST, 1)
    types = rng.choice(TYPES, RANDOM_PAYLOADS).tolist()
    heads = rng.integers(0, 256, RANDOM_PAYLOADS).tolist()
    for t, head, data in zip(types, heads, random_payloads(rng, RANDOM_PAYLOADS, longest=63), strict=True):
        reassembler.feed(p.can_id(t, p.DEVICE_TO_HOST, 1), bytes((head,)) + data)
    assert reassembler.errors + reassembler.dropped_frames > 1000
    cases = near_valid_payloads(rng, VALID_FRAMES)
    for version in (2, 3):
        reassembler = p.CanReassembler(p.DEVICE_TO_HOST, 1, version=version)
        got = 0
        for _, t, payload in cases:
            for arb, data in segments(t, payload, fd=True, node=1):
                got += reassembler.feed(arb, data) is not None
        expected = sum(decode_or_refuse(p.decode_message, t, b, version) for _, t, b in cases)
        assert got == reassembler.frames == expected and reassembler.errors == len(cases) - expected


@pytest.mark.parametrize("layout", [o.HEARTBEAT, o.FLOAT, o.FLOAT2, o.U32, o.U32x2, o.SDO])
def test_odrive_frames_too_short_for_their_fields_are_protocol_errors(layout):
    rng = np.random.default_rng(45)
    datas = random_payloads(rng, RANDOM_PAYLOADS // 6, longest=8)
    decoded = sum(decode_or_refuse(o.unpack, layout, d, "frame") for d in datas)
    assert decoded == sum(len(d) >= layout.size for d in datas)
    for _ in range(VALID_FRAMES // 6):  # frames long enough: the fields are the first bytes, padding ignored
        data = rng.bytes(int(rng.integers(layout.size, 9)))
        assert repr(o.unpack(layout, data, "frame")) == repr(layout.unpack_from(data))  # repr: NaN equals NaN


def test_cia402_words_all_decode():
    """The CiA 402 words decode from integers (the frames' lengths are checked by the cycle, rx_len): every
    statusword and controlword has a state or none, never an exception."""
    states = {c.state_of(w) for w in range(1 << 16)}
    assert states - {None} == set(c.State)
    assert {c.command_of(w) for w in range(1 << 16)} - {None} == set(c.Command)


def test_the_c_core_counts_and_drops_every_malformed_host_frame():
    """The firmware core checks each host frame's length before decoding (hb_msg_decode): random payloads of
    every type and CRC-valid frames of wrong contents are counted as rejected, and the device still answers."""
    from hilbench.firmware_sim.devices._fwcore import lib
    from hilbench.firmware_sim.devices.core_c import CoreDevice
    from hilbench.firmware_sim.devices.sim_config import load_sim_config

    rng = np.random.default_rng(47)
    dev = CoreDevice(load_sim_config(), pacing="lockstep")
    handle, raw = lib.hb_device_handle, dev._dev
    types = rng.choice(TYPES, RANDOM_PAYLOADS).tolist()
    for t, payload in zip(types, random_payloads(rng, RANDOM_PAYLOADS), strict=True):
        handle(raw, t, payload, len(payload), 0)
    cases = near_valid_payloads(rng, VALID_FRAMES)
    stream = b"".join(crc_valid_frame(3, t, b) for _, t, b in cases)
    dev.rx_bytes(stream, 0.0)
    dev.take_bytes()
    status = dev.status()
    assert status["rx_frames"] + status["crc_errors"] == RANDOM_PAYLOADS + VALID_FRAMES
    assert status["crc_errors"] > RANDOM_PAYLOADS // 2
    dev.rx_bytes(p.encode_frame(p.Heartbeat(77)), 0.0)
    answers = p.FrameDecoder().feed(dev.take_bytes())
    assert any(isinstance(m, p.Status) and m.token == 77 for m in answers)


def test_a_device_sending_malformed_crc_valid_frames_does_not_end_the_run(simulator):
    """The simulated device over its pty, with CRC-valid frames of wrong contents slipped into what it sends
    (SAMPLES of 28-30 bytes, a v3 block cut by 4 bytes, a short STATUS, an unknown type): every sample arrives,
    each bad frame is counted and dropped, and the run's events say so. The first kind killed the receiver."""
    import serial

    from hilbench.drivers.amplifier import Amplifier
    from hilbench.drivers.fault_injection import FaultyPort
    from hilbench.drivers.links import SerialLink

    cut = canonical_messages(3)["samples"].encode(3)[:-4]
    bad = [crc_valid_frame(3, p.MsgType.SAMPLES, bytes(range(n))) for n in (28, 29, 30)] + [
        crc_valid_frame(3, p.MsgType.SAMPLES, cut), crc_valid_frame(3, p.MsgType.STATUS, bytes(20)),
        crc_valid_frame(3, 0x3F, b"\x01\x02")]
    _, path = simulator(pacing="lockstep")
    port = FaultyPort(serial.serial_for_url(path, timeout=0), inject=bad, p_inject=1.0, seed=40)
    amp = Amplifier(SerialLink(port=port), timeout=2.0)
    try:
        amp.configure(p.Config(sample_rate=10000, current_limit=3.0, watchdog_timeout=1.0))
        amp.arm()
        n = 50_000
        got = sum(len(blk) for blk in amp.stream(0.1 * np.sin(np.arange(n) / 500.0), block=256))
        counters = amp.counters
        assert got == n and counters["host_lost_samples"] == 0
        assert counters["host_crc_errors"] == port.injected >= 2 * len(bad)  # each kind sent, each one counted
        (kind, text), = amp.run_events()
        assert kind == "info" and text.startswith(f"link: {port.injected} malformed frame(s) counted and dropped")
    finally:
        amp.close()
