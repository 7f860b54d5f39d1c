"""Plant steps per second: C engine against the pure-Python oracle and a numpy version, same run.

Input: the random-enveloped identification excitation at 10 kHz, one RK4 sub-step per sample.
"""

from __future__ import annotations

import time

import numpy as np

from hilbench.firmware_sim.engine.friction_models import DC_MOTOR_BREAKAWAY, DC_MOTOR_D, dc_motor
from hilbench.firmware_sim.engine.plant import GMS, Hysteresis, LuGre, Plant, PlantParams
from tests.firmware_sim.reference import reference_simulate


def numpy_simulate(params, u, dt):
    """Semi-vectorised twin: a Python loop over samples, numpy over the elements (RK4 as in plant.c)."""
    k = np.asarray(params.ms_stiffness, float)
    delta = params.ms_delta
    defl = np.zeros_like(k)
    J, b = params.inertia, params.viscous
    th = om = 0.0
    theta = np.empty(u.size)
    for i, tau_i in enumerate(u * params.torque_constant):
        theta[i] = th

        def acc(x, v, th0=th, tau=tau_i, d0=defl):
            return (tau - k @ np.clip(d0 + (x - th0), -delta, delta) - b * v) / J

        k1x, k1v = om, acc(th, om)
        k2x = om + 0.5 * dt * k1v
        k2v = acc(th + 0.5 * dt * k1x, k2x)
        k3x = om + 0.5 * dt * k2v
        k3v = acc(th + 0.5 * dt * k2x, k3x)
        k4x = om + dt * k3v
        k4v = acc(th + dt * k3x, k4x)
        th_new = th + dt / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
        om = om + dt / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
        defl = np.clip(defl + (th_new - th), -delta, delta)
        th = th_new
    return theta


def excitation(n: int, dt: float, seed: int = 0) -> np.ndarray:
    """The identification input the bench uses (science.md §6): uniform noise low-passed at 40 Hz times a
    three-term square-wave envelope of period 2 s, scaled to +-6 A (about 1.6x break-away)."""
    from scipy.signal import butter, sosfiltfilt

    t = np.arange(n) * dt
    noise = sosfiltfilt(butter(4, 40.0, fs=1 / dt, output="sos"), np.random.default_rng(seed).uniform(-1, 1, n))
    w = 2 * np.pi / 2.0
    env = 4 / np.pi * (np.sin(w * t) + np.sin(3 * w * t) / 3 + np.sin(5 * w * t) / 5)
    u = noise * env
    return 6.0 * u / np.max(np.abs(u))


def _rate(fn, n) -> float:
    t0 = time.perf_counter()
    fn()
    return n / (time.perf_counter() - t0)


def model_motors() -> dict[str, PlantParams]:
    """The DC motor of ``dc_motor(16)`` with its Maxwell-slip friction replaced by each state-variable model of
    about the same initial stiffness (~3000 N*m/rad) and break-away (0.76 N*m to 0.9 N*m), viscous kept."""
    ms = dc_motor(16)
    w = np.asarray(ms.ms_slip)
    bare = ms.replace(ms_stiffness=(), ms_slip=())
    stribeck = {"static": 0.9, "stribeck_velocity": 0.05}
    return {
        "LuGre": bare.replace(lugre=LuGre(sigma0=float(np.sum(ms.ms_stiffness)), coulomb=DC_MOTOR_BREAKAWAY,
                                          sigma1=0.5, **stribeck)),
        "GMS N=16": bare.replace(gms=GMS(stiffness=ms.ms_stiffness, fractions=tuple(w / w.sum()),
                                         coulomb=DC_MOTOR_BREAKAWAY, attraction=100.0, **stribeck)),
        "continuous hysteresis": bare.replace(hysteresis=Hysteresis(h=DC_MOTOR_BREAKAWAY, d=DC_MOTOR_D, stack=64)),
    }


def model_rows(quick: bool) -> list[dict]:
    """Steps/s of each friction model beside Maxwell-slip N=16, same input, same run, best of 3 interleaved."""
    dt = 1e-4
    n = 200_000 if quick else 2_000_000
    u = excitation(n, dt)
    plants = {"Maxwell-slip N=16": dc_motor(16), **model_motors()}
    rates = dict.fromkeys(plants, 0.0)
    for _ in range(3):
        for name, p in plants.items():
            rates[name] = max(rates[name], _rate(lambda p=p: Plant(p, dt).run(u), n))
    base = rates["Maxwell-slip N=16"]
    return [{"name": f"C plant {name}", "value": rate, "unit": "steps/s",
             "baseline_name": "C plant Maxwell-slip N=16", "baseline_value": base, "ratio": rate / base,
             "target": None, "ok": None} for name, rate in rates.items() if name != "Maxwell-slip N=16"]


def run(quick: bool = False) -> list[dict]:
    rows = model_rows(quick)
    dt = 1e-4
    for n_el in (16, 256):
        p = dc_motor(n_el)
        n_c = 200_000 if quick else 4_000_000
        n_py = 2_000 if quick else 10_000
        u = excitation(n_c, dt)
        plant = Plant(p, dt)
        plant.run(u[:1000])  # warm-up
        # best of 3, interleaved, for both sides: the machine's load hits them alike
        c_rate = oracle_rate = numpy_rate = 0.0
        for _ in range(3):
            c_rate = max(c_rate, _rate(lambda p=p, u=u: Plant(p, dt).run(u), n_c))
            oracle_rate = max(oracle_rate, _rate(lambda p=p, u=u[:n_py]: reference_simulate(p, u, dt), n_py))
        numpy_rate = _rate(lambda p=p, u=u[:n_py]: numpy_simulate(p, u, dt), n_py)
        rows.append({"name": f"C plant N={n_el}", "value": c_rate, "unit": "steps/s",
                     "baseline_name": "python oracle", "baseline_value": oracle_rate,
                     "ratio": c_rate / oracle_rate, "target": ">= 300x oracle",
                     "ok": c_rate / oracle_rate >= 300})
        rows.append({"name": f"C plant N={n_el} vs numpy", "value": c_rate, "unit": "steps/s",
                     "baseline_name": "numpy per-step", "baseline_value": numpy_rate,
                     "ratio": c_rate / numpy_rate, "target": None, "ok": None})
        if n_el == 16:
            rows.append({"name": "C plant N=16 absolute", "value": c_rate, "unit": "steps/s",
                         "baseline_name": None, "baseline_value": None, "ratio": None,
                         "target": ">= 5e6 steps/s on one core", "ok": c_rate >= 5e6})
    return rows
