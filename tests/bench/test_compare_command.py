"""``hilbench compare`` end to end on run files; bad input is one line and exit 2."""

import json

import numpy as np
import pytest

from hilbench.bench.cli import main
from hilbench.common.runfile import RunWriter
from hilbench.firmware_sim.engine.plant import Hysteresis, PlantParams, simulate
from tests.analysis.identification.test_identification import random_enveloped

TRUTH = PlantParams(inertia=0.01, viscous=0.05, hysteresis=Hysteresis(0.3, 2e-3, 64))


def _write(path, seed, fs=1000.0, n=6000):
    u = random_enveloped(n, fs, seed, 2.0, period=2.0)
    out = simulate(TRUTH, u, 1 / fs, substeps=4)
    with RunWriter(path, sample_rate=fs, channels=("sample_index", "t", "torque", "position")) as w:
        w.append({"sample_index": np.arange(n), "t": np.arange(n) / fs, "torque": u, "position": out.theta})


def test_compare_writes_table_json_and_plots(tmp_path, capsys):
    _write(tmp_path / "a.h5", 1)
    _write(tmp_path / "b.h5", 2)
    rc = main(["compare", str(tmp_path / "a.h5"), "--validate", str(tmp_path / "b.h5"), "-o", str(tmp_path / "out"),
               "--families", "coulomb_viscous,continuous", "--torque-timing", "hold_next", "--max-evaluations", "30"])
    assert rc == 0
    table = (tmp_path / "out" / "compare.md").read_text()
    assert "| continuous | 5 |" in table and "| coulomb_viscous | 4 |" in table and "rms error (rad)" in table
    doc = json.loads((tmp_path / "out" / "compare.json").read_text())
    assert doc["schema"] == "hilbench.compare/1"
    rows = {r["model"]: r for r in doc["rows"]}
    # the data come from the continuous model: it must beat Coulomb+viscous on the validation run, and recover h
    assert (rows["continuous"]["validation"]["position_nrmse_segmented"]
            < rows["coulomb_viscous"]["validation"]["position_nrmse_segmented"])
    for name, r in rows.items():  # the table shows the JSON's fractions in percent (common.metrics.percent)
        cells = next(line for line in table.splitlines() if line.startswith(f"| {name} |")).split("|")
        assert float(cells[4]) == pytest.approx(100 * r["validation"]["torque_nrmse"], rel=5e-4), name
        assert float(cells[7]) == pytest.approx(100 * r["train"]["torque_nrmse"], rel=5e-4), name
    fit = rows["continuous"]["fit"]
    assert fit["parameters"]["h"] == pytest.approx(0.3, rel=0.05)
    assert fit["units"]["h"] == "N*m" and fit["units"]["d"] == "rad"
    assert fit["std_errors"]["h"] > 0
    for name in ("compare_hysteresis.png", "compare_time.png"):
        assert (tmp_path / "out" / name).stat().st_size > 1000
    assert "plot:" in capsys.readouterr().out
    # one model file per family (schema hilbench.friction-model/2), read back with its uncertainties
    from hilbench.analysis.models.model_file import read_family

    model, doc = read_family(tmp_path / "out" / "models" / "continuous.json")
    assert doc["schema"] == "hilbench.friction-model/2" and model.family == "continuous"
    assert model.parameters["h"] == pytest.approx(fit["parameters"]["h"])
    assert model.uncertainty("h") == pytest.approx(fit["std_errors"]["h"]) and model.units["h"] == "N*m"
    assert model.plant.hysteresis.h == pytest.approx(fit["parameters"]["h"])
    assert read_family(tmp_path / "out" / "models" / "coulomb_viscous.json")[0].uncertainty("coulomb") > 0


@pytest.mark.parametrize("extra, message", [
    (["--families", "coulomb_viscous,bogus"], "unknown family bogus"),
    (["--segment", "0"], "--segment must be > 0"),
    (["--published", "emps"], "linear-axis model"),
])
def test_compare_bad_input_is_one_line_exit_2(tmp_path, capsys, extra, message):
    _write(tmp_path / "a.h5", 1, n=2000)
    rc = main(["compare", str(tmp_path / "a.h5"), "--validate", str(tmp_path / "a.h5"), "-o", str(tmp_path / "o"),
               "--max-evaluations", "1", "--families", "coulomb_viscous", *extra])
    err = capsys.readouterr().err
    assert rc == 2 and message in err and len(err.strip().splitlines()) == 1


def test_compare_missing_file_is_one_line_exit_2(tmp_path, capsys):
    rc = main(["compare", str(tmp_path / "nope.h5"), "--validate", str(tmp_path / "nope.h5"), "-o", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and "no such run file" in err and len(err.strip().splitlines()) == 1


def test_compare_over_its_memory_budget_reads_reduced_runs_or_refuses_in_one_line(tmp_path, capsys, monkeypatch):
    """--memory below what the whole 10 kHz arrays need: compare reads both runs chunk by chunk reduced to 2 kHz
    and says so; below what even the reduced copies need: one line, exit 2, before reading (docs/long-runs.md)."""
    import hilbench.analysis.models.compare as compare

    _write(tmp_path / "a.h5", 1, fs=10_000.0, n=20_000)
    _write(tmp_path / "b.h5", 2, fs=10_000.0, n=20_000)
    monkeypatch.setattr(compare, "COMPARE_BYTES_FIXED", 0)
    monkeypatch.setattr(compare, "COMPARE_BYTES_PER_SAMPLE", 10_000)  # whole: 400 MB; reduced by 2: 200 MB
    args = ["compare", str(tmp_path / "a.h5"), "--validate", str(tmp_path / "b.h5"), "--families", "coulomb_viscous",
            "--torque-timing", "hold_next", "--max-evaluations", "5", "--memory", "300M"]
    assert main([*args, "-o", str(tmp_path / "out")]) == 0
    doc = json.loads((tmp_path / "out" / "compare.json").read_text())
    assert doc["data"]["train"]["sample_rate_hz"] == 5000.0 and doc["data"]["train"]["samples"] == 10_000
    assert doc["data"]["train"]["read"].startswith("decimated by 2 (10000 -> 5000 Hz)")
    monkeypatch.setattr(compare, "COMPARE_BYTES_PER_SAMPLE", 40_000)  # reduced: 800 MB, over 256 MiB
    capsys.readouterr()
    assert main([*args[:-1], "256M", "-o", str(tmp_path / "out2")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "over --memory 256 MiB" in err and not (tmp_path / "out2").exists()
    # between the two: the first 1 s (MIN_SPAN_S) or more of each run at 5 kHz that fit, said in one line and in
    # the JSON; span = 300 MiB // (2 * 40 000 B) = 3932 samples, 0.7864 s
    monkeypatch.setattr(compare, "MIN_SPAN_S", 0.5)
    assert main([*args, "-o", str(tmp_path / "out3")]) == 0
    doc = json.loads((tmp_path / "out3" / "compare.json").read_text())
    assert doc["data"]["train"]["samples"] == doc["data"]["validation"]["samples"] == 3932
    assert doc["data"]["train"]["span"].startswith("analysed the first 0.7864 s of 2 s (3932 of 10000 samples")
    assert "analysed the first 0.7864 s" in capsys.readouterr().out
