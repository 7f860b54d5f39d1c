"""One EMPS parser (#24): the import command and the reproduction read the same arrays through one function."""

import ast
from pathlib import Path

import numpy as np
import pytest
from scipy.io import savemat

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.reproductions.emps import load_emps, parse_emps
from hilbench.bench.storage import importers
from tests import real_data

ROOT = Path(__file__).resolve().parents[3]


@pytest.mark.parametrize("name", ["DATA_EMPS.mat", "DATA_EMPS_PULSES.mat"])
def test_import_and_reproduction_read_identical_arrays(name):
    rec = load_emps(real_data.EMPS / name)
    run = importers.load_emps(real_data.EMPS / name)
    # bit-for-bit: both are the one parser's output, not two readings that happen to agree within a tolerance
    assert np.array_equal(run.samples["t"], rec.t) and np.array_equal(run.samples["position"], rec.qm)
    assert np.array_equal(run.samples["position_cmd"], rec.qg)
    assert np.array_equal(run.samples["torque"], rec.force) and np.array_equal(run.samples["drive_voltage"], rec.vir)
    assert run.calibration["gtau"] == rec.gtau and run.calibration["kp"] == rec.kp
    assert ("pulses" in run.samples) == (rec.pulses is not None) == (name == "DATA_EMPS_PULSES.mat")
    # the data set's README: 24841 samples at 1 kHz, gtau = 35.15 N/V
    assert rec.t.size == 24841 and rec.gtau == pytest.approx(35.15, abs=0.01)


def test_one_definition_of_the_emps_variables():
    # grep-style: no module but analysis/reproductions/emps.py reads the EMPS variables 'qm' and 'vir' out of a MAT
    # mapping, and the EMPS functions are the parser, the reproduction's loader and the bench's import adapter
    defs: dict[str, list[str]] = {}
    for pkg in ("analysis", "bench", "drivers", "firmware_sim"):
        for path in (ROOT / pkg).rglob("*.py"):
            text = path.read_text()
            tree = ast.parse(text)
            # the importer's provenance labels ({"position": "qm"}) name the variables without reading them
            labels = {id(v) for node in ast.walk(tree) if isinstance(node, ast.Dict) for v in node.values}
            for node in ast.walk(tree):
                if isinstance(node, ast.Constant) and node.value in ("qm", "vir") and id(node) not in labels:
                    defs.setdefault("read", []).append(str(path.relative_to(ROOT)))
                if isinstance(node, ast.FunctionDef) and "emps" in node.name:
                    defs.setdefault("function", []).append(f"{path.relative_to(ROOT)}:{node.name}")
    assert set(defs["read"]) == {"analysis/reproductions/emps.py"}, defs["read"]
    # the bench's load_emps is the importer (ImportedRun); the parsing is parse_emps alone
    assert sorted(defs["function"]) == ["analysis/reproductions/emps.py:load_emps",
                                        "analysis/reproductions/emps.py:parse_emps",
                                        "bench/storage/importers.py:load_emps"], defs["function"]


def test_bad_emps_variables_are_named_in_one_line(tmp_path):
    t = np.arange(5)[:, None] * 1e-3
    good = {"t": t, "qm": t, "qg": t, "vir": t, "gtau": 2.0, "kp": 1.0, "kv": 1.0}
    cases = {
        "'qm' is missing": {k: v for k, v in good.items() if k != "qm"},
        "'vir' has 4 samples, expected 5": {**good, "vir": t[:4]},
        "'qg' has 1 non-finite value(s) (first at sample 2)": {**good, "qg": np.where(t == t[2], np.nan, t)},
        "'vir' is complex": {**good, "vir": t * 1j},
        "scalar 'kp' is missing": {k: v for k, v in good.items() if k != "kp"},
    }
    for message, variables in cases.items():
        src = tmp_path / "e.mat"
        savemat(src, variables)
        with pytest.raises(AnalysisError, match=message.replace("(", r"\(").replace(")", r"\)")):
            load_emps(src)
        with pytest.raises(importers.ImportDataError, match=message.replace("(", r"\(").replace(")", r"\)")):
            importers.load_emps(src)
    rec = parse_emps(good, "x/e.mat")
    assert rec.name == "e" and rec.pulses is None and np.array_equal(rec.force, 2.0 * t.ravel())
