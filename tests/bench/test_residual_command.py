"""``hilbench residual``: run files in, JSON + figures + Markdown out, one-line errors for bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hilbench.bench.cli import main
from hilbench.common.runfile import RunWriter
from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import simulate
from tests.analysis.residual.test_residual_loop import FS, excitation
from tests.figure_checks import recording_figures


def write_run(path, seed: int) -> None:
    params = dc_motor().replace(viscous=0.01, counts_per_rev=20000, seed=seed)
    tau = excitation(seed)
    out = simulate(params, tau / params.torque_constant, 1 / FS, substeps=4)
    n = tau.size
    with RunWriter(path, sample_rate=FS, channels=("sample_index", "t", "position", "torque_cmd")) as w:
        w.append({"sample_index": np.arange(n), "t": np.arange(n) / FS, "position": out.position_meas,
                  "torque_cmd": tau})


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("residual")
    write_run(d / "train.h5", 41)
    write_run(d / "valid.h5", 1041)
    return d


def test_cli_writes_json_and_report(runs, capsys):
    out_json, report = runs / "out.json", runs / "report"
    with recording_figures() as seen:  # issue 13: every axis labelled with a unit, no empty legend
        rc = main(["residual", str(runs / "train.h5"), "--validate", str(runs / "valid.h5"),
                   "--json", str(out_json), "--report", str(report)])
    assert rc == 0
    assert set(seen) == {"diagnostics_before.png", "diagnostics_after.png", "hysteresis.png"}
    assert not any(seen.values()), seen
    doc = json.loads(out_json.read_text())
    assert [e["name"] for e in doc["effects_added"]] == ["viscous"]
    e = doc["effects_added"][0]
    assert set(e) >= {"name", "parameters", "uncertainty", "error_after"}
    assert e["parameters"]["viscous"] == pytest.approx(0.01, rel=0.1)  # the 10 % bound
    for key in ("error_before", "error_after"):
        for part in ("train", "validation"):
            assert set(doc[key][part]) >= {"torque_rel_pct", "torque_nrmse", "position_nrmse"}
    assert doc["verdict"].startswith("missing effect(s) found: viscous")
    assert isinstance(doc["unexplained"], list)
    for name in ("diagnostics_before.png", "diagnostics_after.png", "summary.md"):
        assert (report / name).stat().st_size > 0
    assert "viscous" in (report / "summary.md").read_text()
    text = capsys.readouterr().out
    assert "validation torque NRMSE" in text and "verdict: " in text and (report / "hysteresis.png").is_file()


def test_cli_bad_input_is_one_line(runs, capsys):
    assert main(["residual", str(runs / "missing.h5"), "--json", str(runs / "x.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("hilbench residual: error:") and "\n" not in err
    assert main(["residual", str(runs / "train.h5"), "--start", "inertia,bogus", "--json", str(runs / "x.json")]) == 2
    assert "unknown model term" in capsys.readouterr().err


def test_cli_over_its_memory_budget_refuses_in_one_line_before_reading(runs, capsys, monkeypatch):
    """Not even the shortest span (10 s of each run) fits: one line, exit 2, before any sample is read."""
    import hilbench.analysis.record as record
    import hilbench.analysis.residual.record_analysis as ra

    monkeypatch.setattr(ra, "LOOP_BYTES_PER_SAMPLE", 10_000)  # 10 s of both runs: 200 MiB + 200 MB

    def no_read(*args, **kwargs):
        raise AssertionError("read the samples before checking the budget")

    monkeypatch.setattr(record, "decimated_record", no_read)
    assert main(["residual", str(runs / "train.h5"), "--validate", str(runs / "valid.h5"), "--memory", "256M",
                 "--json", str(runs / "m.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "over --memory 256 MiB" in err and not (runs / "m.json").exists()


def test_cli_over_its_memory_budget_analyses_the_first_span_that_fits(runs, capsys, monkeypatch):
    """Between the whole runs and the shortest span: the loop analyses the first samples of each run that fit
    (docs/long-runs.md, "A bounded span"), says so in one line and in the JSON's inputs."""
    import hilbench.analysis.residual.record_analysis as ra

    monkeypatch.setattr(ra, "LOOP_BYTES_FIXED", 0)
    monkeypatch.setattr(ra, "LOOP_BYTES_PER_SAMPLE", 10_000)  # whole: 2 x 15 000 samples, 300 MB
    assert main(["residual", str(runs / "train.h5"), "--validate", str(runs / "valid.h5"), "--memory", "260M",
                 "--candidates", "viscous", "--json", str(runs / "span.json")]) == 0
    span = 260 * 2**20 // (2 * 10_000)  # 13 631 samples at 1 kHz
    doc = json.loads((runs / "span.json").read_text())
    notes = doc["inputs"]["span"]
    assert set(notes) == {str(runs / "train.h5"), str(runs / "valid.h5")}
    assert all(n.startswith(f"analysed the first 13.631 s of 15 s ({span} of 15000 samples") for n in notes.values())
    assert f"the loop analyses the first {span} samples of each run" in capsys.readouterr().out
    assert [e["name"] for e in doc["effects_added"]] == ["viscous"]


def test_progress_goes_to_a_terminal_and_quiet_silences_it(monkeypatch):
    """The analyses' progress bar (tqdm, with ETA) writes to standard error when it is a terminal; -q (verbosity 0)
    silences it."""
    import io

    from hilbench.bench import analysis_progress
    from hilbench.bench.storage import outputs

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    written = {}
    monkeypatch.setattr(analysis_progress, "DELAY_S", 0.0)  # drawn at once (a real command waits 2 s)
    for verbosity in (1, 0):
        written[verbosity] = Terminal()
        monkeypatch.setattr("sys.stderr", written[verbosity])
        monkeypatch.setattr(outputs, "verbosity", verbosity)
        with analysis_progress.progress_bar("read run.h5") as progress:
            progress(500, 1000)
    assert "read run.h5" in written[1].getvalue() and "500/1.00k" in written[1].getvalue()
    assert written[0].getvalue() == ""
