"""`hilbench demo` (what `make demo` runs) end to end: the runs, the analyses, and the hidden effect found."""

import json
import re
from pathlib import Path

from hilbench.analysis.record import load_record
from hilbench.bench.cli import main


def test_demo_runs_everything_and_finds_the_undeclared_cogging(tmp_path, capsys):
    tmp_path = tmp_path / "a+b &c=d"  # characters that mean something in a URL query (issue 12 item 12)
    assert main(["demo", "-o", str(tmp_path)]) == 0  # the defaults of `make demo`: the README quotes its figures
    for role in ("identification", "validation", "afrf"):
        assert load_record(tmp_path / "runs" / f"{role}.h5").status == "completed"
    model = json.loads((tmp_path / "model.json").read_text())
    assert model  # identification wrote its model file
    assert json.loads((tmp_path / "afrf.json").read_text())
    report = json.loads((tmp_path / "residual.json").read_text())
    found = {e["name"]: e["parameters"] for e in report["effects_added"]}
    # the simulator's private config: cogging order 6, 0.04 N*m; the preset's viscous 0.004 (not in the start)
    assert abs(found["position_periodic"]["amplitude"] / 0.04 - 1) < 0.10
    assert abs(found["viscous"]["viscous"] / 0.004 - 1) < 0.10
    err = report["error_before"]["validation"]["torque_rel_pct"] / report["error_after"]["validation"]["torque_rel_pct"]
    assert err > 2.0
    assert (tmp_path / "residual" / "summary.md").exists() and (tmp_path / "afrf.png").exists()
    out = capsys.readouterr().out
    assert "done: everything is in" in out
    # the README's demo figures are what this run prints: the torque error before and after, and the effects found
    readme = (Path(__file__).parents[2] / "README.md").read_text()
    before, after = re.search(r"torque error from ([0-9.]+) % to ([0-9.]+) %", readme).groups()
    assert f"validation torque NRMSE {before} % -> {after} %" in out, (before, after)
    figures = re.search(r"hidden cogging \(order 6, ([0-9.]+) vs .*?lacks \(([0-9.]+) vs", readme, re.S)
    cogging, viscous = figures.groups()
    assert f"{float(found['position_periodic']['amplitude']):.3g}" == cogging
    assert f"{float(found['viscous']['viscous']):.3g}" == viscous


def test_every_demo_step_replaces_the_outputs_of_an_earlier_demo(monkeypatch, tmp_path):
    """`make demo` twice: run_demo refuses a used folder unless --overwrite, so each step it then runs must replace
    its own earlier outputs (the afrf and residual steps once stopped a second `make demo` with 'exists')."""
    from hilbench.bench.cli import demo

    calls = []
    monkeypatch.setattr(demo, "_cli", lambda *argv: calls.append([str(a) for a in argv]))
    (tmp_path / "residual.json").write_text('{"effects_added": []}')  # what the residual step reads back
    files = {k: tmp_path / f"{k}.h5" for k in ("identification", "validation", "afrf")}
    for _name, step in demo.analysis_steps():
        step(files, tmp_path)
    assert [argv[0] for argv in calls] == ["identify", "afrf", "residual"]
    assert all("--overwrite" in argv for argv in calls), calls
