"""Imports of real data (EMPS, HSM150) and CSV: round trips, and units/lengths/ranges checked against the
data sets' READMEs (EMPS ships in tests/data/emps/; the others come from $HILBENCH_REAL_DATA, see
tests/real_data.py)."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.io import loadmat, savemat

from hilbench.bench.cli import main as bench_main
from hilbench.bench.storage import importers
from hilbench.common.runfile import open_run
from tests import real_data

EMPS, EMPS_PULSES = real_data.EMPS_TRAIN, real_data.EMPS_TEST
_HSM_DIR = real_data.real_data("hsm150")
HSM = sorted(_HSM_DIR.glob("idf_*.mat")) if _HSM_DIR else []
needs_hsm = real_data.needs("hsm150")


def _one_line_error(capsys, argv, pattern):
    assert bench_main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert pattern in err, err


# ---- EMPS -------------------------------------------------------------------------------------------------


def test_emps_vendored_files_are_the_published_ones():
    # tests/data/emps/README.md lists the digests of the benchmark's files; a clone has them (no skip)
    readme = (real_data.EMPS / "README.md").read_text()
    for path in (EMPS, EMPS_PULSES):
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        assert f"| {path.name} | {digest} |" in readme
    assert "Janot" in readme and "Licence" in readme


@pytest.mark.parametrize("source", [EMPS, EMPS_PULSES], ids=["train", "pulses"])
def test_emps_import_round_trip_and_readme_facts(tmp_path, capsys, source):
    out = tmp_path / "emps.h5"
    assert bench_main(["import", "emps", str(source), "-o", str(out)]) == 0
    assert "24841 samples at 1000 Hz, linear axis" in capsys.readouterr().out
    mat = loadmat(source)
    with open_run(out) as run:
        # README: every signal is (24841, 1), 1 kHz, t = 0 ... 24.84 s; linear axis in m and N
        assert run.status == "completed" and run.axis == "linear" and run.meta["source"] == "import:emps"
        assert run.n_samples == 24841 and run.sample_rate == 1000.0
        assert run.t[0] == 0.0 and run.t[-1] == pytest.approx(24.84, abs=1e-9)
        assert run.unit("position") == "m" and run.unit("position_cmd") == "m"
        assert run.unit("force") == "N" and run.unit("torque") == "N" and run.unit("drive_voltage") == "V"
        # round trip: stored arrays are the source arrays, bit for bit; force = gtau * vir
        np.testing.assert_array_equal(run.t, mat["t"].ravel())
        np.testing.assert_array_equal(run.channel("position"), mat["qm"].ravel())
        np.testing.assert_array_equal(run.channel("position_cmd"), mat["qg"].ravel())
        np.testing.assert_array_equal(run.channel("drive_voltage"), mat["vir"].ravel())
        np.testing.assert_array_equal(run.channel("force"), mat["gtau"][0, 0] * mat["vir"].ravel())
        # README scalars: gtau 35.1507 N/V, kp 160.18 1/s, kv 243.45 V/(m/s) (rounded: half the last digit)
        assert run.calibration["gtau"] == pytest.approx(35.1507, abs=5e-5)
        assert run.calibration["gtau_unit"] == "N/V"
        assert run.calibration["kp"] == pytest.approx(160.18) and run.calibration["kv"] == pytest.approx(
            243.45
        )
        vir = run.channel("drive_voltage")
        qm = run.channel("position")
        if source == EMPS:
            # README ranges (3-5 significant digits, so tolerance = half the last digit)
            assert vir.min() == pytest.approx(-4.33, abs=0.005) and vir.max() == pytest.approx(
                4.14, abs=0.005
            )
            assert qm.min() == pytest.approx(-2.2e-5, abs=5e-8) and qm.max() == pytest.approx(
                0.24638, abs=5e-6
            )
            # README: qm quantised in steps of 5e-8 m in DATA_EMPS
            np.testing.assert_allclose(qm / 5e-8, np.round(qm / 5e-8), atol=1e-6)
            assert "pulses" not in run.channels
        else:
            assert vir.min() == pytest.approx(-7.94, abs=0.005) and vir.max() == pytest.approx(
                9.03, abs=0.005
            )
            # README: pulses {0, 5}, a 1 Hz square wave toggling every 500 samples from sample 344
            pulses = run.channel("pulses")
            assert run.unit("pulses") == "V" and set(np.unique(pulses)) == {0.0, 5.0}
            toggles = np.nonzero(np.diff(pulses))[0] + 1
            assert toggles[0] == 344 and np.all(np.diff(toggles) == 500)


# ---- HSM150 -----------------------------------------------------------------------------------------------

# README: steady-state velocity (mean of last 1 s) and before the step; integers, so +-1 rad/s margin
HSM_AFTER = {
    "neg_0.04": (-206, -183),
    "neg_0.045": (-245, -239),
    "pos_0.06": (211, 245),
    "pos_0.065": (298, 306),
}
HSM_BEFORE = {"neg": (-171, -143), "pos": (139, 147)}
HSM_OPERATING_POINT = {"neg": -0.03, "pos": 0.05}


@needs_hsm
@pytest.mark.parametrize("source", HSM, ids=[p.stem for p in HSM])
def test_hsm150_loader_matches_readme(source):
    imp = importers.load_hsm150(source)
    s = imp.samples
    sign, final, _run = source.stem.split("_")[1:]
    # README: (20000, 7) at 1 kHz, t = 0 ... 19.999; rotary rad, rad/s, N*m, A
    assert imp.axis == "rotary" and imp.n_samples == 20000 and imp.sample_rate == 1000.0
    assert s["t"][0] == 0.0 and s["t"][-1] == pytest.approx(19.999, abs=1e-9)
    # torque command: operating point for 0-10 s, stepped at t = 10 s to the value in the file name
    before, after = s["t"] < 10.0 - 1e-9, s["t"] >= 10.0 - 1e-9
    np.testing.assert_allclose(s["torque_cmd"][before], HSM_OPERATING_POINT[sign], atol=1e-12)
    np.testing.assert_allclose(
        s["torque_cmd"][after], float(final) * (1 if sign == "pos" else -1), atol=1e-12
    )
    # measured torque equals Cu x current (README), Cu = 0.0458 N*m/A; tolerance: float rounding
    assert imp.calibration["Cu"] == 0.0458 and imp.calibration["Cu_unit"] == "N*m/A"
    np.testing.assert_allclose(s["torque"], 0.0458 * s["current"], rtol=0, atol=1e-12)
    # encoder quantum 2*pi/10000 rad: counts reproduce the position to float rounding
    np.testing.assert_allclose(s["counts"] * (2 * math.pi / 10000), s["position"], rtol=1e-12, atol=1e-12)
    assert np.all(s["position_cmd"] == 0.0)  # README: all zeros in these open-loop runs
    # README ranges: |velocity| <= ~311 rad/s, |position| <= ~4000 rad, current about -7.5 ... 5.7 A
    assert np.abs(s["velocity"]).max() <= 312 and np.abs(s["position"]).max() <= 4100  # "about 4000"
    assert s["current"].min() >= -7.6 and s["current"].max() <= 5.8
    lo, hi = HSM_AFTER[f"{sign}_{final}"]
    assert lo - 1 <= s["velocity"][s["t"] >= 19.0].mean() <= hi + 1
    lo, hi = HSM_BEFORE[sign]
    assert lo - 1 <= s["velocity"][(s["t"] >= 9.0) & (s["t"] < 10.0)].mean() <= hi + 1


@needs_hsm
def test_hsm150_import_round_trip(tmp_path, capsys):
    source = HSM[0]
    out = tmp_path / "hsm.h5"
    assert bench_main(["import", "hsm150", str(source), "-o", str(out)]) == 0
    data = loadmat(source)["data"]
    with open_run(out) as run:
        assert run.axis == "rotary" and run.n_samples == 20000
        expected_units = {
            "t": "s",
            "position": "rad",
            "velocity": "rad/s",
            "torque_cmd": "N*m",
            "torque": "N*m",
            "current": "A",
            "counts": "counts",
            "position_cmd": "rad",
        }
        for name, unit in expected_units.items():
            assert run.unit(name) == unit
        for name, col in (
            ("t", 0),
            ("position_cmd", 1),
            ("position", 2),
            ("velocity", 3),
            ("torque_cmd", 4),
            ("torque", 5),
            ("current", 6),
        ):
            np.testing.assert_array_equal(run.channel(name), data[:, col])
        assert run.protocol_params["source_sha256"] and run.device["name"] == "HSM150"
    # refusing to overwrite, one line
    _one_line_error(capsys, ["import", "hsm150", str(source), "-o", str(out)], "file exists")


# ---- CSV --------------------------------------------------------------------------------------------------


def _csv(path: Path, header: str, rows: np.ndarray) -> Path:
    np.savetxt(path, rows, delimiter=",", header=header, comments="", fmt="%.17g")
    return path


def test_csv_round_trip_with_current_and_map(tmp_path):
    t = np.arange(100) / 500.0
    theta = np.sin(t)
    current = np.cos(3 * t)
    speed = np.cos(t)
    src = _csv(
        tmp_path / "log.csv", "time_s,theta,current,speed,comment_id", np.c_[t, theta, current, speed, t * 0]
    )
    out = tmp_path / "log.h5"
    argv = [
        "import",
        "csv",
        str(src),
        "-o",
        str(out),
        "--torque-constant",
        "0.05",
        "--map",
        "t=time_s",
        "--map",
        "position=theta",
        "--map",
        "velocity=speed",
    ]
    assert bench_main(argv) == 0
    with open_run(out) as run:
        assert run.axis == "rotary" and run.n_samples == 100 and run.sample_rate == pytest.approx(500.0)
        np.testing.assert_array_equal(run.t, t)
        np.testing.assert_array_equal(run.channel("position"), theta)
        np.testing.assert_array_equal(run.channel("velocity"), speed)
        np.testing.assert_array_equal(run.channel("current"), current)
        np.testing.assert_allclose(run.channel("torque"), 0.05 * current, rtol=1e-15)
        assert run.unit("torque") == "N*m" and run.unit("velocity") == "rad/s"
        assert run.calibration == {"torque_constant": 0.05, "torque_constant_unit": "N*m/A"}
        assert run.protocol_params["ignored_columns"] == ["comment_id"]


def test_csv_linear_units_stay_honest(tmp_path):
    t = np.arange(10) / 100.0
    src = _csv(tmp_path / "lin.csv", "t,torque,position,velocity", np.c_[t, t * 3, t * 1e-3, t * 0 + 1e-3])
    out = tmp_path / "lin.h5"
    assert bench_main(["import", "csv", str(src), "-o", str(out), "--linear"]) == 0
    with open_run(out) as run:
        assert run.axis == "linear"
        assert (run.unit("force"), run.unit("position"), run.unit("velocity")) == ("N", "m", "m/s")
        np.testing.assert_array_equal(run.channel("force"), t * 3)


def test_csv_semicolon_and_quoted_header(tmp_path):
    src = tmp_path / "semi.csv"
    src.write_text('"t";"torque";"position"\n0;1.5;0\n0.001;1.25;0.5\n0.002;1;1\n')
    imp = importers.load_csv(src)
    np.testing.assert_array_equal(imp.samples["torque"], [1.5, 1.25, 1.0])
    assert imp.sample_rate == pytest.approx(1000.0)


def test_csv_bad_input_is_one_line_error(tmp_path, capsys):
    good = "t,torque,position\n0,1,0\n0.001,1,0\n0.002,1,0\n"
    cases = {
        "nan.csv": ("t,torque,position\n0,1,0\n0.001,nan,0\n0.002,1,0\n", "'torque' has 1 non-finite"),
        "empty_field.csv": ("t,torque,position\n0,1,0\n0.001,,0\n", "could not convert"),
        "missing.csv": ("t,position\n0,0\n0.001,0\n", "missing column(s): torque (or current with"),
        "current_no_k.csv": ("t,current,position\n0,1,0\n0.001,1,0\n", "missing column(s): torque"),
        "backwards.csv": ("t,torque,position\n0,1,0\n0.002,1,0\n0.001,1,0\n", "time must increase strictly"),
        "ragged.csv": ("t,torque,position\n0,1,0\n0.001,1\n", "csv"),
        "empty.csv": ("", "empty file"),
    }
    for name, (text, pattern) in cases.items():
        (tmp_path / name).write_text(text)
        _one_line_error(
            capsys, ["import", "csv", str(tmp_path / name), "-o", str(tmp_path / "x.h5")], pattern
        )
    (tmp_path / "good.csv").write_text(good)
    _one_line_error(
        capsys, ["import", "csv", str(tmp_path / "good.csv"), "--map", "torque"], "CHANNEL=COLUMN"
    )
    _one_line_error(
        capsys, ["import", "csv", str(tmp_path / "good.csv"), "--map", "torque=Tq"], "no column 'Tq'"
    )
    _one_line_error(
        capsys, ["import", "csv", str(tmp_path / "good.csv"), "--map", "speed=t"], "not a run-file"
    )
    _one_line_error(capsys, ["import", "csv", str(tmp_path / "nope.csv")], "no such file")
    assert not (tmp_path / "x.h5").exists()


# ---- corrupt .mat -----------------------------------------------------------------------------------------


def test_corrupt_mat_is_one_line_error(tmp_path, capsys):
    junk = tmp_path / "junk.mat"
    junk.write_bytes(b"MATLAB 5.0 MAT-file" + b"\0" * 10)
    _one_line_error(capsys, ["import", "emps", str(junk), "-o", str(tmp_path / "o.h5")], "junk.mat")
    partial = tmp_path / "partial.mat"
    savemat(partial, {"t": np.arange(5.0)[:, None]})
    _one_line_error(capsys, ["import", "emps", str(partial), "-o", str(tmp_path / "o.h5")], "'qm' is missing")
    _one_line_error(
        capsys, ["import", "hsm150", str(partial), "-o", str(tmp_path / "o.h5")], "'data' is missing"
    )
    truncated = tmp_path / "truncated.mat"
    truncated.write_bytes(EMPS.read_bytes()[:50_000])
    _one_line_error(capsys, ["import", "emps", str(truncated), "-o", str(tmp_path / "o.h5")], "truncated.mat")
    nan_mat = tmp_path / "nan.mat"
    data = np.zeros((10, 7))
    data[:, 0] = np.arange(10) / 1000
    data[3, 5] = np.nan
    savemat(nan_mat, {"data": data})
    _one_line_error(capsys, ["import", "hsm150", str(nan_mat), "-o", str(tmp_path / "o.h5")], "non-finite")
    assert not (tmp_path / "o.h5").exists()


# ---- Mnich rack-and-pinion ----------------------------------------------------------------------------------

_MNICH_DIR = real_data.real_data("mnich_rack_pinion")
MNICH = _MNICH_DIR / "a3MR.csv" if _MNICH_DIR else Path("a3MR.csv")


@real_data.needs("mnich_rack_pinion")
def test_mnich_import_matches_readme_and_identifies_the_mass(tmp_path, capsys):
    # README facts: one motion to -1981 rpm (0.66 m/s after the -rpm*20/1000/60 conversion), the load cell at
    # 2 kHz (0.539 s), reduced mass 24.7 kg. The identified mass from force and integrated speed is an
    # independent check of the whole chain (conversions, alignment, integration): measured 25.04 kg.
    out = tmp_path / "mn.h5"
    assert bench_main(["import", "mnich", str(MNICH), "-o", str(out)]) == 0
    assert "2000 Hz, linear axis" in capsys.readouterr().out
    with open_run(out) as run:
        assert run.status == "completed" and run.meta["source"] == "import:mnich"
        v = run.channel("velocity")
        assert np.max(v) == pytest.approx(1981 * 20 / 1000 / 60, rel=1e-3) and np.min(v) > -1e-9
        assert 0.5 < run.channel("t")[-1] < 0.54
        assert np.all(np.diff(run.channel("position")) >= -1e-12)  # one motion, forward
    model = tmp_path / "m.json"
    assert bench_main(["identify", str(out), "--thresholds", "0", "--coulomb", "--offset", "--json", str(model)]) == 0
    import json

    assert json.loads(model.read_text())["parameters"]["inertia"] == pytest.approx(24.7, rel=0.03)
    _one_line_error(capsys, ["import", "mnich", str(tmp_path / "none.csv"), "-o", str(tmp_path / "o.h5")],
                    "no such file")
