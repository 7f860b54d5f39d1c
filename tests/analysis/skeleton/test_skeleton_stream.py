"""The record-level skeleton: read whole, or chunk by chunk into a decimated copy (docs/long-runs.md, the stated
tolerances), and the warnings of its input (issue 28): a narrow amplitude range, a run that is no chirp."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hilbench.analysis import skeleton as sk
from hilbench.analysis.record import load_record
from hilbench.analysis.skeleton.streaming import Decimator, centred_chunks, decimation_factor
from hilbench.common.runfile import RunWriter
from hilbench.firmware_sim.engine.friction_models import paper_system
from hilbench.firmware_sim.engine.plant import PlantParams, simulate

FS = 1000.0


def _write_chirp(path, params, g, a=0.05, duration=40.0, protocol="chirp"):
    """G*sin(pi*a*t^2) on ``params``, the torque logged as a device logs it (hold_previous)."""
    n = int(duration * FS)
    t = np.arange(n) / FS
    out = simulate(params, g * np.sin(np.pi * a * t**2), 1 / FS, substeps=4)
    torque = np.insert(g * np.sin(np.pi * a * t[:-1] ** 2), 0, 0.0)
    with RunWriter(path, sample_rate=FS, channels=("sample_index", "t", "torque", "position"),
                   calibration={"inertia": params.inertia}, protocol_name=protocol,
                   protocol_params={"gain": g, "rate": a, "duration": duration}) as w:
        w.append({"sample_index": np.arange(n), "t": t, "torque": torque, "position": out.theta})


def _on(a_ref, a, y):
    return np.interp(np.log(a_ref), np.log(a), y)


def test_streamed_equals_whole_within_stated_tolerance(tmp_path):
    """The paper's system under a 40 s chirp at G = 5 N: read in chunks of 4096 samples and decimated by 18 (to
    55.6 Hz, 15x the band's 3.7 Hz top), the composed curves agree with the whole record's: k_eq and the
    restoring force within 1 % in every amplitude bin (measured 0.5 %), the energy per cycle and the damping
    force within 1 % in the median bin (measured 0.12 % each). The band is the whole record's exactly (a record
    shorter than one spectrum segment)."""
    path = tmp_path / "g5.h5"
    _write_chirp(path, paper_system(), 5.0)
    settings = sk.SkeletonSettings(spring=50.0)
    whole = sk.analyse([load_record(path)], settings)
    seen = []
    streamed = sk.analyse_stream([path], settings, chunk=4096, progress=lambda d, t: seen.append((d, t)))
    assert streamed.per_run[0]["read"].startswith("chunk by chunk, decimated by 18")
    assert seen[-1] == (2 * 40_000, 2 * 40_000)
    w, s = whole.curves, streamed.curves
    inside = (w.amplitude >= s.amplitude.min()) & (w.amplitude <= s.amplitude.max())
    assert inside.sum() >= 25
    for name in ("stiffness", "restoring_force"):
        rel = np.abs(_on(w.amplitude, s.amplitude, getattr(s, name)) / getattr(w, name) - 1)[inside]
        assert rel.max() < 0.01, (name, rel.max())
    rel_e = np.abs(_on(w.amplitude, s.amplitude, s.energy) / w.energy - 1)[inside]
    rel_d = np.abs(_on(w.velocity, s.velocity, s.damping_force) / w.damping_force - 1)
    assert np.median(rel_e) < 0.01 and np.median(rel_d) < 0.01, (np.median(rel_e), np.median(rel_d))
    assert whole.warnings == streamed.warnings == []
    doc = json.loads(sk.report(streamed, tmp_path / "out")[0].read_text())
    assert doc["per_run"][0]["read"] == streamed.per_run[0]["read"] and doc["warnings"] == []


def test_decimator_carries_state_across_chunks():
    """The anti-alias filter and the decimation phase carried across chunk edges: chunks of 7 samples give the
    whole signal's output to 1e-12; tones at the band's top (1/15 of the decimated rate) and at 2.2x it keep their
    amplitude within 3e-5, and a tone just above the new Nyquist frequency is attenuated below -60 dB."""
    fs, q = 1000.0, decimation_factor(1000.0, 2.0)
    assert q == 33
    t = np.arange(20_000) / fs
    fs_d = fs / q
    tones = (fs_d / 15, 2.2 * fs_d / 15, 0.55 * fs_d)
    x = np.vstack([np.sin(2 * np.pi * f * t) for f in tones])
    whole = Decimator(fs, q).push(x)
    dec = Decimator(fs, q)
    parts = np.concatenate([dec.push(x[:, i:i + 7]) for i in range(0, x.shape[1], 7)], axis=1)
    np.testing.assert_allclose(parts, whole, rtol=0, atol=1e-12)
    k = np.arange(whole.shape[1] // 2, whole.shape[1])  # past the start; amplitude by least squares at the tone
    checks = (lambda a: abs(a - 1) < 3e-5, lambda a: abs(a - 1) < 3e-5, lambda a: a < 1e-3)
    for row, (f, check) in enumerate(zip(tones, checks, strict=True)):
        w = 2 * np.pi * f * k * q / fs
        coef = np.linalg.lstsq(np.column_stack([np.sin(w), np.cos(w)]), whole[row, k], rcond=None)[0]
        assert check(float(np.hypot(*coef))), (row, np.hypot(*coef))


@pytest.mark.parametrize("timing", ["hold_previous", "hold_next", "instant"])
def test_centred_chunks_equal_whole(timing):
    """The force centred chunk by chunk (one sample carried) equals the whole channel's centring exactly."""
    rng = np.random.default_rng(1)
    x, f = rng.normal(size=103), rng.normal(size=103)
    pairs = [(x[i:i + 10], f[i:i + 10]) for i in range(0, 103, 10)]
    out = list(centred_chunks(pairs, timing))
    np.testing.assert_array_equal(np.concatenate([o[0] for o in out]), x)
    np.testing.assert_array_equal(np.concatenate([o[1] for o in out]), sk.centred_force(f, timing))


def test_warns_on_narrow_amplitude_range(tmp_path):
    """A stiff linear system (resonance 15.9 Hz) under a chirp to 2 Hz: its amplitude varies by 1.6 % only,
    under the 2x the skeleton needs, and the result says so, naming --gain."""
    path = tmp_path / "narrow.h5"
    _write_chirp(path, PlantParams(inertia=1.0, spring=1e4, viscous=10.0), 50.0)
    res = sk.analyse([load_record(path)], sk.SkeletonSettings())
    ratio = res.curves.amplitude.max() / res.curves.amplitude.min()
    assert ratio < 1.1
    assert len(res.warnings) == 1 and "too narrow" in res.warnings[0] and "--gain" in res.warnings[0]


def test_warns_on_a_run_that_is_no_chirp(tmp_path):
    """The same chirp data filed as an identification run: the skeleton warns that the run is no chirp."""
    path = tmp_path / "ident.h5"
    _write_chirp(path, paper_system(), 5.0, protocol="identification")
    res = sk.analyse([load_record(path)], sk.SkeletonSettings(spring=50.0))
    assert any("not a chirp" in w and "hilbench run chirp" in w for w in res.warnings), res.warnings


def test_a_host_clocked_run_is_read_whole_by_the_streamed_path(tmp_path):
    """A run sampled at its host_time (a CiA 402 drive) is resampled over the whole record by the loader, so the
    streamed path reads it whole: the same curves as :func:`analyse`, and it says so."""
    path = tmp_path / "host.h5"
    n = 20_000
    t = np.arange(n) / FS
    p = paper_system()
    out = simulate(p, 5.0 * np.sin(np.pi * 0.05 * t**2), 1 / FS, substeps=4)
    with RunWriter(path, sample_rate=FS, channels=("sample_index", "t", "torque", "position", "host_time"),
                   device={"sample_times": "host_time"},
                   calibration={"inertia": p.inertia}, protocol_name="chirp") as w:
        w.append({"sample_index": np.arange(n), "t": t, "host_time": t + 1e-5 * np.sin(t),
                  "torque": 5.0 * np.sin(np.pi * 0.05 * t**2), "position": out.theta})
    settings = sk.SkeletonSettings(spring=50.0)
    whole = sk.analyse([load_record(path)], settings)
    streamed = sk.analyse_stream([path], settings, chunk=1000)
    assert streamed.per_run[0]["read"].startswith("whole (a host-clocked run")
    np.testing.assert_array_equal(streamed.curves.stiffness, whole.curves.stiffness)
