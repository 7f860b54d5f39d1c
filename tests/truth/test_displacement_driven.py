"""A displacement-driven record (force against an imposed displacement, a tribometer) from the independent
generator goes through ``hilbench import csv --record displacement-driven`` -> ``identify --inertia 0`` ->
``residual``: the identified virgin curve matches the 40-element Maxwell-slip truth and the report's figures
are force figures."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from hilbench.analysis.record import load_record
from hilbench.bench.cli import main
from tests.truth.generator import displacement_driven, virgin_curve

PRESLIDING = 0.1e-3  # m
BREAKAWAY = 40.0  # N


@pytest.fixture(scope="module")
def tribometer(tmp_path_factory):
    d = tmp_path_factory.mktemp("tribo")
    paths = {}
    for name, seed in (("train", 5), ("valid", 6)):
        rec, k, w = displacement_driven(seed, presliding=PRESLIDING, breakaway=BREAKAWAY)
        csv = d / f"{name}.csv"
        np.savetxt(csv, np.column_stack([rec.t, rec.position, rec.torque]), delimiter=",",
                   header="t,position,torque", comments="", fmt="%.10g")
        h5 = d / f"{name}.h5"
        assert main(["import", "csv", str(csv), "--linear", "--record", "displacement-driven", "-o", str(h5)]) == 0
        paths[name] = h5
    return d, paths, k, w


def test_record_attribute_is_written_and_read(tribometer):
    _, paths, _, _ = tribometer
    with h5py.File(paths["train"], "r") as f:
        assert f.attrs["record"] == "displacement-driven"
    assert load_record(paths["train"]).kind == "displacement-driven"


def test_identify_inertia_zero_recovers_the_virgin_curve(tribometer, capsys):
    d, paths, k, w = tribometer
    out = d / "model.json"
    assert main(["identify", str(paths["train"]), "--validate", str(paths["valid"]), "--inertia", "0",
                 "--json", str(out)]) == 0
    assert "force simulated from the measured displacement" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    m = doc["parameters"]
    ks, ds = np.asarray(m["ms_stiffness"]), np.asarray(m["ms_delta"])
    fc = float(m.get("coulomb", 0.0))
    x = np.linspace(0, 1.2 * PRESLIDING, 400)[1:]
    fitted = np.sum(ks * np.clip(x[:, None], -ds, ds), axis=1) + fc
    truth = virgin_curve(k, w, x)
    rms = np.sqrt(np.mean((fitted - truth) ** 2)) / np.sqrt(np.mean(truth**2))
    assert rms < 0.02, f"virgin curve RMS error {100 * rms:.2f} %"
    assert doc["figures"]["validation_force_rel_pct"] < 2.0


def test_residual_report_gives_force_figures(tribometer):
    d, paths, _, _ = tribometer
    out, rep = d / "residual.json", d / "report"
    assert main(["residual", str(paths["train"]), "--validate", str(paths["valid"]), "--start",
                 "inertia,maxwell_slip", "--json", str(out), "--report", str(rep)]) == 0
    doc = json.loads(out.read_text())
    assert doc["record"] == "displacement-driven" and doc["inputs"]["fixed_inertia"] == 0.0
    va = doc["error_after"]["validation"]
    assert va["force_rel_pct"] is not None and va["position_nrmse"] is None
    assert va["force_rel_pct"] < 2.0
    assert doc["effects_added"] == []  # the truth is pure Maxwell-slip: nothing is missing
    assert (rep / "force.png").stat().st_size > 10_000
    assert "force relative error (%)" in (rep / "summary.md").read_text()


def test_negative_inertia_is_one_line_and_exit_2(tribometer, capsys):
    d, paths, _, _ = tribometer
    for cmd in (["identify", str(paths["train"]), "--inertia", "-1", "--json", str(d / "bad.json")],
                ["residual", str(paths["train"]), "--inertia", "-1", "--json", str(d / "bad2.json")]):
        assert main(cmd) == 2
        err = capsys.readouterr().err.strip()
        assert "--inertia must be finite and >= 0" in err and "\n" not in err
    assert not (d / "bad.json").exists() and not (d / "bad2.json").exists()
