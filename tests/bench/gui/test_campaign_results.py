"""The campaign view's Results tab: the table and the drift charts of an analysed campaign (offscreen Qt).

The results table is written as ``hilbench analyse`` writes it (bench.campaign_analysis.table), with a
break-away that steps by +5 % (5 sigma of its scatter) at run 40 of 60 and one failed run."""

from datetime import UTC, datetime, timedelta

import numpy as np
import pyqtgraph as pg
import pytest

from hilbench.analysis.drift.monitor import DriftSettings, monitor
from hilbench.bench.campaign_analysis.table import TABLE_NAME, to_table
from hilbench.bench.gui.campaign_view import RESULT_COLUMNS, CampaignView, result_headers

N, STEP_AT, FAILED = 60, 40, 7


def _rows() -> list[dict]:
    rng = np.random.default_rng(4)
    start = datetime(2026, 1, 5, 8, tzinfo=UTC)
    rows = []
    for i in range(N):
        row = {"campaign": "c", "key": f"id{i + 1}-1", "repeat": 1, "step": "identify", "status": "ok", "error": "",
               "start_time": (start + timedelta(minutes=5 * i)).isoformat(), "inertia": 2e-4, "inertia_se": 1e-6,
               "breakaway": (1.0 if i < STEP_AT else 1.05) + 0.01 * rng.standard_normal(), "breakaway_se": 0.01,
               "viscous": 1e-3 + 1e-5 * rng.standard_normal(), "viscous_se": 1e-5, "validation_torque_nrmse": 0.05,
               "verdict": "good", "sliding_distance": 10.0, "settings_hash": "s", "content_hash": f"h{i}"}
        if i == FAILED:
            row.update(status="failed", error="AnalysisError: no position channel", breakaway=None, verdict=None)
        rows.append(row)
    return rows


@pytest.fixture
def results(tmp_path):
    import pyarrow.parquet as pq

    pq.write_table(to_table(_rows()), tmp_path / TABLE_NAME)
    return tmp_path


@pytest.fixture
def view(qtbot):
    v = CampaignView()
    qtbot.addWidget(v)
    yield v.results  # the view holds the tab: keep it alive


def _column(name: str) -> int:
    return [c[1] for c in RESULT_COLUMNS].index(name)


def test_results_tab_shows_the_runs_table_and_the_drift_charts(view, results):
    view.path_edit.setText(str(results))
    assert view.load()
    table = view.table
    assert table.rowCount() == N
    rows = _rows()
    for i in (0, STEP_AT, N - 1):  # shown in start order, break-away to 6 significant digits
        assert table.item(i, _column("key")).text() == rows[i]["key"]
        assert table.item(i, _column("breakaway")).data(0) == pytest.approx(rows[i]["breakaway"], rel=1e-5)
        assert table.item(i, _column("validation_torque_nrmse")).data(0) == pytest.approx(5.0)  # percent
    assert table.item(FAILED, _column("status")).text() == "failed"
    assert "no position channel" in table.item(FAILED, _column("verdict")).text()
    # the charts are the drift monitor's with its defaults: the CLI's baseline rule (the first half of 59 ok runs)
    truth = monitor(_rows(), DriftSettings(parameters=("breakaway",))).series["breakaway"]
    assert "baseline: the first 29 of 59 runs" in view.status.text()
    points = [i for i in view.plots["value"].listDataItems() if i.opts.get("symbol") == "o"][0]
    np.testing.assert_array_equal(points.getData()[1], truth.value)
    ewma = view.plots["ewma"].listDataItems()[0].getData()[1]
    np.testing.assert_array_equal(ewma[np.isfinite(ewma)], truth.ewma[np.isfinite(truth.ewma)])
    # the step at run 40 (39 of the 59 ok runs, start order): one change point within +-3 runs, drawn on all charts
    assert len(truth.change_points) == 1 and abs(truth.change_points[0] - (STEP_AT - 1)) <= 3
    # the x axis is the table's "#" (failed runs keep their number): the step's change point sits at the "#" of the
    # run the status names, one past the series index after the failed run 8
    shown = [i + 1 + (i >= FAILED) for i in truth.change_points]
    for plot in view.plots.values():
        lines = [i for i in plot.items if isinstance(i, pg.InfiniteLine) and i.angle == 90]
        assert [line.value() for line in lines] == shown
    x = points.getData()[0]
    assert x[0] == 1 and FAILED + 1 not in x and x[-1] == N
    named = view.drift.runs[truth.change_points[0]].split("/")[1]
    assert table.item(shown[0] - 1, _column("key")).text() == named
    assert "change points at c/id" in view.status.text()


def test_a_missing_results_folder_is_one_line_in_the_status(view, tmp_path):
    view.path_edit.setText(str(tmp_path / "nowhere"))
    assert not view.load()
    assert TABLE_NAME in view.status.text() and view.table.rowCount() == 0


def test_the_headers_carry_the_units_of_the_runs_axis():
    rotary, linear = result_headers("rotary"), result_headers("linear")
    assert rotary[_column("inertia")] == "inertia J\n(kg*m^2)" and linear[_column("inertia")] == "inertia J\n(kg)"
    assert linear[_column("breakaway")] == "break-away force\n(N)"
    assert linear[_column("viscous")] == "viscous coefficient b\n(N*s/m)"
    assert rotary[_column("validation_torque_nrmse")] == "validation torque NRMSE\n(%)"
    assert rotary[_column("temperature_mean")] == "winding\n(degC)" and rotary[_column("order")] == "#"


def test_the_value_chart_is_labelled_in_engineering_units(view, results):
    """The viscous coefficient (about 1e-3 N*m*s/rad) reads in mN*m*s/rad, as the live plots scale their axes: the
    axis scales its ticks by 1000, the data stay SI."""
    view.path_edit.setText(str(results))
    view.parameter.setCurrentText("viscous")
    assert view.load()
    axis = view.plots["value"].getAxis("left")
    assert "b (mN*m*s/rad)" in axis.labelString()
    assert axis.scale == 1000.0
    points = [i for i in view.plots["value"].listDataItems() if i.opts.get("symbol") == "o"][0]
    assert np.nanmax(points.getData()[1]) < 2e-3  # SI
    view.parameter.setCurrentText("breakaway")
    assert "break-away (N*m)" in axis.labelString() and axis.scale == 1.0
    assert view.plots["ewma"].getAxis("left").scale == 1.0


def test_the_operator_keeps_the_height_they_gave_the_table(view, results, qtbot):
    view.window().resize(800, 700)
    view.window().show()
    qtbot.waitExposed(view.window())
    view.window().tabs.setCurrentWidget(view)  # the CampaignView holding the tab
    view.path_edit.setText(str(results))
    assert view.load()
    table, charts = view.split.sizes()
    view.split.moveSplitter(table + 120, 1)  # as a drag of the handle does (it emits splitterMoved)
    moved = view.split.sizes()
    assert moved[0] > table
    view.window().resize(800, 760)
    qtbot.wait(50)
    assert view.split.sizes()[0] == moved[0]  # a resize gives its pixels to the charts, not back to the rule
    assert view.load() and view.split.sizes()[0] < moved[0]  # a new table: the rule again


def test_a_linear_axis_campaign_charts_in_linear_units(view, tmp_path):
    """Rows of a linear axis (their `axis` column): the value chart reads the column's `unit_linear` (N, kg), not
    the rotary unit the Parquet field's `unit` holds (issue #38)."""
    import pyarrow.parquet as pq

    pq.write_table(to_table([{**r, "axis": "linear"} for r in _rows()]), tmp_path / TABLE_NAME)
    view.path_edit.setText(str(tmp_path))
    assert view.load()
    assert view.axis == "linear"  # read once in load(), which the table's headers reuse
    heads = [view.table.horizontalHeaderItem(j).text() for j in range(view.table.columnCount())]
    assert heads == result_headers("linear") and "break-away force\n(N)" in heads
    axis = view.plots["value"].getAxis("left")
    assert "break-away (N) " in axis.labelString() and "N*m" not in axis.labelString()
    view.parameter.setCurrentText("viscous")  # about 1e-3: engineering prefix, linear unit
    assert "b (mN*s/m) " in axis.labelString()


def test_a_campaign_too_short_to_chart_says_so_in_the_status(view, tmp_path):
    """Two runs: the report's own line (all baseline, not charted), the table filled, no chart drawn."""
    import pyarrow.parquet as pq

    pq.write_table(to_table(_rows()[:2]), tmp_path / TABLE_NAME)
    view.path_edit.setText(str(tmp_path))
    assert not view.load()
    assert view.table.rowCount() == 2 and view.drift is None
    assert "no drift charts: baseline: the first 2 of 2 runs" in view.status.text()
    assert "not charted: 2 runs: too few to chart (a baseline needs 3" in view.status.text()
    assert not view.plots["value"].listDataItems()
