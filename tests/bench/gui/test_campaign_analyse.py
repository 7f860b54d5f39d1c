"""Issue 38: Analyse and Drift on a finished campaign, from the campaign view (offscreen Qt). The commands run in
their own process (``python -m hilbench analyse|drift``) while the GUI thread keeps serving its event loop; the
campaign is a small synthetic one (bench.campaign_analysis.synthetic: 6 simulated identification runs of 1 s)."""

import json

import pytest
from PySide6 import QtCore, QtGui

from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign
from hilbench.bench.campaign_analysis.table import TABLE_NAME, to_table
from hilbench.bench.gui.campaign_view import CampaignView

RUNS = 6


@pytest.fixture
def view(qtbot):
    v = CampaignView()
    qtbot.addWidget(v)
    yield v
    v.shutdown()


def _plain(label) -> str:
    return QtGui.QTextDocumentFragment.fromHtml(label.text()).toPlainText()


def test_analyse_then_drift_a_finished_campaign(view, qtbot, tmp_path):
    camp = tmp_path / "camp"
    write_campaign(camp, SyntheticCampaign(runs=RUNS, duration=1.0))
    view.out_edit.setText(str(tmp_path / "elsewhere"))
    assert not view.analyse_button.isEnabled() and not view.drift_button.isEnabled()  # no campaign there
    view.out_edit.setText(str(camp))
    assert view.analyse_button.isEnabled() and not view.drift_button.isEnabled()  # nothing analysed yet
    view.analyse_options = ("--serial",)  # one process, no cluster start-up: the test stays short
    ticks = []
    timer = QtCore.QTimer()
    timer.timeout.connect(lambda: ticks.append(1))
    timer.start(20)
    assert view.analyse()
    progress = []
    view.command.progress.connect(lambda done, total: progress.append((done, total)))
    assert not view.analyse_button.isEnabled() and not view.drift_button.isEnabled()  # one command at a time
    assert not view.analyse()
    qtbot.waitUntil(lambda: view.command is None, timeout=120000)
    timer.stop()
    assert len(ticks) > 10  # the GUI thread ran its timers throughout (the analysis takes seconds)
    assert progress and progress[-1] == (RUNS, RUNS)
    assert view.analysis_bar.value() == view.analysis_bar.maximum() == RUNS
    status = _plain(view.status)
    assert f"{RUNS} analysed (0 failed)" in status, status
    assert (camp / "analysis" / TABLE_NAME).is_file()
    # the Results tab shows the table just written
    assert view.tabs.currentWidget() is view.results
    assert view.results.path_edit.text() == str(camp / "analysis")
    assert view.results.table.rowCount() == RUNS
    assert view.drift_button.isEnabled()

    assert view.drift()
    qtbot.waitUntil(lambda: view.command is None, timeout=120000)
    report = camp / "analysis" / "drift" / "drift.json"
    status = _plain(view.status)
    assert str(report) in status and "campaign-camp.html" in status, status
    assert json.loads(report.read_text())["runs"] == RUNS
    assert (camp / "analysis" / "drift" / "campaign-camp.html").is_file()


def test_a_failing_analysis_is_one_red_line(view, qtbot, tmp_path):
    camp = tmp_path / "camp"
    write_campaign(camp, SyntheticCampaign(runs=2, duration=0.5))
    view.out_edit.setText(str(camp))
    view.results_edit.setText(str(camp))  # analyse refuses to write into the campaign folder: exit 2
    messages = []
    view.message.connect(lambda text, error: messages.append((text, error)))
    assert view.analyse()
    qtbot.waitUntil(lambda: view.command is None, timeout=60000)
    status = _plain(view.status)
    assert "#c00000" in view.status.text() and "\n" not in status
    assert status == f"analyse failed: {camp}: is a campaign folder; the results go into a folder of their own"
    assert messages == [(status, True)]
    assert view.tabs.currentWidget() is not view.results and view.analyse_button.isEnabled()


def test_a_failing_drift_is_one_red_line_and_writes_nothing(view, qtbot, tmp_path):
    """Two runs whose analysis failed leave nothing to follow: the command's own reason, in red, and no report.
    (Two analysed runs are a report with nothing charted yet: tests/bench/test_documented_path.py.)"""
    import pyarrow.parquet as pq

    from tests.bench.gui.test_campaign_results import _rows

    results = tmp_path / "results"
    results.mkdir()
    failed = [{**r, "status": "failed", "error": "AnalysisError: no position channel"} for r in _rows()[:2]]
    pq.write_table(to_table(failed), results / TABLE_NAME)
    view.results_edit.setText(str(results))
    assert view.drift_button.isEnabled() and not view.analyse_button.isEnabled()  # no campaign folder given
    assert view.drift()
    qtbot.waitUntil(lambda: view.command is None, timeout=60000)
    status = _plain(view.status)
    assert "#c00000" in view.status.text() and status.startswith("drift failed: no analysed run (status ok)")
    assert not (results / "drift" / "drift.json").exists()


def test_closing_stops_a_running_analysis(view, qtbot, tmp_path):
    camp = tmp_path / "camp"
    write_campaign(camp, SyntheticCampaign(runs=2, duration=0.5))
    view.out_edit.setText(str(camp))
    assert view.analyse() and view.busy
    process = view.command.process
    view.shutdown()
    assert process.state() == QtCore.QProcess.ProcessState.NotRunning
