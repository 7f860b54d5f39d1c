"""A lab's own data through ``hilbench import csv|mat``: units, header aliases, declared torque timing, gaps,
MAT v5 and v7.3, size bounds. Each test reproduces a defect a new user hit (issue #13 "Bringing your own data",
issue #12 items 8 and 12) and checks it is gone; the oracle is the simulated device run the file was made from.
"""

from __future__ import annotations

import json
import math

import h5py
import numpy as np
import pytest
from scipy.io import savemat

from hilbench.analysis.record import load_record
from hilbench.bench.cli import main
from hilbench.bench.storage import importers
from hilbench.common.runfile import open_run, run_torque_timing
from tests import real_data
from tests.bench.test_identify_command import _write_run


def _one_line_error(capsys, argv, *patterns):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for pattern in patterns:
        assert pattern in err, err
    return err


@pytest.fixture(scope="module")
def device_run(tmp_path_factory):
    """A simulated device run (DC motor, 2 kHz, 10 s; torque from the measured current: hold_previous)."""
    path = tmp_path_factory.mktemp("dev") / "device.h5"
    params = _write_run(path, 1)
    with open_run(path) as r:
        arrays = {name: np.asarray(r.channel(name)) for name in ("t", "position", "torque")}
    return path, params, arrays


def _lab_csv(path, arrays, header="Time [ms],theta [deg],torque [mN*m]", scale=(1e3, 180 / math.pi, 1e3)):
    cols = [arrays["t"] * scale[0], arrays["position"] * scale[1], arrays["torque"] * scale[2]]
    np.savetxt(path, np.c_[tuple(cols)], delimiter=",", header=header, comments="", fmt="%.17g")
    return path


def _identify(capsys, run, out):
    assert main(["identify", str(run), "--json", str(out), "-v"]) == 0  # the timing line is a -v line
    printed = capsys.readouterr().out
    return json.loads(out.read_text())["parameters"], printed


# ---- units and header aliases ------------------------------------------------------------------------------


def test_units_in_the_header_or_given_make_si(tmp_path, device_run, capsys):
    # Why: "a file in ms and degrees was accepted as 2 Hz, and identification returned J = 37.8 with no warning"
    _, params, arrays = device_run
    bare = _lab_csv(tmp_path / "bare.csv", arrays, header="time,theta,torque")
    _one_line_error(capsys, ["import", "csv", str(bare), "-o", str(tmp_path / "x.h5")],
                    "t has no unit and read as seconds gives 2 Hz", "--unit t=ms")
    assert not (tmp_path / "x.h5").exists()
    given = tmp_path / "given.h5"
    assert main(["import", "csv", str(bare), "-o", str(given), "--unit", "t=ms", "--unit", "position=deg",
                 "--unit", "torque=mN*m", "--torque-timing", "hold_previous"]) == 0
    headed = tmp_path / "headed.h5"
    src = _lab_csv(tmp_path / "lab.csv", arrays)
    assert main(["import", "csv", str(src), "-o", str(headed), "--torque-timing", "hold_previous"]) == 0
    capsys.readouterr()
    for run in (given, headed):
        with open_run(run) as r:
            assert r.sample_rate == pytest.approx(2000.0, rel=1e-9)
            assert r.protocol_params["source_units"] == {"t": "ms", "position": "deg", "torque": "mN*m"}
            assert r.protocol_params["units_assumed"] == []
            for name in ("t", "position", "torque"):  # back in SI: to float rounding of the round trip
                np.testing.assert_allclose(r.channel(name), arrays[name], rtol=1e-13, atol=1e-15)
        doc, _ = _identify(capsys, run, tmp_path / f"{run.stem}.json")
        assert doc["inertia"] == pytest.approx(params.inertia, rel=0.02)  # the 2 kHz bound of test_identify_command


@pytest.mark.parametrize("header", ["t,position,torque", "time,pos,tau", "Time [s],Position [rad],Torque [N*m]",
                                    "timestamp;angle;torque_Nm", "time_s\ttheta_rad\ttorque_mNm"])
def test_usual_header_aliases(tmp_path, header):
    # Why: "It has no `time` alias"
    sep = ";" if ";" in header else "\t" if "\t" in header else ","
    scale = 1e-3 if header.endswith("mNm") else 1.0
    src = tmp_path / "a.csv"
    src.write_text(header + "\n" + "\n".join(sep.join(f"{v:g}" for v in (k * 1e-3, 0.1 * k, 2.0 + k))
                                                for k in range(20)) + "\n")
    imp = importers.load_csv(src)
    assert imp.sample_rate == pytest.approx(1000.0)
    np.testing.assert_allclose(imp.samples["position"], 0.1 * np.arange(20), rtol=1e-15)
    np.testing.assert_allclose(imp.samples["torque"], scale * (2.0 + np.arange(20)), rtol=1e-15)


def test_encoder_counts_with_counts_per_rev(tmp_path, capsys):
    counts = np.array([0, 1, 5, 4096, 8191, -3], float)
    src = tmp_path / "enc.csv"
    np.savetxt(src, np.c_[np.arange(6) * 1e-3, counts, np.ones(6)], delimiter=",", header="t,position,torque",
               comments="", fmt="%.17g")
    _one_line_error(capsys, ["import", "csv", str(src), "--unit", "position=counts"], "--counts-per-rev")
    out = tmp_path / "enc.h5"
    assert main(["import", "csv", str(src), "-o", str(out), "--unit", "position=counts", "--counts-per-rev",
                 "4096"]) == 0
    with open_run(out) as r:
        np.testing.assert_allclose(r.channel("position"), counts * 2 * math.pi / 4096, rtol=1e-15)
        np.testing.assert_array_equal(r.channel("counts"), counts.astype(np.int64))
        assert r.calibration["counts_per_rev"] == 4096 and r.unit("position") == "rad"
    # a counts column and no position: the position comes from the counts
    src2 = tmp_path / "enc2.csv"
    np.savetxt(src2, np.c_[np.arange(6) * 1e-3, counts, np.ones(6)], delimiter=",", header="t,encoder,torque",
               comments="", fmt="%.17g")
    imp = importers.load_csv(src2, counts_per_rev=4096)
    np.testing.assert_allclose(imp.samples["position"], counts * 2 * math.pi / 4096, rtol=1e-15)


def test_file_without_time_column_takes_a_sample_rate(tmp_path, capsys):
    src = tmp_path / "nt.csv"
    src.write_text("theta,torque\n" + "".join(f"{0.1 * k},{k % 3}\n" for k in range(50)))
    _one_line_error(capsys, ["import", "csv", str(src)], "missing column(s): t")
    imp = importers.load_csv(src, sample_rate=500.0)
    np.testing.assert_array_equal(imp.samples["t"], np.arange(50) / 500.0)
    assert imp.sample_rate == pytest.approx(500.0) and imp.protocol_params["variables"]["t"] == "k/500 Hz"
    timed = tmp_path / "timed.csv"
    timed.write_text("t,theta,torque\n0,0,1\n0.001,0.1,1\n0.002,0.2,1\n")
    _one_line_error(capsys, ["import", "csv", str(timed), "--sample-rate", "1000"], "is the time already")


def test_unit_mistakes_are_one_line_errors(tmp_path, capsys):
    src = tmp_path / "u.csv"
    src.write_text("Time [ms],pos,torque\n0,0,1\n1,0.1,1\n2,0.2,1\n")
    _one_line_error(capsys, ["import", "csv", str(src), "--unit", "position=kg"],
                    "unit 'kg' is not a unit of angle", "deg")
    _one_line_error(capsys, ["import", "csv", str(src), "--unit", "t=s"], "says ms, --unit t=s")
    _one_line_error(capsys, ["import", "csv", str(src), "--unit", "speed=rpm"], "no channel or column 'speed'")
    _one_line_error(capsys, ["import", "csv", str(src), "--linear", "--unit", "position=deg"],
                    "not a unit of length")
    both = tmp_path / "both.csv"
    both.write_text("t,pos,position,torque\n0,0,0,1\n0.001,0,0,1\n")
    _one_line_error(capsys, ["import", "csv", str(both)], "'pos', 'position' all look like position", "--map")


# ---- torque timing -------------------------------------------------------------------------------------------


def test_declared_torque_timing_gives_the_device_model(tmp_path, device_run, capsys):
    # Why: "It takes no torque timing, so the same data gives another model through CSV: b 0.0063 instead of
    # 0.0037 (truth 0.004), and 11 elements instead of 18". The same samples, exported and imported with the
    # timing declared, must give the device run's model to float rounding; undeclared, they do not.
    path, params, arrays = device_run
    src = _lab_csv(tmp_path / "lab.csv", arrays)
    declared, undeclared = tmp_path / "declared.h5", tmp_path / "undeclared.h5"
    assert main(["import", "csv", str(src), "-o", str(declared), "--torque-timing", "hold_previous", "-v"]) == 0
    assert "torque timing: hold_previous (stored in the run file)" in capsys.readouterr().out
    assert main(["import", "csv", str(src), "-o", str(undeclared)]) == 0
    assert "torque timing: not declared; analyses will assume instant" in capsys.readouterr().out
    with h5py.File(declared, "r") as f:
        assert f.attrs["torque_timing"] == "hold_previous"
    with h5py.File(undeclared, "r") as f:
        assert "torque_timing" not in f.attrs
    assert load_record(declared).timing == "hold_previous"

    device, out_dev = _identify(capsys, path, tmp_path / "dev.json")
    assert "torque timing: hold_previous (default for device runs)" in out_dev
    same, out_same = _identify(capsys, declared, tmp_path / "same.json")
    assert "torque timing: hold_previous (declared in the run file)" in out_same
    other, out_other = _identify(capsys, undeclared, tmp_path / "other.json")
    assert "torque timing: instant (default for import:csv runs)" in out_other
    assert len(same["ms_stiffness"]) == len(device["ms_stiffness"])
    for key in ("inertia", "viscous"):
        assert same[key] == pytest.approx(device[key], rel=1e-9)
    np.testing.assert_allclose(same["ms_stiffness"], device["ms_stiffness"], rtol=1e-6)
    # measured: device b = 0.00437 (truth 0.004), undeclared 0.0151 and 10 elements instead of 13
    assert abs(device["viscous"] / params.viscous - 1) < 0.15
    assert abs(other["viscous"] / params.viscous - 1) > 1.0
    # residual reads the same attribute and says so
    assert main(["residual", str(declared), "--json", str(tmp_path / "r.json"), "-v"]) == 0
    assert f"{declared}: torque timing of torque: hold_previous (declared in the run file)" in capsys.readouterr().out


def test_run_torque_timing_precedence():
    assert run_torque_timing({"source": "device"}) == ("hold_previous", "default for device runs")
    assert run_torque_timing({"source": "import:csv"}) == ("instant", "default for import:csv runs")
    declared = {"source": "import:csv", "torque_timing": "hold_next"}
    assert run_torque_timing(declared) == ("hold_next", "declared in the run file")
    assert run_torque_timing(declared, "instant") == ("instant", "given")
    assert run_torque_timing(declared, channel="torque_cmd") == ("hold_next", "default for import:csv runs")


# ---- gaps ------------------------------------------------------------------------------------------------------


def test_gap_is_found_at_import_or_resampled(tmp_path, device_run, capsys):
    # Why: "It accepts gaps that `identify` later refuses, with no resampling offered"
    _, params, arrays = device_run
    keep = np.ones(arrays["t"].size, bool)
    keep[5000:5040] = False  # 40 samples (20 ms) lost after sample 4999 at t = 2.4995 s
    holed = {k: v[keep] for k, v in arrays.items()}
    src = _lab_csv(tmp_path / "holed.csv", holed, header="t,position,torque", scale=(1, 1, 1))
    _one_line_error(capsys, ["import", "csv", str(src), "-o", str(tmp_path / "x.h5")],
                    "a step of 0.0205 s after sample 4999 (line 5001, t = 2.4995 s)", "--resample linear")
    assert not (tmp_path / "x.h5").exists()
    out = tmp_path / "resampled.h5"
    assert main(["import", "csv", str(src), "-o", str(out), "--resample", "linear", "--torque-timing",
                 "hold_previous", "-v"]) == 0
    assert "resampled: linear interpolation" in capsys.readouterr().out
    with open_run(out) as r:
        t = r.channel("t")
        assert r.n_samples == arrays["t"].size and r.sample_rate == pytest.approx(2000.0)
        np.testing.assert_allclose(t, arrays["t"], atol=1e-12)
        # kept samples are unchanged; the filled ones are the straight line across the gap
        np.testing.assert_allclose(r.channel("position")[keep], arrays["position"][keep], atol=1e-12)
        line = np.interp(t[~keep], arrays["t"][[4999, 5040]], arrays["position"][[4999, 5040]])
        np.testing.assert_allclose(r.channel("position")[~keep], line, atol=1e-12)
        assert r.protocol_params["resampled"]["samples_before"] == keep.sum()
    doc, _ = _identify(capsys, out, tmp_path / "m.json")  # identify accepts what import wrote
    assert doc["inertia"] == pytest.approx(params.inertia, rel=0.05)


# ---- MAT ---------------------------------------------------------------------------------------------------------


def _mat73(path, variables):
    """A MATLAB v7.3 file as MATLAB writes it: HDF5 with a 512-byte user block, arrays transposed."""
    with h5py.File(path, "w", userblock_size=512) as f:
        for name, value in variables.items():
            a = np.asarray(value)
            if np.iscomplexobj(a):
                comp = np.empty(a.shape, dtype=[("real", "f8"), ("imag", "f8")])
                comp["real"], comp["imag"] = a.real, a.imag
                a = comp
            ds = f.create_dataset(name, data=a.T)
            ds.attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 23 12:00:00 2026 HDF5 schema 1.00 .")
        fh.seek(124)
        fh.write(b"\x00\x02IM")


@pytest.mark.parametrize("version", ["v5", "v7.3"])
def test_generic_mat_import(tmp_path, device_run, capsys, version):
    # Why: "There is no generic MAT importer, though most lab data is MATLAB"
    path, params, arrays = device_run
    n = arrays["t"].size
    variables = {"time": arrays["t"][:, None] * 1e3, "theta": np.degrees(arrays["position"])[:, None],
                 "log": np.c_[np.zeros(n), arrays["torque"]], "gain": np.array([[2.5]]), "note": "rig 3"}
    src = tmp_path / f"rig_{version}.mat"
    if version == "v5":
        savemat(src, variables)
    else:
        _mat73(src, {k: v for k, v in variables.items() if k != "note"})
    out = tmp_path / f"rig_{version}.h5"
    argv = ["import", "mat", str(src), "-o", str(out), "--map", "torque=log(:,2)", "--unit", "t=ms",
            "--unit", "position=deg", "--torque-timing", "hold_previous"]
    assert main(argv) == 0
    assert f"wrote {out}: {n} samples at 2000 Hz" in capsys.readouterr().out
    with open_run(out) as r:
        for name in ("t", "position", "torque"):
            np.testing.assert_allclose(r.channel(name), arrays[name], rtol=1e-13, atol=1e-15)
        assert r.meta["source"] == "import:mat" and r.meta["torque_timing"] == "hold_previous"
    device, _ = _identify(capsys, path, tmp_path / "dev.json")
    same, _ = _identify(capsys, out, tmp_path / "mat.json")
    assert same["inertia"] == pytest.approx(device["inertia"], rel=1e-9)


@pytest.mark.parametrize("version", ["v5", "v7.3"])
def test_complex_mat_data_is_refused(tmp_path, capsys, version):
    # Why (#12 item 12): "Complex MAT data loses its imaginary part silently"
    t = np.arange(10)[:, None] * 1e-3
    variables = {"t": t, "position": t * (1 + 1j), "torque": t}
    src = tmp_path / "c.mat"
    savemat(src, variables) if version == "v5" else _mat73(src, variables)
    _one_line_error(capsys, ["import", "mat", str(src), "-o", str(tmp_path / "c.h5")],
                    "variable 'position' is complex")
    data = np.zeros((10, 7), complex)
    data[:, 0] = np.arange(10) / 1000
    data[3, 5] = 1j
    savemat(tmp_path / "h.mat", {"data": data})
    _one_line_error(capsys, ["import", "hsm150", str(tmp_path / "h.mat"), "-o", str(tmp_path / "c.h5")],
                    "variable 'data' is complex")
    assert not (tmp_path / "c.h5").exists()


def test_mat_mistakes_are_one_line_errors(tmp_path, capsys):
    src = tmp_path / "m.mat"
    savemat(src, {"t": np.arange(5.0)[:, None], "position": np.arange(4.0)[:, None], "torque": np.ones((5, 1)),
                  "block": np.ones((5, 3))})
    _one_line_error(capsys, ["import", "mat", str(src)], "different lengths", "position: 4")
    _one_line_error(capsys, ["import", "mat", str(src), "--map", "torque=block(:,4)"], "no column 4")
    _one_line_error(capsys, ["import", "mat", str(src), "--map", "torque=nope(:,1)"], "no variable 'nope'")
    (tmp_path / "junk.mat").write_bytes(b"not a mat file at all" * 10)
    _one_line_error(capsys, ["import", "mat", str(tmp_path / "junk.mat")], "junk.mat")



def test_mat_variable_size_is_bounded_before_it_is_read(tmp_path, capsys, monkeypatch):
    t = np.arange(40)[:, None] * 1e-3
    savemat(tmp_path / "v5.mat", {"t": t, "position": t, "torque": t})
    _mat73(tmp_path / "v73.mat", {"t": t, "position": t, "torque": t})
    monkeypatch.setattr(importers, "MAX_IMPORT_SAMPLES", 2)
    for name in ("v5.mat", "v73.mat"):
        _one_line_error(capsys, ["import", "mat", str(tmp_path / name)],
                        "has 40 elements, above the import bound of 32 (16 x MAX_IMPORT_SAMPLES)")


@real_data.needs("hsm150")
def test_generic_mat_import_of_a_real_hsm150_run_matches_its_own_importer(tmp_path):
    # a real lab file read by the generic importer, columns picked from its matrix, against the dedicated loader
    source = sorted(real_data.real_data("hsm150").glob("idf_*.mat"))[0]
    own = importers.load_hsm150(source)
    generic = importers.load_mat(source, mapping={"t": "data(:,1)", "position": "data(:,3)", "velocity": "data(:,4)",
                                                  "torque": "data(:,6)"}, torque_timing="instant")
    assert generic.sample_rate == own.sample_rate == 1000.0
    for name in ("t", "position", "velocity", "torque"):
        np.testing.assert_array_equal(generic.samples[name], own.samples[name])


# ---- size bounds (#12 item 8) ------------------------------------------------------------------------------------


def test_nanosecond_step_is_refused_naming_the_bound(tmp_path, capsys, monkeypatch):
    # Why (#12 item 8): "A CSV with a 1 ns step writes a 16 GB file"
    src = tmp_path / "ns.csv"
    src.write_text("t,position,torque\n" + "".join(f"{k * 1e-9!r},{k},1\n" for k in range(4)))
    _one_line_error(capsys, ["import", "csv", str(src), "-o", str(tmp_path / "ns.h5")],
                    "above the import bound of 1e+07 Hz (MAX_IMPORT_RATE_HZ)")
    assert not (tmp_path / "ns.h5").exists()
    # within the rate bound, a short file stays small: chunks are bounded by the samples there are
    fast = tmp_path / "us.csv"
    fast.write_text("t,position,torque\n" + "".join(f"{k * 1e-6!r},{k},1\n" for k in range(4)))
    assert main(["import", "csv", str(fast), "-o", str(tmp_path / "us.h5")]) == 0
    assert (tmp_path / "us.h5").stat().st_size < 64 * 1024  # 201 KB before; grew with the rate
    # a file with more rows than the bound is refused before it is parsed
    monkeypatch.setattr(importers, "MAX_IMPORT_SAMPLES", 3)
    _one_line_error(capsys, ["import", "csv", str(fast)], "4 rows, above the import bound of 3 samples")
    monkeypatch.undo()
    # resampling is bounded before the grid is allocated
    spread = tmp_path / "spread.csv"
    spread.write_text("t,position,torque\n0,0,1\n1e-6,0,1\n2e-6,0,1\n1000,1,1\n")
    _one_line_error(capsys, ["import", "csv", str(spread), "--resample", "linear", "--unit", "t=s"],
                    "would make 1000000001 samples", "(MAX_IMPORT_SAMPLES)")


# ---- issue 30 items 14 and 15: one column, one unit; MAT sizes bounded in total, unused data never read ----


def test_two_units_or_two_channels_for_one_column_are_one_line(tmp_path, capsys):
    src = tmp_path / "x.csv"
    src.write_text("t,x,torque\n0,0,1\n0.001,0.1,1\n0.002,0.2,1\n")
    # the last --unit won silently: degrees then radians on the same column is a 57x scale
    _one_line_error(capsys, ["import", "csv", str(src), "--map", "position=x", "--unit", "x=deg", "--unit",
                             "position=rad", "-o", str(tmp_path / "a.h5")], "two units for channel position",
                    "deg and rad")
    _one_line_error(capsys, ["import", "csv", str(src), "--map", "position=x", "--unit", "position=deg", "--unit",
                             "position=deg", "-o", str(tmp_path / "a.h5")], "--unit position= is given twice")
    # torque == position was stored
    _one_line_error(capsys, ["import", "csv", str(src), "--map", "torque=x", "--map", "position=x", "-o",
                             str(tmp_path / "a.h5")], "column 'x' is mapped to torque and position")
    _one_line_error(capsys, ["import", "csv", str(src), "--map", "position=x", "--map", "position=torque", "-o",
                             str(tmp_path / "a.h5")], "--map position= is given twice")
    assert not (tmp_path / "a.h5").exists()
    assert main(["import", "csv", str(src), "--map", "position=x", "--unit", "x=deg", "-o",
                 str(tmp_path / "a.h5")]) == 0
    with open_run(tmp_path / "a.h5") as r:
        np.testing.assert_allclose(r.channel("position"), np.radians([0, 0.1, 0.2]), rtol=1e-15)


def test_unused_mat_variables_are_never_read(tmp_path, capsys):
    # a 27 KB v7.3 file with four unused chunked variables of 7.9e8 elements each was read whole (23.6 GiB)
    src = tmp_path / "bomb.mat"
    t = np.arange(100)[:, None] * 1e-3
    _mat73(src, {"t": t, "position": np.sin(t), "torque": np.cos(t)})
    with h5py.File(src, "a") as f:
        for k in range(4):
            ds = f.create_dataset(f"junk{k}", shape=(1, 790_000_000), dtype="f8", chunks=(1, 1 << 20),
                                  compression="gzip")
            ds.attrs["MATLAB_class"] = np.bytes_("double")
    assert src.stat().st_size < 64_000
    import time

    t0 = time.perf_counter()
    assert main(["import", "mat", str(src), "-o", str(tmp_path / "b.h5")]) == 0
    assert time.perf_counter() - t0 < 10.0  # reading one 7.9e8-element variable alone takes minutes and 6.3 GB
    with open_run(tmp_path / "b.h5") as r:
        np.testing.assert_allclose(r.channel("torque"), np.cos(t).ravel(), rtol=0, atol=0)
    assert "ignored columns: junk0, junk1, junk2, junk3" in capsys.readouterr().out


@pytest.mark.parametrize("version", ["v5", "v7.3"])
def test_mat_sizes_are_bounded_in_total_and_unused_ones_are_not_counted(tmp_path, capsys, monkeypatch, version):
    t = np.arange(40)[:, None] * 1e-3
    variables = {"t": t, "position": t, "torque": t, "unused": np.zeros((1000, 1))}
    src = tmp_path / "m.mat"
    savemat(src, variables) if version == "v5" else _mat73(src, variables)
    monkeypatch.setattr(importers, "MAX_IMPORT_SAMPLES", 40)
    monkeypatch.setattr(importers, "MAX_MAT_ELEMENTS_FACTOR", 2)  # 80 elements: each used one fits, 120 do not
    _one_line_error(capsys, ["import", "mat", str(src), "-o", str(tmp_path / "m.h5")],
                    "the variables used hold 120 elements together, above the import bound of 80")
    monkeypatch.setattr(importers, "MAX_MAT_ELEMENTS_FACTOR", 3)  # 120: the 1000 unused elements are not read
    assert main(["import", "mat", str(src), "-o", str(tmp_path / "m.h5")]) == 0
    with open_run(tmp_path / "m.h5") as r:
        assert r.channel("t").size == 40
    monkeypatch.setattr(importers, "MAX_MAT_VARIABLES", 3)  # the listing is bounded too
    _one_line_error(capsys, ["import", "mat", str(src), "-o", str(tmp_path / "m2.h5")],
                    "4 variables, above the 3 an import lists")


def test_an_import_never_writes_over_its_source(tmp_path, capsys):
    # an output is never an input: `import csv x.csv -o x.csv --overwrite` replaced the CSV with the run file
    src = tmp_path / "x.csv"
    src.write_text("t,position,torque\n0,0,1\n0.001,0.1,1\n0.002,0.2,1\n")
    before = src.read_bytes()
    _one_line_error(capsys, ["import", "csv", str(src), "-o", str(src), "--overwrite"], "is an input of this command")
    (tmp_path / "servo.csv").write_text("x\n")
    _one_line_error(capsys, ["import", "mnich", str(tmp_path / "servo.csv"), "-o", str(tmp_path / "a3NI.csv"),
                             "--overwrite"], "is an input of this command")  # the default load-cell file beside it
    assert src.read_bytes() == before


def test_csv_lines_are_bounded_before_they_are_parsed(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(importers, "MAX_LINE_BYTES", 64)
    ok = tmp_path / "ok.csv"
    ok.write_text("t,position,torque\n" + "".join(f"{k * 1e-3:.3f},0.{k},1\n" for k in range(100_000)) + "0,0,1")
    assert ok.stat().st_size > 1 << 20  # two 1 MiB blocks: lines are counted and measured across their seams
    assert importers._count_lines(str(ok)) == 100_002
    long_row = tmp_path / "row.csv"
    long_row.write_text("t,position,torque\n0,0,1\n0.001," + "1" * 100 + ",1\n0.002,0,1\n")
    _one_line_error(capsys, ["import", "csv", str(long_row), "-o", str(tmp_path / "a.h5")],
                    "line 3 is longer than 64 bytes")
    header = tmp_path / "header.csv"
    header.write_text("t," + "x" * 200 + ",position,torque\n0,0,0,1\n")  # a file without line breaks: the same
    _one_line_error(capsys, ["import", "csv", str(header), "-o", str(tmp_path / "a.h5")],
                    "the header is longer than 64 characters")
    assert not (tmp_path / "a.h5").exists()


def test_the_dedicated_mat_importers_read_only_their_variables_within_the_bound(tmp_path, capsys, monkeypatch):
    n = 50
    data = np.zeros((n, 7))
    data[:, 0] = np.arange(n) * 1e-3
    src = tmp_path / "idf.mat"
    savemat(src, {"data": data, "unused": np.zeros((5000, 1)), "J": 1e-3})
    monkeypatch.setattr(importers, "MAX_IMPORT_SAMPLES", 50)  # bound 800 elements: data 350 fits, unused 5000 not
    assert main(["import", "hsm150", str(src), "-o", str(tmp_path / "h.h5")]) == 0
    with open_run(tmp_path / "h.h5") as r:
        assert r.channel("t").size == n and r.calibration["J"] == 1e-3
    monkeypatch.setattr(importers, "MAX_MAT_ELEMENTS_FACTOR", 4)  # 200: data's 350 elements are refused unread
    _one_line_error(capsys, ["import", "hsm150", str(src), "-o", str(tmp_path / "h2.h5")],
                    "variable 'data' has 350 elements, above the import bound of 200")
    emps = tmp_path / "emps.mat"
    t = np.arange(n)[:, None] * 1e-3
    savemat(emps, {"t": t, "qm": t, "qg": t, "vir": t, "gtau": 2.0, "kp": 1.0, "kv": 1.0, "junk": np.zeros((9, 9))})
    _one_line_error(capsys, ["import", "emps", str(emps), "-o", str(tmp_path / "e.h5")],
                    "the variables used hold 203 elements together, above the import bound of 200")


def test_mnich_exports_are_bounded_before_they_are_parsed(tmp_path, capsys, monkeypatch):
    servo = tmp_path / "a3MR.csv"
    servo.write_text("h\n" * 5 + "".join(f"{k},{k},1,0\n" for k in range(40)))
    (tmp_path / "a3NI.csv").write_text("h\n" * 4 + "".join(f"{k * 5e-4},1,0,0\n" for k in range(40)))
    monkeypatch.setattr(importers, "MAX_IMPORT_SAMPLES", 30)
    _one_line_error(capsys, ["import", "mnich", str(servo), "-o", str(tmp_path / "m.h5")],
                    "a3MR.csv: 40 rows, above the import bound of 30 samples")
    monkeypatch.setattr(importers, "MAX_IMPORT_SAMPLES", 1000)
    monkeypatch.setattr(importers, "MAX_LINE_BYTES", 16)
    (tmp_path / "a3NI.csv").write_text("h\n" * 4 + "0," + "1" * 40 + "\n")
    _one_line_error(capsys, ["import", "mnich", str(servo), "-o", str(tmp_path / "m.h5")],
                    "a3NI.csv: line 5 is longer than 16 bytes")
