"""One run, one reading: the CLI's identify and compare, the GUI's identification and a script report the same
validation figure, in the same unit, for the same model on the same runs (docs/metrics.md, docs/record.md)."""

import json
import re

import pytest

from hilbench.analysis.identification import analyse
from hilbench.analysis.record import load_record
from hilbench.bench.cli import main
from hilbench.bench.gui.analyses import identification
from tests.bench.test_identify_command import _write_run


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("one")
    _write_run(d / "a.h5", 1)
    _write_run(d / "b.h5", 2)
    return d


def _pct(text: str, pattern: str) -> float:
    m = re.search(pattern + r" ([0-9.]+) %", text)
    assert m, (pattern, text)
    return float(m.group(1))


def test_identify_the_gui_and_a_script_give_the_same_figures(runs, capsys):
    assert main(["identify", str(runs / "a.h5"), "--validate", str(runs / "b.h5"), "--json",
                 str(runs / "m.json")]) == 0
    out = capsys.readouterr().out
    doc = json.loads((runs / "m.json").read_text())["figures"]
    train, val = 100 * doc["train_torque_nrmse"], 100 * doc["validation_torque_nrmse"]
    assert _pct(out, "train NRMSE torque") == pytest.approx(train, rel=5e-3)  # printed to 3 digits
    assert _pct(out, "validation NRMSE torque") == pytest.approx(val, rel=5e-3)
    script = analyse(load_record(runs / "a.h5"), validation=load_record(runs / "b.h5")).figures
    assert 100 * script["validation_torque_nrmse"] == pytest.approx(val, rel=1e-12)
    shown = {q: (v, u) for q, v, u in identification(load_record(runs / "a.h5")).numbers}
    value, unit = shown["train torque NRMSE"]
    assert unit == "%" and float(value) == pytest.approx(train, rel=5e-3)


def test_compare_scores_the_identified_model_as_identify_does(runs, capsys):
    """compare's maxwell_slip row is the NNLS fit identify makes with --offset; both score it on the validation run
    by the same definition, so the figure agrees to the printed digits (it read 17 % against 0.82 % when compare
    evaluated the friction along a low-passed position)."""
    assert main(["identify", str(runs / "a.h5"), "--validate", str(runs / "b.h5"), "--offset", "--json",
                 str(runs / "off.json")]) == 0
    ident = json.loads((runs / "off.json").read_text())["figures"]["validation_torque_nrmse"]
    assert main(["compare", str(runs / "a.h5"), "--validate", str(runs / "b.h5"), "--families", "maxwell_slip",
                 "-o", str(runs / "cmp")]) == 0
    table = capsys.readouterr().out
    row = json.loads((runs / "cmp" / "compare.json").read_text())
    rows = {r["model"]: r for r in row["rows"]}
    cmp = rows["maxwell_slip"]["validation"]["torque_nrmse"]
    assert cmp == pytest.approx(ident, rel=1e-3)
    assert "validation torque NRMSE (%)" in table and f"{100 * cmp:.4g}" in table
