"""The simulated amplifier's drift ([drift] of its TOML): the winding temperature it reports in every SAMPLES
header (protocol v3) against the first-order thermal model's closed form, cooling between runs, and a wear
step that changes the sliding friction by its factor, judged by the steady velocity of the motor under a
constant current (closed form: J*domega/dt = kt*i - L*F0 - b*omega). No I/O: time is passed in explicitly."""

import math

import numpy as np
import pytest

from hilbench.drivers import protocol as p
from hilbench.firmware_sim.devices.core_c import CoreDevice
from hilbench.firmware_sim.devices.sim_config import SimConfigError, sim_config_from_dict
from tests.firmware.host import Host

RATE = 1000
CPR = 1 << 16
KT = 0.2


def stream(host: Host, u: np.ndarray, now: float = 0.0, block: int = 128) -> list[p.SampleBlock]:
    """Configure, arm and stream ``u`` (A), one tick after each setpoint block; the SAMPLES received."""
    cfg = p.Config(sample_rate=RATE, mode=p.Mode.CURRENT, current_limit=10.0, velocity_limit=1e4,
                   torque_constant=KT, counts_per_rev=CPR, watchdog_timeout=0.0)
    assert host.send(cfg, now)[0].result == p.Result.OK
    assert host.send(p.Arm(), now)[0].result == p.Result.OK
    out = []
    for seq, start in enumerate(range(0, len(u), block)):
        out += host.send(p.SetpointBlock(seq, u[start:start + block], end=start + block >= len(u)), now)
        out += host.tick(now)
    for _ in range(4):
        out += host.tick(now)
    blocks = [m for m in out if isinstance(m, p.SampleBlock)]
    assert sum(len(b) for b in blocks) == len(u)
    return blocks


def device(**drift) -> tuple[Host, CoreDevice]:
    sim = sim_config_from_dict({"device": {"buffer_capacity": 4096}, "drift": drift})
    dev = CoreDevice(sim, "lockstep", max_block=128)
    return Host(dev), dev


def test_identity_names_the_sensor_only_with_drift():
    for table, sensors in (({"plant": {}}, 0), ({"drift": {}}, p.Sensor.TEMPERATURE)):
        host = Host(CoreDevice(sim_config_from_dict(table), "lockstep"))
        (ident,) = host.send(p.GetIdentity())
        assert ident.protocol_version == 3 and ident.sensors == sensors


def test_temperature_follows_the_thermal_closed_form_and_cools_between_runs():
    """T(t) = T_amb + R_th*R_w*i^2*(1 - exp(-t/tau)) for a constant current from ambient; each header reads
    the temperature when its block leaves, after its last sample (or one more), to float32 rounding."""
    amb, r_th, r_w, tau, i = 20.0, 2.0, 1.5, 1.5, 3.0  # 0.6 N*m < 0.76 N*m break-away: the rotor stays put
    host, dev = device(ambient=amb, thermal_resistance=r_th, winding_resistance=r_w, thermal_time_constant=tau)
    blocks = stream(host, np.full(4 * RATE, i, dtype=np.float32))
    rise = r_th * r_w * i**2
    worst = 0.0
    for b in blocks:
        end = b.first_index + len(b)  # samples applied when the block left: end or end + 1
        want = [amb + rise * (1 - math.exp(-k / RATE / tau)) for k in (end, end + 1)]
        worst = max(worst, min(abs(b.temperature - w) for w in want))
    assert worst < 2e-5 * (amb + rise)  # float32 on the wire: 2**-24 relative, the recursion's rounding
    t_end = dev.drift_state()["temperature"]
    assert t_end == pytest.approx(amb + rise * (1 - math.exp(-4.0 / tau)), rel=1e-12)
    # between runs the winding cools for the wall-clock time that passes: the stream ended at 0 s, 3 s later
    host.tick(3.0)
    assert dev.drift_state()["temperature"] == pytest.approx(amb + (t_end - amb) * math.exp(-3.0 / tau), rel=1e-12)
    # and without [drift] the device reports nothing (NaN headers)
    plain = Host(CoreDevice(sim_config_from_dict({"device": {"buffer_capacity": 4096}}), "lockstep", max_block=128))
    assert all(math.isnan(b.temperature) for b in stream(plain, np.full(300, i, dtype=np.float32)))


def test_a_wear_step_scales_the_sliding_friction_by_its_factor():
    """Under a constant current the motor slides at omega_ss = (kt*i - L*F0)/b, F0 the plant's total slip
    force (0.76 N*m), b its viscous term: before the step L = 1 (60 rad/s), after it L = 1.1 (41 rad/s)."""
    step, at = 0.1, 250.0
    host, dev = device(wear_step=step, wear_step_distance=at)
    plant = sim_config_from_dict({}).plant
    f0, b, j = sum(plant.ms_slip), plant.viscous, plant.inertia
    i = 5.0
    blocks = stream(host, np.full(10 * RATE, i, dtype=np.float32))
    theta = np.concatenate([b_.counts for b_ in blocks]).astype(float) * 2 * np.pi / CPR
    t = np.arange(theta.size) / RATE
    omega = [(KT * i - level * f0) / b for level in (1.0, 1.0 + step)]
    k_step = int(np.argmax(theta >= at))  # the step acts at the next 50 ms parameter update
    assert 3.0 < t[k_step] < 5.5
    tau_m = j / b
    for lo, hi, want in ((2.5, t[k_step], omega[0]), (t[k_step] + 3.5, t[-1], omega[1])):
        sel = (t >= lo) & (t <= hi)
        measured = (theta[sel][-1] - theta[sel][0]) / (t[sel][-1] - t[sel][0])
        # the transient left after 2.5 s (before) or 3.5 s (after) is below exp(-4.5) of the step in omega
        assert measured == pytest.approx(want, rel=0.01), (lo, hi, measured, want, tau_m)
    state = dev.drift_state()
    assert state["level"] == pytest.approx(1.0 + step) and state["distance"] == pytest.approx(theta[-1], rel=1e-3)


def test_bad_drift_tables_are_one_line():
    for table, fragment in (({"wear_rat": 1.0}, "unknown [drift] key"), ({"wear_rate": "fast"}, "must be a number"),
                            ({"thermal_time_constant": 0.0}, "thermal_time_constant"),
                            ({"block": 0.0}, "block in (0, 10]")):
        with pytest.raises(SimConfigError) as info:
            sim_config_from_dict({"drift": table})
        assert fragment in str(info.value) and "\n" not in str(info.value)


def test_the_device_drifts_as_the_python_drift_laws_do():
    """Independent oracle: the same drift simulated by firmware_sim.engine.drift (Python, the C plant run block by
    block) and by the device's plant HAL (C, per sample). The Python laws heat with the measured current, the
    current at the start of each sample (0 A at sample 0), the HAL with the current held over it, so from ambient
    under a constant current the Python temperature at the start of sample k is the HAL's after k - 1 samples. A
    block's header reads the HAL after its last sample e or one more: Python's temperature at e + 2 or e + 3, to
    float32 rounding. The motion under 5 A (sliding; the friction level falls with the temperature and grows with
    wear) agrees to the encoder's resolution and 0.1 % of the distance."""
    from hilbench.firmware_sim.engine.drift import Drift, DriftState, simulate_drifting

    laws = {"thermal_time_constant": 2.0, "thermal_resistance": 2.0, "winding_resistance": 1.0,
            "level_temperature_coefficient": -0.01, "viscous_temperature_coefficient": 0.02, "wear_rate": 2e-4}
    # the level law reaches zero at 123 degC: the winding is declared to stay below 100 degC (5 A heat it to 73)
    host, dev = device(ambient=23.0, max_temperature=100.0, **laws)
    sim = sim_config_from_dict({"drift": {"ambient": 23.0, "max_temperature": 100.0, **laws}})
    i, n = 5.0, 4 * RATE
    u = np.full(n, i, dtype=np.float32)
    blocks = stream(host, u)
    counts = np.concatenate([b.counts for b in blocks]).astype(np.int64)
    params = sim.plant.replace(current_limit=10.0, torque_constant=KT, counts_per_rev=CPR)
    state = DriftState(temperature=23.0, ambient=23.0)
    out, temperature = simulate_drifting(params, u.astype(float), 1.0 / RATE, Drift(**laws), state,
                                         substeps=sim.substeps_at(RATE), block=0.05)
    worst = 0.0
    for b in blocks:
        e = b.first_index + len(b) - 1
        if e + 3 < n:
            worst = max(worst, min(abs(b.temperature - temperature[e + 2]), abs(b.temperature - temperature[e + 3])))
    assert worst < 1e-4  # K; float32 of ~66 degC is 4e-6 K
    drift_state = dev.drift_state()
    step = 2.0 * 1.0 * i**2 * (1 - math.exp(-1 / RATE / 2.0))  # at most one sample's rise, K (0.025 K)
    assert 0.0 < drift_state["temperature"] - state.temperature < 1.01 * step
    assert drift_state["distance"] == pytest.approx(state.distance, rel=1e-3)
    theta = counts * 2 * np.pi / CPR
    assert np.max(np.abs(theta - out.position_meas)) < 1e-3 * theta[-1] + 2 * np.pi / CPR
    assert theta[-1] > 100.0  # it slid: the wear term acted (level 1 + 2e-4/rad)
