"""AFRF from stepped-sine run files (written by bench's RunWriter, read by analysis with h5py) and the
``hilbench afrf`` command."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal

from hilbench.analysis.afrf.frf import afrf_from_run
from hilbench.analysis.errors import AnalysisError
from hilbench.bench.acquisition.excitations import stepped_sine
from hilbench.bench.cli import main as bench_main
from hilbench.common import runfile as rf
from hilbench.firmware_sim.engine.plant import PlantParams, simulate

FS = 1000.0
M, K, C = 1.0, 50.0, 10.0  # damping rate zeta*w_n = C/(2M) = 5 1/s: a step's transient dies within its settle


def _write_run(path, params, freqs, amps, settle=20, measure=4, keep=None, windows=True):
    exc = stepped_sine(FS, frequencies=freqs, amplitudes=amps, settle_periods=settle, measure_periods=measure)
    out = simulate(params, exc.u, 1.0 / FS)
    n = exc.u.size if keep is None else keep
    k = np.arange(n)
    with rf.RunWriter(path, sample_rate=FS, protocol_name="stepped_sine", protocol_params=exc.protocol(),
                      protocol_arrays={"step_windows": exc.windows} if windows else {"setpoints": exc.u}) as w:
        w.append({"sample_index": k, "t": k / FS, "current_cmd": exc.u[:n], "current": exc.u[:n],
                  "torque": out.torque[:n], "position": out.theta[:n], "counts": np.zeros(n, np.int64)})
    return exc


def _zoh_frf(f: float) -> complex:
    num, den, _ = signal.cont2discrete(([1.0], [M, C, K]), 1.0 / FS, method="zoh")
    z = np.exp(1j * 2 * np.pi * f / FS)
    return complex(np.polyval(np.ravel(num), z) / np.polyval(den, z))


def test_afrf_from_run_matches_zoh_frf(tmp_path):
    """A linear system run through the bench's stepped sine (continuous across steps, frequency snapped to
    whole periods: 3 Hz plays 3.00075 Hz at 333.25 samples per period) and written to a run file: |X(f)|/G
    equals the sampled-data FRF at the played frequency to 1e-5 (the step change's transient decays as
    exp(-5 t): after 20 settle periods, 3.3 s at 6 Hz, it is below 1e-7). 2f and 3f of a linear system
    are < 1e-6 of 1f."""
    path = tmp_path / "afrf.h5"
    exc = _write_run(path, PlantParams(inertia=M, spring=K, viscous=C), [1.0, 3.0, 6.0], [0.5, 2.0])
    r = afrf_from_run(path)
    played = np.unique(exc.windows["frequency"])
    np.testing.assert_allclose(r.frequencies, played, rtol=1e-12)
    assert r.frequencies[1] == pytest.approx(3.00075, abs=1e-5)
    np.testing.assert_array_equal(r.amplitudes, [0.5, 2.0])
    assert r.amplitude_unit == "A" and r.displacement_unit == "rad" and r.drive_unit == "N*m"
    zoh = np.abs([_zoh_frf(f) for f in r.frequencies])
    for i, g in enumerate(r.amplitudes):
        np.testing.assert_allclose(r.magnitudes[i, :, 0] / g, zoh, rtol=1e-5)
        np.testing.assert_allclose(np.abs(r.drive[i]), g, rtol=1e-9)
    assert np.max(r.magnitudes[..., 1:] / r.magnitudes[..., :1]) < 1e-6


def test_afrf_from_aborted_run_marks_missing_steps(tmp_path):
    path = tmp_path / "aborted.h5"
    exc = _write_run(path, PlantParams(inertia=M, spring=K, viscous=C), [1.0, 3.0], [0.5, 2.0], keep=None)
    cut = int(exc.windows["measure_stop"][2]) + 10  # the first three steps are complete
    path2 = tmp_path / "cut.h5"
    _write_run(path2, PlantParams(inertia=M, spring=K, viscous=C), [1.0, 3.0], [0.5, 2.0], keep=cut)
    full, part = afrf_from_run(path), afrf_from_run(path2)
    assert np.isnan(part.magnitudes[1, 1]).all() and np.isfinite(part.magnitudes[:1]).all()
    np.testing.assert_array_equal(part.response[0], full.response[0])
    _write_run(tmp_path / "none.h5", PlantParams(inertia=M, spring=K, viscous=C), [1.0], [0.5], keep=100)
    with pytest.raises(AnalysisError, match="no step's measure window is complete"):
        afrf_from_run(tmp_path / "none.h5")


def test_bad_runs(tmp_path, capsys):
    no_windows = tmp_path / "chirp.h5"
    _write_run(no_windows, PlantParams(inertia=M, spring=K, viscous=C), [2.0], [1.0], windows=False)
    with pytest.raises(AnalysisError, match="no step windows"):
        afrf_from_run(no_windows)
    assert bench_main(["afrf", str(no_windows)]) == 2
    err = capsys.readouterr().err
    assert "no step windows" in err and err.count("\n") == 1 and "Traceback" not in err

    # a measure window shorter than one period of its frequency
    short = tmp_path / "short.h5"
    exc = stepped_sine(FS, frequencies=[2.0], amplitudes=[1.0], settle_periods=1, measure_periods=1)
    win = exc.windows.copy()
    win["measure_stop"] = win["measure_start"] + 300  # 0.6 of a 2 Hz period
    k = np.arange(exc.u.size)
    with rf.RunWriter(short, sample_rate=FS, channels=("sample_index", "t", "position"),
                      protocol_params=exc.protocol(), protocol_arrays={"step_windows": win}) as w:
        w.append({"sample_index": k, "t": k / FS, "position": np.sin(k / 50.0)})
    with pytest.raises(AnalysisError, match="at least one whole period"):
        afrf_from_run(short)

    with pytest.raises(AnalysisError, match="no such run file"):
        afrf_from_run(tmp_path / "missing.h5")
    foreign = tmp_path / "foreign.h5"
    foreign.write_bytes(b"not hdf5")
    assert bench_main(["afrf", str(foreign)]) == 2
    assert "not an HDF5 file" in capsys.readouterr().err


def test_cli_run_json_plot(tmp_path, capsys):
    path = tmp_path / "afrf.h5"
    _write_run(path, PlantParams(inertia=M, spring=K, viscous=C), [1.0, 3.0], [0.5, 2.0])
    out, png = tmp_path / "afrf.json", tmp_path / "afrf.png"
    assert bench_main(["afrf", str(path), "--json", str(out), "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "2 amplitudes x 2 frequencies" in text
    doc = json.loads(out.read_text())
    assert doc["magnitude_unit"] == "rad" and len(doc["magnitude"]) == 2 and len(doc["magnitude"][0][0]) == 3
    assert doc["magnitude"][1][0][0] == pytest.approx(afrf_from_run(path).magnitudes[1, 0, 0], rel=1e-12)
    assert png.stat().st_size > 5000


def test_cli_model(tmp_path, capsys):
    out = tmp_path / "c.json"
    argv = ["afrf", "--model", "coulomb", "--amplitudes", "1", "10", "--log-frequencies", "0.5", "2", "2",
            "--settle-periods", "10", "--settle-time", "0", "--measure-periods", "2",
            "--samples-per-period", "200", "--workers", "1", "--json", str(out)]
    assert bench_main(argv) == 0
    doc = json.loads(out.read_text())
    assert doc["magnitude_unit"] == "m" and doc["amplitude_unit"] == "N"  # the paper's systems are a mass
    mag = np.array(doc["magnitude"], dtype=float)
    assert mag[0].max() < 1e-15  # G = 1 < Fc = 1.5: stuck
    # G = 10, f = 0.5 Hz: the describing function sqrt(G^2 - (4Fc/pi)^2)/w^2 within its 1.5 % (test_afrf)
    w = 2 * np.pi * 0.5
    assert mag[1, 0, 0] == pytest.approx(np.sqrt(100 - (6 / np.pi) ** 2) / w**2, rel=0.015)
    assert bench_main(["afrf"]) == 2
    assert "either" in capsys.readouterr().err
