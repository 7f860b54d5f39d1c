"""`hilbench demo` (what `make demo` runs) end to end: the runs, the analyses, and the hidden effect found."""

import json

from hilbench.analysis.record import load_record
from hilbench.bench.cli import main


def test_demo_runs_everything_and_finds_the_undeclared_cogging(tmp_path, capsys):
    tmp_path = tmp_path / "a+b &c=d"  # characters that mean something in a URL query (issue 12 item 12)
    assert main(["demo", "-o", str(tmp_path), "--duration", "10"]) == 0  # 20 s by default; 10 s finds both
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
    assert "done: everything is in" in capsys.readouterr().out
