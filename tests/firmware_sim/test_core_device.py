"""The simulated amplifier's firmware, the C core on the host target with the plant behind its HAL, through
the wire protocol and without any I/O: time is passed in explicitly (s). firmware/tests/test_core.c checks
the same behaviours on a scripted HAL; here the samples are the plant's, and the limits are judged by an
independent numpy evaluation of the documented estimate."""

import math
import subprocess
import sys

import numpy as np
import pytest

from hilbench.drivers import protocol as p
from hilbench.firmware_sim.devices.core_c import CoreDevice
from hilbench.firmware_sim.devices.sim_config import SimConfigError, load_sim_config, sim_config_from_dict
from tests.firmware.host import Host, samples

SIM = sim_config_from_dict({"device": {"buffer_capacity": 4096},
                            "plant": {"elements": 4, "seed": 3, "noise_current": 0.01,
                                      "noise_position": 1e-4}})
OK = p.Result.OK


def fresh(pacing="lockstep", sim=SIM, **config) -> Host:
    host = Host(CoreDevice(sim, pacing, max_block=128))
    cfg = p.Config(**{"sample_rate": 1000, "current_limit": 5.0, "torque_constant": 0.2,
                      "counts_per_rev": 4096, **config})
    assert host.send(cfg)[0].result == OK
    assert host.send(p.Arm())[0].result == OK
    return host


def test_realtime_watchdog_zeroes_current_at_the_computed_sample():
    host = fresh("realtime", watchdog_timeout=0.1)
    for k in range(8):
        host.send(p.SetpointBlock(k, np.full(128, 1.0)), 100.0)  # t0 and the last host message: 100.0 s
    got = samples(host.tick(100.5))
    # sample k is at 100.0 + k ms; deadline 100.1 s -> sample 101 is the first after it
    assert len(got["current_cmd"]) == 102
    assert np.all(got["current_cmd"][:101] == 1.0) and got["current_cmd"][101] == 0.0
    assert got["status"][101] == p.SampleStatus.FAULT | p.SampleStatus.END
    s = host.device.status()
    assert (s["faults"], s["fault_index"], s["fault_silence"]) == (p.Fault.WATCHDOG, 101, 101)
    assert s["state"] == p.State.DISARMED and s["current_applied"] == 0.0
    # a second stream from k0 = 102, host silent from 200.05 s: k0 + floor(0.05*1000 + 0.1*1000) + 1
    host.send(p.ClearFaults(), 200.0)
    host.send(p.Arm(), 200.0)
    host.send(p.SetpointBlock(0, np.full(128, 1.0)), 200.0)
    host.send(p.SetpointBlock(1, np.full(128, 1.0)), 200.0)
    host.send(p.Heartbeat(1), 200.05)
    host.tick(200.5)
    s = host.device.status()
    assert (s["faults"], s["fault_index"]) == (p.Fault.WATCHDOG, 102 + 151)


def test_realtime_underrun_and_sequence_gap():
    host = fresh("realtime", watchdog_timeout=0.0)
    host.send(p.SetpointBlock(0, np.full(50, 0.5)), 0.0)
    got = samples(host.tick(0.2))  # 200 samples due, 50 buffered
    assert len(got["current_cmd"]) == 51 and got["current_cmd"][50] == 0.0
    assert host.device.status()["faults"] == p.Fault.BUFFER_UNDERRUN
    host.send(p.ClearFaults(), 0.3)
    host.send(p.Arm(), 0.3)
    host.send(p.SetpointBlock(0, np.full(10, 0.5)), 0.3)
    out = host.send(p.SetpointBlock(2, np.full(10, 0.5)), 0.3)  # block 1 lost on the link
    assert samples(out)["current_cmd"].tolist() == [0.0]
    s = host.device.status()
    assert s["faults"] == p.Fault.BUFFER_UNDERRUN and s["dropped_frames"] == 1


def test_disarm_and_estop_while_streaming_and_latching():
    host = fresh()
    host.send(p.SetpointBlock(0, np.full(100, 2.0)))
    host.tick()
    got = samples(host.send(p.Disarm()))
    assert got["current_cmd"].tolist() == [0.0] and got["status"][0] == p.SampleStatus.END
    assert host.device.status()["faults"] == 0 and host.device.status()["state"] == p.State.DISARMED
    host.send(p.Arm())
    host.send(p.SetpointBlock(0, np.full(100, 2.0)))
    out = host.send(p.EStop())
    assert out[-1] == p.Reply(p.MsgType.ESTOP, p.Result.OK, p.Fault.ESTOP)
    assert host.send(p.Arm())[0].result == p.Result.FAULT_LATCHED
    # faults survive a reconfiguration; only CLEAR_FAULTS clears them
    host.send(p.Config(sample_rate=2000))
    assert host.device.status()["faults"] == p.Fault.ESTOP
    host.send(p.ClearFaults())
    assert host.send(p.Arm())[0].result == OK


def test_unconfigured_and_invalid_requests():
    host = Host(CoreDevice(SIM))
    assert host.send(p.Arm())[0].result == p.Result.NOT_CONFIGURED
    assert host.send(p.GetConfig())[0].result == p.Result.NOT_CONFIGURED
    assert host.send(p.Config(sample_rate=1234))[0].result == p.Result.INVALID_CONFIG
    assert host.send(p.SetpointBlock(0, np.zeros(3))) == []
    assert host.device.status()["dropped_frames"] == 1


BARE = sim_config_from_dict({"plant": {"preset": "none", "inertia": 1e-4, "viscous": 1e-3}})


def _accelerate(host: Host, u: np.ndarray, block: int) -> dict:
    """Stream ``u`` in blocks of ``block`` setpoints, one tick after each (limits judged across blocks)."""
    out = []
    for seq, start in enumerate(range(0, len(u), block)):
        out += host.send(p.SetpointBlock(seq, u[start:start + block], end=start + block >= len(u)))
        out += host.tick()
    return samples(out)


def test_over_speed_and_position_window_across_blocks_against_numpy():
    rate, cpr, limit = 2000, 4096, 10.0
    u = np.full(40, 1.0, dtype=np.float32)  # 1 A * 0.2 N m/A on 1e-4 kg m^2: 2000 rad/s^2, 10 rad/s at 5 ms
    free = _accelerate(fresh(sim=BARE, sample_rate=rate, counts_per_rev=cpr), u, 40)
    counts = free["counts"].astype(np.int64)
    # oracle: v[k] = 2*pi/cpr * (c[k] - c[k-W]) / (W*dt), W = rate/1000, the motor at rest at c[0] before
    w = rate // 1000
    hist = np.concatenate([np.full(w, counts[0]), counts])
    v = (hist[w:] - hist[:-w]) * (2 * math.pi / cpr) * rate / w
    j = int(np.argmax(np.abs(v) > limit))
    assert 3 < j < 39 and counts[j] > counts[j - 1]
    # the window's top between sample j-1 and j: both limits trip at j
    top = (counts[j - 1] + counts[j]) / 2 * 2 * math.pi / cpr
    host = fresh(sim=BARE, sample_rate=rate, counts_per_rev=cpr, velocity_limit=limit, position_max=top)
    got = _accelerate(host, u, 3)  # blocks of 3: the 2-sample window straddles block boundaries
    assert len(got["counts"]) == j + 1 and np.array_equal(got["counts"], counts[:j + 1])
    assert np.all(got["current_cmd"][:j] == 1.0) and got["current_cmd"][j] == 0.0
    assert got["status"][j] == p.SampleStatus.FAULT | p.SampleStatus.END
    s = host.device.status()
    assert (s["faults"], s["fault_index"]) == (p.Fault.OVER_SPEED | p.Fault.POSITION_WINDOW, j)
    # a later fault adds its bit; the first fault's sample is kept
    host.send(p.EStop())
    s = host.device.status()
    assert (s["faults"], s["fault_index"]) == (p.Fault.OVER_SPEED | p.Fault.POSITION_WINDOW | p.Fault.ESTOP, j)


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


def test_cli_bad_config_is_one_line(tmp_path, starts_devices):
    bad = tmp_path / "bad.toml"
    bad.write_text("[plant]\ninertia = -1\n")
    res = subprocess.run([sys.executable, "-m", "hilbench.firmware_sim", "--serial", "--config", str(bad)],
                         capture_output=True, text=True, timeout=30)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and "error" in res.stderr and "Traceback" not in res.stderr


def test_the_device_plant_is_the_plant_bit_for_bit_sample_by_sample():
    """The HAL steps the plant one sample per call and carries hb_run's Maxwell-slip cache from call to call
    (hb_run_cached) instead of rebuilding it: the counts and measured currents are those of one hb_run over the
    whole input (firmware_sim.engine.plant.Plant, an independent call path), bit for bit, through reversals that
    make the cache rebuild itself (16 elements, current noise, position noise)."""
    from hilbench.firmware_sim.engine.plant import Plant

    sim = sim_config_from_dict({"device": {"buffer_capacity": 4096},
                                "plant": {"elements": 16, "seed": 11, "noise_current": 0.01, "noise_position": 2e-5}})
    rate, n = 2000, 3000
    u = (1.5 * np.sin(2 * np.pi * 3.0 * np.arange(n) / rate) * np.exp(-np.arange(n) / 1500)).astype(np.float32)
    host = fresh(sim=sim, sample_rate=rate, current_limit=4.0)
    got = _accelerate(host, u, 128)
    plant = Plant(sim.plant_for(4.0, 0.2, 4096), 1.0 / rate, sim.substeps_at(rate), "current")
    want = plant.run(u.astype(np.float64))
    assert np.array_equal(got["counts"], want.counts.astype(np.int32))
    assert np.array_equal(got["current_meas"], want.current_meas.astype(np.float32))
    assert len(np.unique(np.sign(np.diff(want.theta[want.theta != 0])))) > 1  # the motion reversed
