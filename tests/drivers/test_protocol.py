"""Wire protocol: golden frames, round trips, an independent COBS/CRC oracle, decoder resync and fuzzing."""

import math
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from cobs import cobs
from hypothesis import given, settings
from hypothesis import strategies as st

from hilbench.drivers import protocol as p
from hilbench.drivers.calibration import Calibration, CountUnwrapper
from hilbench.drivers.errors import DriverError, ProtocolError
from tests.drivers.protocol_examples import canonical_messages

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "protocol"
MESSAGES = canonical_messages()
VERSIONED = [(v, name) for v in (1, 2, 3) for name in sorted(canonical_messages(v))]


def reference_cobs(data: bytes) -> bytes:
    """Textbook COBS (Cheshire & Baker 1999), written independently of the ``cobs`` package."""
    out, block = bytearray(), bytearray()
    for byte in data:
        if byte == 0:
            out += bytes([len(block) + 1]) + block
            block.clear()
        else:
            block.append(byte)
            if len(block) == 254:
                out += b"\xff" + block
                block.clear()
    out += bytes([len(block) + 1]) + block
    return bytes(out)


@pytest.mark.parametrize(("version", "name"), VERSIONED)
def test_golden_frame(version, name):
    """v1 frames are kept byte for byte (a v2 host and device still read and write them); v2 adds
    GET_IDENTITY's host version, the 106-byte CONFIG and two-value position setpoints."""
    golden = bytes.fromhex((GOLDEN / f"v{version}_{name}.hex").read_text().strip())
    msg = canonical_messages(version)[name]
    assert p.encode_frame(msg, version) == golden
    assert p.decode_frame(golden[:-1]) == msg


@pytest.mark.parametrize(("version", "name"), VERSIONED)
def test_frame_matches_independent_oracle(version, name):
    msg = canonical_messages(version)[name]
    payload = msg.encode(version) if isinstance(msg, p.Config | p.SampleBlock) else msg.encode()
    raw = bytes([version, int(msg.TYPE)]) + payload
    expected = reference_cobs(raw + struct.pack("<I", zlib.crc32(raw) & 0xFFFFFFFF)) + b"\x00"
    assert p.encode_frame(msg, version) == expected
    assert b"\x00" not in expected[:-1]


def test_v2_layouts_by_hand():
    """docs/protocol.md: CONFIG v2 = the v1 65 bytes + kp, ki, kd, i_limit, d_cutoff (f64) + flags (u8);
    GET_IDENTITY v2 = host version (u16); position setpoints interleave angle and current."""
    cfg = canonical_messages(2)["config_position"]
    payload = cfg.encode()
    assert len(payload) == 106
    assert struct.unpack_from("<5d", payload, 65) == (2500.0, 125000.0, 4.5, 3.25, 250.0)
    assert payload[105] == 1 and payload[4] == 2
    assert payload[:65] == struct.pack("<IBddddddId", 20000, 2, 8.0, 300.0, -0.5, 0.75, 0.5, 0.2, 65536, 1.0)
    assert p.GetIdentity(2).encode() == b"\x02\x00" and p.GetIdentity(1).encode() == b""
    assert p.GetIdentity().encode() == b"\x03\x00"  # this host speaks v3
    assert cobs.decode(p.encode_frame(p.GetIdentity(1))[:-1])[0] == 1  # a v1 probe goes out as a v1 frame
    assert cobs.decode(p.encode_frame(p.GetIdentity(2))[:-1])[0] == 2  # a v2 probe as a v2 frame
    assert cobs.decode(p.encode_frame(p.GetIdentity())[:-1])[0] == 3
    sp = canonical_messages(2)["setpoints_position"].encode()
    assert struct.unpack_from("<6f", sp, 5) == (0.0, 0.5, np.float32(2.5e-4), -0.75, np.float32(-1e-3), 1.25)
    with pytest.raises(ProtocolError, match="v1 has no position mode"):
        cfg.encode(1)


def test_v1_config_decodes_without_a_position_loop():
    v1 = bytes.fromhex((GOLDEN / "v1_config.hex").read_text().strip())
    cfg = p.decode_frame(v1[:-1])
    assert cfg.mode == p.Mode.VELOCITY and cfg.feedforward is False
    assert all(getattr(cfg, g) == 0.0 for g in p.Config.GAINS)


def test_position_config_problems():
    assert p.Config(mode=p.Mode.POSITION, feedforward=True).problems() == []
    text = " ".join(p.Config(mode=p.Mode.POSITION, position_kp=0.0, position_ki=-1.0, position_d_cutoff=6000.0,
                             sample_rate=10000).problems())
    for fragment in ("position_kp > 0", "position_ki must be finite and >= 0", "Nyquist"):
        assert fragment in text
    assert "position-mode option" in " ".join(p.Config(mode=p.Mode.CURRENT, feedforward=True).problems())


@pytest.mark.parametrize(("version", "head"), [(2, 27), (3, 31)])
def test_sample_block_layout_by_hand(version, head):
    # header <IQIQHB (v3: + temperature f4) then counts i4, cmd f4, meas f4, status u2 (struct of arrays),
    # see docs/protocol.md
    blk = canonical_messages(version)["samples"]
    payload = blk.encode(version)
    assert len(payload) == head + 14 * 4
    assert struct.unpack_from("<IQIQHB", payload, 0) == (3, 2**33 + 5, 100, 2**33 + 9, 0, 3)
    if version >= 3:
        assert struct.unpack_from("<f", payload, 27) == (36.625,)
    assert struct.unpack_from("<4i", payload, head) == (0, -1, 2**31 - 1, -(2**31))
    assert struct.unpack_from("<4f", payload, head + 16) == (0.5, 0.0, -0.25, 1.0)
    assert struct.unpack_from("<4H", payload, head + 48) == (1, 1, 3, 5)
    back = p.SampleBlock.decode(payload, version)  # the agreed version tells the layout, not the length
    assert back == blk
    assert math.isnan(back.temperature) if version < 3 else back.temperature == 36.625
    other = 5 - version  # the same bytes read in the other version's layout are refused, never misread
    with pytest.raises(ProtocolError, match="whole samples"):
        p.SampleBlock.decode(payload, other)


def test_a_v3_block_cut_by_4_bytes_is_refused():
    """Was read as a v2 block (the layout was chosen by length) whose counts began with the last 4 bytes of the
    header: invented samples."""
    payload = canonical_messages(3)["samples"].encode(3)
    with pytest.raises(ProtocolError):
        p.SampleBlock.decode(payload[:-4], 3)
    assert p.decode_frame(p.encode_frame(canonical_messages(3)["samples"])[:-1], 3) == canonical_messages(3)["samples"]


@pytest.mark.parametrize("n", [28, 29, 30])
def test_a_samples_payload_of_28_to_30_bytes_is_a_protocol_error(n):
    """It raised struct.error (the v3 header picked by length, its temperature unpacked before the length check),
    which killed the link's receiver thread."""
    for version in (2, 3):
        with pytest.raises(ProtocolError):
            p.decode_message(p.MsgType.SAMPLES, bytes(n), version)


def test_identity_v3_names_its_sensors():
    """IDENTITY v3 = the v2 layout + one sensors byte; a v2 IDENTITY decodes with no sensors."""
    v3 = canonical_messages(3)["identity"].encode()
    v2 = canonical_messages(2)["identity"].encode()
    assert v3[:-1][:-8] == v2[:-8] and len(v3) == len(v2) + 1 and v3[-1] == 1
    assert p.Identity.decode(v3).sensors == p.Sensor.TEMPERATURE
    assert p.Identity.decode(v2).sensors == 0
    bad = v2[:-8] + struct.pack("<HIHB", 2, 8192, 256, 1)  # a sensors byte in a v2 IDENTITY
    with pytest.raises(ProtocolError, match="sensors byte"):
        p.Identity.decode(bad)
    for n in (1, 2, 3, 5):  # a body of a non-whole number of samples is refused under either header
        for version in (2, 3):
            with pytest.raises(ProtocolError, match="whole samples"):
                p.SampleBlock.decode(bytes(27 + 14 + n), version)


def test_config_problems_are_specific():
    assert p.Config().problems() == []
    bad = p.Config(sample_rate=3000, current_limit=math.nan, position_min=1.0, position_max=0.0,
                   watchdog_timeout=-1, counts_per_rev=0)
    text = " ".join(bad.problems())
    for fragment in ("3000 Hz", "current_limit", "position window", "watchdog_timeout", "counts_per_rev"):
        assert fragment in text


def test_decoder_resyncs_in_arbitrary_chunks():
    frames = [p.encode_frame(m) for m in MESSAGES.values()]
    stream = b"\x13\x37garbage\x00" + b"".join(frames[:5]) + b"\x05\x01\x02" + b"\x00" + b"".join(frames[5:])
    dec = p.FrameDecoder()
    rng = np.random.default_rng(1)
    got, pos = [], 0
    while pos < len(stream):
        step = int(rng.integers(1, 40))
        got += dec.feed(stream[pos: pos + step])
        pos += step
    assert got == list(MESSAGES.values())
    assert dec.crc_errors == 2  # the leading garbage and the broken frame between, nothing else


def test_decoder_drops_oversize_frame_and_recovers():
    dec = p.FrameDecoder(max_frame=64)
    assert dec.feed(b"\x01" * 500) == []
    assert dec.feed(b"\x02\x00" + p.encode_frame(p.Arm())) == [p.Arm()]
    assert dec.crc_errors == 1


def test_version_mismatch_is_a_protocol_error():
    raw = bytes([4, int(p.MsgType.ARM)])
    frame = reference_cobs(raw + struct.pack("<I", zlib.crc32(raw)))
    with pytest.raises(ProtocolError, match="version 4"):
        p.decode_frame(frame)


def test_protocol_error_is_a_driver_error():
    assert issubclass(ProtocolError, DriverError)


@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=300))
def test_fuzz_decode_frame_raises_only_protocol_error(data):
    try:
        p.decode_frame(data)
    except ProtocolError:
        pass


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 255), st.binary(max_size=200))
def test_fuzz_valid_crc_garbage_payload(msg_type, payload):
    # frames that pass COBS and CRC but carry garbage: the payload decoders themselves must hold up
    raw = bytes([1, msg_type]) + payload
    frame = reference_cobs(raw + struct.pack("<I", zlib.crc32(raw)))
    try:
        msg = p.decode_frame(frame)
    except ProtocolError:
        return
    assert msg.TYPE == msg_type
    assert p.decode_frame(p.encode_frame(msg)[:-1]) == msg


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=80), max_size=20))
def test_fuzz_stream_decoder_never_raises(chunks):
    dec = p.FrameDecoder(max_frame=256)
    for chunk in chunks:
        dec.feed(chunk)
    assert dec.feed(p.encode_frame(p.Heartbeat(5))) in ([p.Heartbeat(5)], [])
    assert dec.feed(p.encode_frame(p.Heartbeat(6))) == [p.Heartbeat(6)]  # resynchronised by now


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 63), st.lists(st.binary(min_size=1, max_size=64), max_size=30))
def test_fuzz_can_reassembler_never_raises(msg_type, datas):
    re = p.CanReassembler(p.HOST_TO_DEVICE, 1)
    for data in datas:
        re.feed(p.can_id(msg_type, p.HOST_TO_DEVICE, 1), data)


@pytest.mark.parametrize("fd", [False, True])
@pytest.mark.parametrize("name", sorted(MESSAGES))
def test_can_round_trip(name, fd):
    msg = MESSAGES[name]
    frames = p.encode_can(msg, p.DEVICE_TO_HOST, 3, fd=fd)
    limit = 64 if fd else 8
    assert all(len(data) <= limit for _, data in frames)
    assert all(p.split_can_id(arb) == (int(msg.TYPE), p.DEVICE_TO_HOST, 3) for arb, _ in frames)
    re = p.CanReassembler(p.DEVICE_TO_HOST, 3)
    results = [re.feed(arb, data) for arb, data in frames]
    assert results[:-1] == [None] * (len(frames) - 1)
    assert results[-1] == msg
    other = p.CanReassembler(p.DEVICE_TO_HOST, 4)  # another node ignores it
    assert [other.feed(arb, data) for arb, data in frames] == [None] * len(frames)


def test_can_lost_segment_is_counted_and_next_message_decodes():
    re = p.CanReassembler(p.DEVICE_TO_HOST, 1)
    frames = p.encode_can(MESSAGES["samples"], p.DEVICE_TO_HOST, 1)
    for arb, data in frames[:2] + frames[3:]:
        assert re.feed(arb, data) is None
    assert re.dropped_frames == 1
    out = [re.feed(arb, data) for arb, data in frames]
    assert out[-1] == MESSAGES["samples"]


def test_can_estop_wins_arbitration():
    ids = [p.can_id(t, d, n) for t in p.MsgType for d in (0, 1) for n in range(1, 16)]
    assert min(ids) == p.can_id(p.MsgType.ESTOP, p.HOST_TO_DEVICE, 1)
    assert max(ids) < 2**11


def test_setpoint_blocks_cover_values_in_order():
    values = np.arange(1001, dtype=np.float32)
    blocks = p.make_setpoint_blocks(values, 250)
    assert [b.seq for b in blocks] == [0, 1, 2, 3, 4]
    assert [b.end for b in blocks] == [False] * 4 + [True]
    assert np.array_equal(np.concatenate([b.values for b in blocks]), values)
    pairs = np.arange(2002, dtype=np.float32).reshape(1001, 2)  # position mode with feed-forward
    blocks = p.make_setpoint_blocks(pairs, 250)
    assert [len(b.values) for b in blocks] == [500] * 4 + [2]
    assert np.array_equal(np.concatenate([b.values for b in blocks]), pairs.reshape(-1))


@settings(max_examples=200, deadline=None)
@given(st.integers(-(2**40), 2**40), st.lists(st.integers(-(2**31) + 1, 2**31 - 1), min_size=1, max_size=50),
       st.integers(1, 10))
def test_count_unwrapper_recovers_int64_counts(start, steps, cut):
    # exact oracle: the int64 walk itself; the wire carries it modulo 2**32
    truth = start + np.cumsum(np.array(steps, dtype=np.int64))
    wire = truth.astype(np.int32)  # numpy astype wraps modulo 2**32
    unwrap = CountUnwrapper()
    unwrap.last = int(truth[0]) - steps[0]  # continuing a stream whose previous sample is known
    out = np.concatenate([unwrap(wire[:cut]), unwrap(wire[cut:])])
    assert np.array_equal(out, truth)


def test_calibration_closed_form():
    cal = Calibration(torque_constant=0.05, counts_per_rev=4000, ratio=4.0)
    # one load revolution is ratio motor revolutions = 16000 counts
    assert cal.position(np.array([16000]))[0] == pytest.approx(2 * math.pi, rel=1e-15)
    assert cal.torque(np.array([2.0]))[0] == pytest.approx(0.4, rel=1e-15)
    assert cal.current(cal.torque(np.array([1.25])))[0] == pytest.approx(1.25, rel=1e-15)
