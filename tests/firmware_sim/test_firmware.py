"""The amplifier firmware and its safety logic, without any I/O (time is passed in explicitly)."""

import math
import subprocess
import sys

import numpy as np
import pytest

from hilbench.drivers import protocol as p
from hilbench.firmware_sim.firmware import Firmware
from hilbench.firmware_sim.plant import simulate
from hilbench.firmware_sim.safety import SafetyMonitor, watchdog_trip_index
from hilbench.firmware_sim.sim_config import SimConfigError, load_sim_config, sim_config_from_dict

SIM = sim_config_from_dict({"device": {"buffer_capacity": 4096},
                            "plant": {"elements": 4, "seed": 3, "noise_current": 0.01,
                                      "noise_position": 1e-4}})


def fresh(pacing="lockstep", **config):
    fw = Firmware(SIM, pacing, max_block=128)
    cfg = p.Config(**{"sample_rate": 1000, "current_limit": 5.0, "torque_constant": 0.2,
                      "counts_per_rev": 4096, **config})
    assert fw.handle(cfg, 0.0)[0].result == p.Result.OK
    assert fw.handle(p.Arm(), 0.0)[0].result == p.Result.OK
    return fw


def samples(msgs):
    blocks = [m for m in msgs if isinstance(m, p.SampleBlock)]
    names = ("counts", "current_cmd", "status")
    return {k: np.concatenate([getattr(b, k) for b in blocks]) for k in names}, blocks


def test_watchdog_trip_index_closed_form():
    # first k with t0 + (k-k0)/rate > last_rx + timeout
    assert watchdog_trip_index(10.0, 0.1, 10.0, 0, 1000) == 101
    assert watchdog_trip_index(10.05, 0.1, 10.0, 500, 1000) == 500 + 151
    assert watchdog_trip_index(10.0, 0.0, 10.0, 0, 1000) is None


def test_safety_first_trip_and_velocity_window_across_blocks():
    cfg = p.Config(sample_rate=2000, current_limit=1.0, velocity_limit=10.0, position_min=-1.0,
                   position_max=1.0, counts_per_rev=1000)
    mon = SafetyMonitor(cfg)
    assert mon.window == 2
    zeros = np.zeros(4)
    # v[k] = 2*pi/1000 * (c[k] - c[k-2]) / 1 ms: 1 count -> 6.28 rad/s, 2 counts -> 12.6 rad/s > 10;
    # before the first sample the motor is at rest at c[0]
    counts = np.array([0, 1, 1, 2], dtype=np.int64)
    assert mon.first_trip(counts, zeros, zeros) == (4, 0)
    mon.accept(counts)
    nxt = np.array([3, 4, 6, 8], dtype=np.int64)  # v[0] = (3 - 1) counts / 1 ms -> 12.6 rad/s
    assert mon.first_trip(nxt, zeros, zeros) == (0, p.Fault.OVER_SPEED)
    current = np.array([0, 0.5, -1.5, 0])
    assert mon.first_trip(np.array([2, 2, 2, 2]), current, zeros) == (2, p.Fault.OVER_CURRENT)
    far = int(1.2 * 1000 / (2 * math.pi))  # 1.2 rad
    j, bits = SafetyMonitor(cfg).first_trip(np.array([0, 0, far, far]), zeros, zeros)
    assert j == 2 and bits == p.Fault.OVER_SPEED | p.Fault.POSITION_WINDOW
    mon.latch(p.Fault.OVER_SPEED, 17, 3)
    mon.latch(p.Fault.WATCHDOG, 40, 9)
    assert (mon.faults, mon.fault_index, mon.fault_silence) == (p.Fault.OVER_SPEED | p.Fault.WATCHDOG, 17, 3)
    mon.clear()
    assert (mon.faults, mon.fault_index) == (0, 0)


def test_blocks_of_any_size_equal_one_direct_run():
    fw = fresh()
    rng = np.random.default_rng(0)
    u = rng.uniform(-4, 4, 3000).astype(np.float32)
    pos, seq, out = 0, 0, []
    while pos < len(u):
        n = int(rng.integers(1, 129))
        fw.handle(p.SetpointBlock(seq, u[pos: pos + n], end=pos + n >= len(u)), 0.0)
        pos, seq = pos + n, seq + 1
        if rng.random() < 0.5:
            out += fw.advance(0.0)
    while fw.busy:
        out += fw.advance(0.0)
    got, _ = samples(out)
    ref = simulate(SIM.plant_for(5.0, 0.2, 4096), u.astype(np.float64), 1e-3, SIM.substeps_at(1000))
    assert np.array_equal(got["counts"], ref.counts)
    assert np.array_equal(got["current_cmd"], ref.current_cmd.astype(np.float32))
    assert fw.state == p.State.ARMED and fw.index == 3000


def test_realtime_watchdog_zeroes_current_at_the_computed_sample():
    fw = fresh("realtime", watchdog_timeout=0.1)
    fw.handle(p.SetpointBlock(0, np.full(128, 1.0)), 100.0)
    for k in range(1, 8):
        fw.handle(p.SetpointBlock(k, np.full(128, 1.0)), 100.0)  # last host message at t = 100.0 s
    got, blocks = samples(fw.advance(100.5))
    # t0 = 100.0, so sample k is at 100.0 + k ms; deadline 100.1 s -> sample 101 is the first after it
    assert len(got["current_cmd"]) == 102
    assert np.all(got["current_cmd"][:101] == 1.0) and got["current_cmd"][101] == 0.0
    assert got["status"][101] == p.SampleStatus.FAULT | p.SampleStatus.END
    status = fw.status()
    assert status.faults == p.Fault.WATCHDOG and status.fault_index == 101 and status.fault_silence == 101
    assert fw.state == p.State.DISARMED and status.current_applied == 0.0


def test_realtime_underrun_and_sequence_gap():
    fw = fresh("realtime", watchdog_timeout=0.0)
    fw.handle(p.SetpointBlock(0, np.full(50, 0.5)), 0.0)
    got, _ = samples(fw.advance(0.2))  # 200 samples due, 50 buffered
    assert len(got["current_cmd"]) == 51 and got["current_cmd"][50] == 0.0
    assert fw.faults == p.Fault.BUFFER_UNDERRUN
    fw.handle(p.ClearFaults(), 0.3)
    fw.handle(p.Arm(), 0.3)
    fw.handle(p.SetpointBlock(0, np.full(10, 0.5)), 0.3)
    out = fw.handle(p.SetpointBlock(2, np.full(10, 0.5)), 0.3)  # block 1 lost on the link
    got, _ = samples(out)
    assert got["current_cmd"].tolist() == [0.0] and fw.faults == p.Fault.BUFFER_UNDERRUN
    assert fw.counters["dropped_frames"] == 1


def test_disarm_and_estop_while_streaming_and_latching():
    fw = fresh()
    fw.handle(p.SetpointBlock(0, np.full(100, 2.0)), 0.0)
    fw.advance(0.0)
    out = fw.handle(p.Disarm(), 0.0)
    got, _ = samples(out)
    assert got["current_cmd"].tolist() == [0.0] and got["status"][0] == p.SampleStatus.END
    assert fw.faults == 0 and fw.state == p.State.DISARMED
    fw.handle(p.Arm(), 0.0)
    fw.handle(p.SetpointBlock(0, np.full(100, 2.0)), 0.0)
    out = fw.handle(p.EStop(), 0.0)
    assert out[-1] == p.Reply(p.MsgType.ESTOP, p.Result.OK, p.Fault.ESTOP)
    assert fw.handle(p.Arm(), 0.0)[0].result == p.Result.FAULT_LATCHED
    # faults survive a reconfiguration; only CLEAR_FAULTS clears them
    fw.handle(p.Config(sample_rate=2000), 0.0)
    assert fw.faults == p.Fault.ESTOP
    fw.handle(p.ClearFaults(), 0.0)
    assert fw.handle(p.Arm(), 0.0)[0].result == p.Result.OK


def test_unconfigured_and_invalid_requests():
    fw = Firmware(SIM)
    assert fw.handle(p.Arm(), 0.0)[0].result == p.Result.NOT_CONFIGURED
    assert fw.handle(p.GetConfig(), 0.0)[0].result == p.Result.NOT_CONFIGURED
    assert fw.handle(p.Config(sample_rate=1234), 0.0)[0].result == p.Result.INVALID_CONFIG
    assert fw.handle(p.SetpointBlock(0, np.zeros(3)), 0.0) == []
    assert fw.counters["dropped_frames"] == 1


def test_injected_effects_never_reach_the_wire():
    plain = sim_config_from_dict({"plant": {"elements": 4}})
    effects = sim_config_from_dict({"plant": {"elements": 4, "noise_current": 0.2,
                                              "torque_offset": 0.1, "delay_samples": 3,
                                              "cogging": [{"order": 6, "amplitude": 0.05}]}})
    encoded = []
    for sim in (plain, effects):
        fw = Firmware(sim)
        fw.handle(p.Config(), 0.0)
        replies = [r for m in (p.GetIdentity(), p.Heartbeat(1), p.GetConfig()) for r in fw.handle(m, 0.0)]
        encoded.append([p.encode_frame(m) for m in replies])
    assert encoded[0] == encoded[1]


def test_sim_config_errors(tmp_path):
    with pytest.raises(SimConfigError, match="unknown plant parameter"):
        sim_config_from_dict({"plant": {"colour": 1}})
    with pytest.raises(SimConfigError, match="come from the host's CONFIG"):
        sim_config_from_dict({"plant": {"counts_per_rev": 4096}})
    with pytest.raises(SimConfigError, match="unknown section"):
        sim_config_from_dict({"plot": {}})
    bad = tmp_path / "bad.toml"
    bad.write_text("[plant\n")
    with pytest.raises(SimConfigError, match="cannot read"):
        load_sim_config(bad)
    assert load_sim_config(seed=42).plant.seed == 42


def test_cli_bad_config_is_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[plant]\ninertia = -1\n")
    res = subprocess.run([sys.executable, "-m", "hilbench.firmware_sim", "--serial", "--config", str(bad)],
                         capture_output=True, text=True, timeout=30)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and "error" in res.stderr and "Traceback" not in res.stderr
