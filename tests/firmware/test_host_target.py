"""The C core on the host target (cffi, C plant behind the HAL), checked against the Python codec and the
plant run directly: independent implementations of the same protocol and the same motor."""

import zlib

import numpy as np
from cobs import cobs
from hypothesis import given, settings
from hypothesis import strategies as st

from hilbench.drivers import protocol as p
from hilbench.firmware_sim.devices._fwcore import ffi, lib
from hilbench.firmware_sim.devices.core_c import CoreDevice
from hilbench.firmware_sim.devices.sim_config import sim_config_from_dict
from hilbench.firmware_sim.engine.plant import simulate
from tests.firmware.host import Host, samples

# The C core is driven here with explicit times (tests/firmware/host.py): nothing runs on a clock, so these tests
# start no device paced in real time and run in the parallel part of make test.

SIM = sim_config_from_dict({"device": {"buffer_capacity": 4096},
                            "plant": {"elements": 4, "seed": 3, "noise_current": 0.01, "noise_position": 1e-4,
                                      "current_lag": 2e-4, "delay_samples": 2}})


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 255), st.binary(max_size=1500))
def test_frame_encoder_matches_python_cobs_and_zlib(msg_type, payload):
    raw = bytes((p.PROTOCOL_VERSION, msg_type)) + payload
    want = cobs.encode(raw + zlib.crc32(raw).to_bytes(4, "little")) + b"\x00"
    out = ffi.new("uint8_t[]", len(want) + 16)
    n = lib.hb_frame_encode(msg_type, payload, len(payload), out)
    assert ffi.buffer(out, n)[:] == want


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=600))
def test_cobs_decoder_matches_python(data):
    out = ffi.new("uint8_t[]", len(data) + 1)
    n = lib.hb_cobs_decode(data, len(data), out)
    try:
        want = cobs.decode(data)
    except cobs.DecodeError:
        assert n == -1
    else:
        assert ffi.buffer(out, n)[:] == want


@settings(max_examples=150, deadline=None)
@given(st.lists(st.binary(max_size=200), max_size=12))
def test_device_survives_garbage_and_answers_the_next_intact_request(chunks):
    host = Host(CoreDevice(SIM, "lockstep"))
    for chunk in chunks:
        host.device.rx_bytes(chunk, 0.0)
        host.device.tick(0.0)
    host.receive()
    replies = host.send(p.Heartbeat(77)) + host.send(p.Heartbeat(78))  # the first may close a garbage frame
    assert any(isinstance(m, p.Status) and m.token == 78 for m in replies)


def test_blocks_of_any_size_equal_one_direct_run():
    host = Host(CoreDevice(SIM, "lockstep", max_block=128))
    assert host.send(p.Config(sample_rate=1000, current_limit=5.0, torque_constant=0.2,
                              counts_per_rev=4096))[0].result == p.Result.OK
    assert host.send(p.Arm())[0].result == p.Result.OK
    rng = np.random.default_rng(0)
    u = rng.uniform(-4, 4, 3000).astype(np.float32)
    pos, seq, out = 0, 0, []
    while pos < len(u):
        n = int(rng.integers(1, 129))
        out += host.send(p.SetpointBlock(seq, u[pos: pos + n], end=pos + n >= len(u)))
        pos, seq = pos + n, seq + 1
        if rng.random() < 0.5:
            out += host.tick()
    while host.device.busy:
        out += host.tick()
    got = samples(out)
    ref = simulate(SIM.plant_for(5.0, 0.2, 4096), u.astype(np.float64), 1e-3, SIM.substeps_at(1000))
    assert np.array_equal(got["counts"], ref.counts.astype(np.int32))
    assert np.array_equal(got["current_cmd"], ref.current_cmd.astype(np.float32))
    assert np.array_equal(got["current_meas"], ref.current_meas.astype(np.float32))
    assert got["status"][-1] == p.SampleStatus.ENABLED | p.SampleStatus.END
    status = host.device.status()
    assert status["state"] == p.State.ARMED and status["index"] == 3000


def test_injected_effects_never_reach_the_wire():
    plain = sim_config_from_dict({"plant": {"elements": 4}})
    effects = sim_config_from_dict({"plant": {"elements": 4, "noise_current": 0.2, "torque_offset": 0.1,
                                              "delay_samples": 3, "cogging": [{"order": 6, "amplitude": 0.05}]}})
    encoded = []
    for sim in (plain, effects):
        host = Host(CoreDevice(sim))
        host.send(p.Config())
        replies = [r for m in (p.GetIdentity(), p.Heartbeat(1), p.GetConfig()) for r in host.send(m)]
        encoded.append([p.encode_frame(m) for m in replies])
    assert encoded[0] == encoded[1]
    assert p.decode_frame(encoded[0][0][:-1]).firmware.startswith("hilbench-sim c-core")


def test_unstable_rate_is_refused_as_invalid_config():
    # sqrt(k/J) = 1e4 1/s: one RK4 sub-step is stable while |lambda|*dt <= 2.5, i.e. from 4 kHz up
    stiff = sim_config_from_dict({"plant": {"preset": "none", "inertia": 1e-4, "ms_stiffness": [1e4],
                                            "ms_slip": [1.0], "substeps": 1}})
    host = Host(CoreDevice(stiff))
    results = {rate: host.send(p.Config(sample_rate=rate))[0].result for rate in (1000, 2000, 5000, 20000)}
    assert results == {1000: p.Result.INVALID_CONFIG, 2000: p.Result.INVALID_CONFIG, 5000: p.Result.OK,
                       20000: p.Result.OK}
