"""The record-level AFRF: read whole or one step window at a time (the same result), its JSON/figure report, and
the warning when no drive amplitude reaches break-away (issue 28)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hilbench.analysis import afrf
from hilbench.analysis.afrf.steps import SLIDING_SLOPE, sliding_slopes
from hilbench.bench.acquisition.excitations import stepped_sine
from hilbench.common import runfile as rf
from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import PlantParams, simulate

FS = 1000.0


def _write(path, params, freqs, amps, settle=5, measure=10):
    """A stepped-sine run of ``params`` (drive in A; the plant's torque constant applies) written as the bench
    writes one."""
    exc = stepped_sine(FS, frequencies=freqs, amplitudes=amps, settle_periods=settle, measure_periods=measure)
    out = simulate(params, exc.u, 1.0 / FS)
    n = exc.u.size
    k = np.arange(n)
    with rf.RunWriter(path, sample_rate=FS, protocol_name="stepped_sine", protocol_params=exc.protocol(),
                      protocol_arrays={"step_windows": exc.windows}) as w:
        w.append({"sample_index": k, "t": k / FS, "current_cmd": exc.u, "current": exc.u,
                  "torque": out.torque, "position": out.theta, "counts": np.zeros(n, np.int64)})
    return exc


def test_streamed_equals_whole_and_report(tmp_path):
    """Each step's harmonics use its own window only: read window by window from the file, the AFRF equals the
    whole record's bit for bit (tolerance 0); the progress callback reaches the measured samples' total."""
    path = tmp_path / "lin.h5"
    exc = _write(path, PlantParams(inertia=1.0, spring=50.0, viscous=10.0), [1.0, 3.0, 6.0], [0.5, 2.0])
    whole = afrf.analyse(afrf.load(path))
    seen = []
    streamed = afrf.analyse_stream(path, progress=lambda d, t: seen.append((d, t)))
    np.testing.assert_array_equal(streamed.response, whole.response)
    np.testing.assert_array_equal(streamed.drive, whole.drive)
    np.testing.assert_array_equal(streamed.convergence, whole.convergence)
    np.testing.assert_array_equal(streamed.frequencies, whole.frequencies)
    measured = int(np.sum(exc.windows["measure_stop"] - exc.windows["measure_start"]))
    assert seen[-1] == (measured, measured) and len(seen) == exc.windows.size
    paths = afrf.report(streamed, tmp_path / "out")
    doc = json.loads(paths[0].read_text())
    assert doc["warnings"] == streamed.warnings
    assert doc["magnitude"][1][2][0] == pytest.approx(float(whole.magnitudes[1, 2, 0]), rel=1e-15)
    assert paths[1].stat().st_size > 10_000


def test_warns_when_no_amplitude_reaches_breakaway(tmp_path):
    """The DC-motor preset breaks away at 0.76 N*m = 3.8 A. The default stepped sine (0.5 and 2 A at 1, 2, 5 Hz)
    stays in presliding: |X(f)| is rate-independent (slope ~0 > -0.5) and the AFRF warns, naming --amplitudes.
    With 8 A added, that amplitude slides (slope < -1) and there is no warning."""
    weak, strong = tmp_path / "weak.h5", tmp_path / "strong.h5"
    _write(weak, dc_motor(), [1.0, 2.0, 5.0], [0.5, 2.0])
    _write(strong, dc_motor(), [1.0, 2.0, 5.0], [0.5, 2.0, 8.0])
    r = afrf.analyse(afrf.load(weak))
    slopes = sliding_slopes(r)
    assert np.all(np.abs(slopes) < 0.2), slopes
    assert len(r.warnings) == 1 and "break-away" in r.warnings[0] and "--amplitudes" in r.warnings[0]
    s = afrf.analyse_stream(strong)
    slopes = sliding_slopes(s)
    assert slopes[-1] < 2 * SLIDING_SLOPE and np.all(np.abs(slopes[:2]) < 0.2), slopes
    assert s.warnings == []
