"""One run, one reading: the CLI's identify and compare, the GUI's identification and a script report the same
validation figure, in the same unit, for the same model on the same runs (docs/metrics.md, docs/record.md)."""

import json
import re

import pytest

from hilbench.analysis.identification import analyse
from hilbench.analysis.record import load_record
from hilbench.bench.cli import main
from hilbench.bench.gui.analyses import run_analysis
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
    assert _pct(out, "train torque NRMSE") == pytest.approx(train, rel=5e-3)  # printed to 3 digits
    assert _pct(out, "validation torque NRMSE") == pytest.approx(val, rel=5e-3)
    script = analyse(load_record(runs / "a.h5"), validation=load_record(runs / "b.h5")).figures
    assert 100 * script["validation_torque_nrmse"] == pytest.approx(val, rel=1e-12)
    shown = {q: (v, u) for q, v, u in run_analysis("identify", runs / "a.h5").numbers}
    value, unit = shown["train torque NRMSE"]
    assert unit == "%" and float(value) == pytest.approx(train, rel=5e-3)


def test_compare_scores_the_identified_model_as_identify_does(runs, capsys):
    """compare's maxwell_slip row is the NNLS fit identify makes, with identify's terms (no offset unless asked:
    issue #37); both score it on the validation run by the one scoring function (analysis.scoring), so the figure
    agrees to rounding (it read 17 % against 0.82 % when compare evaluated the friction along a low-passed
    position, and 0.1797 % against 0.1793 % when compare's row fitted an offset identify's did not)."""
    assert main(["identify", str(runs / "a.h5"), "--validate", str(runs / "b.h5"), "--json",
                 str(runs / "off.json")]) == 0
    ident = json.loads((runs / "off.json").read_text())["figures"]["validation_torque_nrmse"]
    assert main(["compare", str(runs / "a.h5"), "--validate", str(runs / "b.h5"), "--families", "maxwell_slip",
                 "-o", str(runs / "cmp")]) == 0
    table = capsys.readouterr().out
    row = json.loads((runs / "cmp" / "compare.json").read_text())
    rows = {r["model"]: r for r in row["rows"]}
    cmp = rows["maxwell_slip"]["validation"]["torque_nrmse"]
    assert cmp == pytest.approx(ident, rel=1e-9)
    assert "validation torque NRMSE (%)" in table and f"{100 * cmp:.4g}" in table


def test_a_record_over_the_memory_budget_is_read_chunk_by_chunk_with_the_same_result(runs, capsys, monkeypatch):
    """--memory below what the whole arrays need makes identify read both runs chunk by chunk (the record
    loader's stream_record feeding identify_chunks): the same model and figures as the whole-array path."""
    import hilbench.analysis.identification as ident
    import hilbench.analysis.record as record

    assert main(["identify", str(runs / "a.h5"), "--validate", str(runs / "b.h5"), "--json",
                 str(runs / "whole.json")]) == 0
    monkeypatch.setattr(ident, "ARRAY_BYTES_PER_SAMPLE", 1 << 20)  # as if the record were 40 000 times longer
    monkeypatch.setattr(record, "STREAM_CHUNK", 4099)  # many chunks, cut at odd places
    assert main(["identify", str(runs / "a.h5"), "--validate", str(runs / "b.h5"), "--json",
                 str(runs / "streamed.json"), "--memory", "2G"]) == 0
    whole = json.loads((runs / "whole.json").read_text())
    streamed = json.loads((runs / "streamed.json").read_text())
    assert whole["data"]["train"]["read"] == "whole"
    assert streamed["data"]["train"]["read"] == "chunk by chunk (--memory)"
    assert streamed["parameters"]["inertia"] == pytest.approx(whole["parameters"]["inertia"], rel=1e-7)
    for key in ("train_torque_nrmse", "validation_torque_nrmse", "validation_position_nrmse_segmented"):
        assert streamed["figures"][key] == pytest.approx(whole["figures"][key], rel=1e-6), key
    # and --plots, which draws the whole record, is refused in one line instead of outgrowing the budget
    capsys.readouterr()
    assert main(["identify", str(runs / "a.h5"), "--json", str(runs / "p.json"), "--memory", "2G",
                 "--plots", str(runs / "plots")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--plots draws the whole record" in err


def test_residual_starts_from_the_model_identify_reports(runs, capsys):
    """residual --start maxwell_slip starts from identify's own fit, and --start MODEL.json from identify's model
    file unrefitted: the start model's validation figure is identify's (it read 1.57 % against identify's 0.816 %
    when residual refitted its start terms)."""
    assert main(["identify", str(runs / "a.h5"), "--validate", str(runs / "b.h5"), "--json",
                 str(runs / "id.json")]) == 0
    ident = json.loads((runs / "id.json").read_text())["figures"]["validation_torque_nrmse"]
    capsys.readouterr()
    for start, name in (("maxwell_slip", "r_family.json"), (str(runs / "id.json"), "r_file.json")):
        assert main(["residual", str(runs / "a.h5"), "--validate", str(runs / "b.h5"), "--start", start,
                     "--candidates", "offset", "--json", str(runs / name)]) == 0
        out = capsys.readouterr().out
        doc = json.loads((runs / name).read_text())
        figure = doc["inputs"]["start_model"]["figures"]["validation_torque_nrmse"]
        assert figure == pytest.approx(ident, rel=1e-9), start
        assert _pct(out, r"start model \([^)]*\): validation torque NRMSE") == pytest.approx(100 * ident, rel=5e-3)
        assert "family_model" in doc["start"]
        # the simulated start model carries the model's elements (without them its position drifted: 2.4e4 %)
        assert doc["error_before"]["validation"]["position_nrmse"] < 0.1
