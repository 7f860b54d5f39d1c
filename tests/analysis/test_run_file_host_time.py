"""Host-clocked records on their host_time: closed forms of the resampling, and identification of a run whose
samples were taken with jitter (stalls, then overdue cycles back to back) against the same run un-jittered.

The jittered record is what a CiA 402 drive produces: command k held from SYNC k to SYNC k+1, position and
current sampled at each SYNC. It comes from the C plant run on a 50 us grid (20 steps per 1 ms cycle) with
the SYNC times rounded to that grid; the analysis only gets the samples and the SYNC times.
"""

import json

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.identify import RunArrays, identify
from hilbench.analysis.identification.maxwell_fit import LipSettings
from hilbench.analysis.identification.regressors import reversal_travels
from hilbench.analysis.record import on_host_time, resample_host_clocked

RATE, FINE, KT, CPR = 1000, 20, 0.2, 1 << 20  # Hz, plant steps per cycle, N*m/A, counts/rev


def _irregular(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.uniform(0.05e-3, 3e-3, n))  # s: 0.05 to 3 ms between samples


def test_a_cubic_sampled_at_irregular_times_is_reproduced_exactly():
    s = _irregular(400, 1)
    poly = np.polynomial.Polynomial([0.3, -2.0, 40.0, -900.0])  # rad, over ~0.6 s
    t, r = resample_host_clocked(s, RATE, {"x": (poly(s - s[0]), "instant")})
    assert t[0] == 0 and np.allclose(np.diff(t), 1 / RATE) and t[-1] <= s[-1] - s[0] < t[-1] + 1 / RATE
    np.testing.assert_allclose(r["x"], poly(t), rtol=0, atol=1e-12 * np.abs(poly(t)).max())


def _means_by_overlap(edges: np.ndarray, held: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Mean of the step function (held[i] on [edges[i], edges[i+1])) over each [t_j, t_j + 1/RATE),
    by explicit overlaps (the oracle)."""
    out = np.zeros(t.size)
    for j, a in enumerate(t):
        b = a + 1 / RATE
        overlap = np.clip(np.minimum(edges[1:], b) - np.maximum(edges[:-1], a), 0, None)
        out[j] = overlap @ held * RATE
    return out


def test_held_channels_keep_their_integral_and_their_timing():
    s = _irregular(300, 2)
    v = np.random.default_rng(3).normal(size=s.size)
    t, r = resample_host_clocked(s, RATE, {"next": (v, "hold_next"), "prev": (v, "hold_previous")})
    rel = s - s[0]
    edges = np.append(rel, rel[-1] + 1 / RATE)
    # hold_next: v[k] held over [s_k, s_k+1)
    np.testing.assert_allclose(r["next"], _means_by_overlap(edges, v, t), atol=1e-12)
    # hold_previous: v[k] is the mean over [s_k-1, s_k); out[j] the mean over [t_j-1, t_j)
    prev = _means_by_overlap(edges, np.append(v[1:], v[-1]), t)
    np.testing.assert_allclose(r["prev"][1:], prev[:-1], atol=1e-12)
    assert r["prev"][0] == v[0]
    # the impulse of the held signal over the grid equals the record's
    span = t[-1] + 1 / RATE
    inside = np.clip(np.minimum(edges[1:], span) - edges[:-1], 0, None)
    assert r["next"].sum() / RATE == pytest.approx(inside @ v, abs=1e-12)


def test_bad_host_time_is_refused_in_one_line():
    with pytest.raises(AnalysisError, match="strictly increasing"):
        resample_host_clocked(np.array([0.0, 1e-3, 1e-3, 2e-3, 3e-3]), RATE, {})
    with pytest.raises(AnalysisError, match="unknown sample kind"):
        resample_host_clocked(np.arange(5) * 1e-3, RATE, {"x": (np.zeros(5), "sometimes")})


@pytest.fixture(scope="module")
def runs():
    """The same excitation on the plant, sampled every 1 ms (device-clocked) and with host jitter."""
    from hilbench.bench.acquisition import excitations
    from hilbench.firmware_sim.devices.sim_config import load_sim_config, substeps_for
    from hilbench.firmware_sim.engine.plant import simulate

    sim = load_sim_config()
    params = sim.plant_for(20.0, KT, CPR)
    u = excitations.random_enveloped(20.0, RATE, amplitude=16.0, period=4.0, offset=0.0, cutoff=40.0, seed=0,
                                     mode="current", limit=20.0).u
    n = u.size
    dt = 1.0 / (RATE * FINE)

    def sample(slots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Command k held over [slot_k, slot_k+1) plant steps; position (rad) and torque (N*m) at slot_k."""
        held = np.repeat(u, np.diff(np.append(slots, slots[-1] + FINE)))
        out = simulate(params, held, dt, substeps_for(params, dt))
        return out.counts[slots] * 2 * np.pi / CPR, out.current_meas[slots] * KT

    rng = np.random.default_rng(1)
    late = np.abs(rng.normal(0, 0.05, n))  # periods: 50 us (1 sigma) of lateness on every SYNC
    for k0 in rng.choice(n - 200, 12, replace=False):  # 12 stalls of 5..30 ms, then overdue SYNCs back to back
        stall = rng.uniform(5, 30)
        for j in range(int(stall) + 2):
            late[k0 + j] = max(late[k0 + j], stall - j + 0.03 * j)
    slots = np.rint(np.maximum.accumulate(np.arange(n) + late) * FINE).astype(np.int64)
    slots = np.maximum(slots, np.maximum.accumulate(slots - np.arange(n)) + np.arange(n))  # strictly increasing
    x0, tau0 = sample(np.arange(n) * FINE)
    x1, tau1 = sample(slots)
    return {"device": (np.arange(n) / RATE, tau0, x0), "host_time": slots * dt, "jittered": (tau1, x1),
            "plant": sim.plant}


def _model(t, tau, x):
    return identify(RunArrays(t, tau, x), settings=LipSettings(timing="hold_previous")).model


def test_identification_on_host_time_matches_the_device_clocked_run(runs):
    device = _model(*runs["device"])
    host_time = runs["host_time"]
    tau, x = runs["jittered"]
    d = np.diff(host_time)
    assert d.max() > 20e-3 and np.percentile(np.abs(d - 1e-3), 99) > 0.1e-3  # the jitter is there (UNFIT)
    t, xr, taur, line = on_host_time(host_time, RATE, x, tau, "hold_previous")
    assert line.startswith(f"resampled on host_time: {x.size} samples") and f"-> {t.size} at 1000 Hz" in line
    resampled = _model(t, taur, xr)
    naive = _model(np.arange(x.size) / RATE, tau, x)  # t = k/rate, as before
    j = runs["plant"].inertia
    # measured: device-clocked +0.33 %, resampled +0.41 %, t = k/rate -1.54 % (J error against the plant)
    assert abs(resampled.inertia - device.inertia) < 0.002 * j
    assert abs(naive.inertia - device.inertia) > 0.01 * j  # what the resampling removes
    # the virgin curve (presliding) of the two runs' models agree within 2 % RMS over the travels both saw
    q = 2 * np.pi / CPR
    grid = np.geomspace(2 * q, 0.5 * min(reversal_travels(runs["device"][2], 4 * q).max(),
                                         reversal_travels(xr, 4 * q).max()), 200)
    rms = np.sqrt(np.mean((resampled.virgin_curve(grid) / device.virgin_curve(grid) - 1) ** 2))
    assert rms < 0.02, rms


def test_identify_command_resamples_a_host_sampled_run(runs, tmp_path, capsys):
    from hilbench.bench.cli import main
    from hilbench.common.runfile import RunWriter

    tau, x = runs["jittered"]
    host_time = runs["host_time"]
    n = x.size
    path = tmp_path / "drive.h5"
    w = RunWriter(path, sample_rate=float(RATE), channels=("t", "sample_index", "current_cmd", "current",
                                                           "torque", "position", "counts", "host_time"),
                  device={"protocol": "CiA 402 over CANopen",
                                                              "sample_times": "host_time"},
                  calibration={"torque_constant": KT}, protocol_name="identification")
    k = np.arange(n)
    w.append({"sample_index": k, "t": k / RATE, "current_cmd": tau / KT, "current": tau / KT, "torque": tau,
              "position": x, "counts": np.rint(x * CPR / (2 * np.pi)), "host_time": 100.0 + host_time})
    w.finish("completed")
    out = tmp_path / "model.json"
    assert main(["identify", str(path), "--json", str(out), "-v"]) == 0  # the loader's notes are -v lines
    assert "resampled on host_time: 20000 samples" in capsys.readouterr().out
    samples = int(np.floor((host_time[-1] - host_time[0]) * RATE + 1e-9)) + 1
    assert json.loads(out.read_text())["data"]["train"]["samples"] == samples
