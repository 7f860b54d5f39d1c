"""Issue 28, GUI bullets: the operator window at 1280x800 (offscreen) shows every tab without scroll arrows, every
widget inside the window and not squeezed below its text, tables whose unit column is on screen, a verdict in
full, measured and model in distinct pens, state colours that mean something, messages in words, an error that
clears on a tab change, side panels of fixed width, one click to open a run, and the model saved and used as the
residual loop's start."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PySide6 import QtCore, QtGui, QtWidgets

from hilbench.bench.errors import BenchError
from hilbench.bench.gui import analyses
from hilbench.bench.gui.connection_panel import GREEN, state_colour
from hilbench.bench.gui.elided_label import ElidedLabel
from hilbench.bench.gui.main_window import MainWindow
from hilbench.bench.gui.run_browser import curve_pen, scaled_label
from hilbench.bench.gui.worker import DeviceState, one_line

SIZE = (1280, 800)


@pytest.fixture
def window(qapp, qtbot, tmp_path):
    w = MainWindow(device="sim://", runs_dir=tmp_path)
    w.resize(*SIZE)
    w.show()
    qtbot.waitExposed(w)
    yield w
    w.shutdown()
    w.close()


def _settle(qtbot) -> None:
    qtbot.wait(50)


def _tab_widgets(w: QtWidgets.QWidget) -> list[QtWidgets.QTabWidget]:
    return [t for t in w.findChildren(QtWidgets.QTabWidget) if t.isVisible()]


def _inside_scroll_area(widget: QtWidgets.QWidget) -> bool:
    parent = widget.parentWidget()
    while parent is not None:
        if isinstance(parent, QtWidgets.QAbstractScrollArea) and parent.viewport().isAncestorOf(widget):
            return True
        parent = parent.parentWidget()
    return False


def _text_width(widget: QtWidgets.QWidget) -> int:
    """Pixels the one-line text of a button, check box or label needs (0: none, or it wraps or elides itself)."""
    if isinstance(widget, QtWidgets.QLabel):
        if widget.wordWrap() or isinstance(widget, ElidedLabel) or not widget.text():
            return 0
        text = QtGui.QTextDocumentFragment.fromHtml(widget.text()).toPlainText() if QtGui.Qt.mightBeRichText(
            widget.text()) else widget.text()
        return widget.fontMetrics().horizontalAdvance(text)
    if isinstance(widget, QtWidgets.QAbstractButton) and widget.text():
        extra = 16 if isinstance(widget, QtWidgets.QCheckBox | QtWidgets.QRadioButton) else 0
        return widget.fontMetrics().horizontalAdvance(widget.text().replace("&", "")) + extra
    return 0


def layout_problems(w: QtWidgets.QMainWindow) -> list[str]:
    """What does not fit in the window as shown: tab bars that need scroll arrows or elide a tab, widgets outside
    the window, buttons/labels/check boxes narrower than their text, scroll areas that scroll sideways."""
    problems = []
    box = w.rect()
    for tabs in _tab_widgets(w):
        bar = tabs.tabBar()
        arrows = [b for b in bar.findChildren(QtWidgets.QToolButton) if b.isVisible()]
        if arrows:
            problems.append(f"tab bar {[tabs.tabText(i) for i in range(tabs.count())]} shows scroll arrows")
        for i in range(bar.count()):
            if not bar.rect().contains(bar.tabRect(i)):
                problems.append(f"tab {bar.tabText(i)!r} lies outside its bar")
            if bar.tabRect(i).width() < bar.fontMetrics().horizontalAdvance(bar.tabText(i)):
                problems.append(f"tab {bar.tabText(i)!r} is elided")
    for child in w.findChildren(QtWidgets.QWidget):
        if not child.isVisible() or child.isWindow() or _inside_scroll_area(child):
            continue
        top_left = child.mapTo(w, QtCore.QPoint(0, 0))
        rect = QtCore.QRect(top_left, child.size())
        name = f"{type(child).__name__} {child.objectName() or getattr(child, 'text', lambda: '')()!r}"
        if not box.contains(rect):
            problems.append(f"{name} at {rect.getRect()} is outside the {box.width()}x{box.height()} window")
        needs = _text_width(child)
        if child.width() < needs:
            problems.append(f"{name} is {child.width()} px wide, its text needs {needs}")
    for area in w.findChildren(QtWidgets.QScrollArea):
        if area.isVisible() and area.horizontalScrollBar().isVisible():
            problems.append(f"scroll area of {type(area.widget()).__name__} scrolls sideways")
    return problems


def test_every_tab_fits_1280x800_without_scroll_arrows(window, qtbot):
    assert (window.width(), window.height()) == SIZE  # no minimum size pushed it wider or taller
    pages = []
    for i in range(window.tabs.count()):
        window.tabs.setCurrentIndex(i)
        for j in range(window.protocol.tabs.count()):
            window.protocol.tabs.setCurrentIndex(j)
            names = range(window.protocol.protocol_box.count()) if j == 0 else [0]
            for k in names:
                window.protocol.protocol_box.setCurrentIndex(k)
                inner = [window.browser.tabs] if window.tabs.currentWidget() is window.browser else [None]
                for tabs in inner:
                    for m in range(tabs.count() if tabs is not None else 1):
                        if tabs is not None:
                            tabs.setCurrentIndex(m)
                        _settle(qtbot)
                        where = (window.tabs.tabText(i), window.protocol.tabs.tabText(j),
                                 window.protocol.protocol_box.itemText(k), tabs.tabText(m) if tabs else "")
                        pages.append(where)
                        problems = layout_problems(window)
                        assert not problems, (where, problems)
    # every protocol and the device settings, under each main tab (the run browser's two tabs each)
    n_protocols = window.protocol.protocol_box.count()
    assert n_protocols == len(window.protocol.forms) >= 5
    assert len(pages) == (n_protocols + 1) * (window.tabs.count() + 1), pages


def test_the_checker_sees_a_tab_bar_that_overflows(qapp, qtbot):
    """The oracle above can fail: five long tabs in a 300 px wide window need scroll arrows."""
    w = QtWidgets.QMainWindow()
    tabs = QtWidgets.QTabWidget()
    for name in ("Identification", "Chirp", "Stepped sine", "Presliding", "Device settings"):
        tabs.addTab(QtWidgets.QLabel("x"), name)
    w.setCentralWidget(tabs)
    w.resize(300, 200)
    w.show()
    qtbot.waitExposed(w)
    _settle(qtbot)
    assert any("scroll arrows" in p for p in layout_problems(w))
    w.close()


def test_the_output_path_shows_its_start_and_end(window, qtbot):
    path = "/very/long/folder/name/of/the/lab/bench/runs/campaign-2026-11/identification-20261126-203000.h5"
    window.protocol.out_edit.setText(path)
    _settle(qtbot)
    shown = window.protocol.out_label.text()
    assert shown.startswith("/very/") and shown.endswith("203000.h5") and "…" in shown
    assert window.protocol.out_label.toolTip() == path
    assert window.protocol.out_label.fontMetrics().horizontalAdvance(shown) <= window.protocol.out_label.width()


def _result(verdict: str) -> analyses.AnalysisResult:
    numbers = [("verdict", verdict, ""),
               ("initial stiffness sum(k) (edge points, p = 2, baseline), a long quantity name", "1.2345e+03 +- 12",
                "N*m/rad"),
               ("Masing rule departure, max (of the largest virgin force)", "0.0123", "1")]
    t = np.linspace(0, 1, 200)
    fig = analyses.Figure("force against displacement", "displacement (rad)", "force (N*m)",
                          [("measured", 2e-4 * np.sin(t), 3e-3 * t), ("model: force from the displacement",
                                                                     2e-4 * np.sin(t), 3e-3 * t)])
    return analyses.AnalysisResult("Residual loop", numbers, [fig])


def test_result_tables_fit_and_the_verdict_is_whole(window, qtbot):
    window.tabs.setCurrentWidget(window.browser)
    window.browser.tabs.setCurrentIndex(1)
    verdict = "structure found that no candidate explains: position-periodic residual at 12 cycles/rev"
    window.browser.show_result(_result(verdict))
    _settle(qtbot)
    table = window.browser.numbers
    assert table.columnViewportPosition(2) + table.columnWidth(2) <= table.viewport().width()
    metrics = table.fontMetrics()
    for row in range(table.rowCount()):  # value and unit are never cut
        for col in (1, 2):
            assert table.columnWidth(col) >= metrics.horizontalAdvance(table.item(row, col).text())
    assert verdict in window.browser.analysis_status.text()  # whole, above the table, wrapped
    assert window.browser.analysis_status.wordWrap()
    assert all(table.item(r, 0).text() != "verdict" for r in range(table.rowCount()))
    assert not layout_problems(window)


def test_measured_and_model_differ_in_colour_and_line_style():
    measured, model = curve_pen("measured", 0), curve_pen("model: force from the displacement", 1)
    assert measured["color"] != model["color"]
    assert measured.get("style", QtCore.Qt.PenStyle.SolidLine) != model["style"]
    others = [curve_pen(f"curve {i}", i) for i in range(4)]
    assert len({(p["color"], p["style"]) for p in others}) == 4


def test_small_values_are_drawn_in_engineering_units():
    assert scaled_label("displacement (rad)", [2e-4, -3e-4]) == (1000.0, "displacement (mrad)")
    assert scaled_label("force (N*m)", [0.003]) == (1000.0, "force (mN*m)")
    assert scaled_label("t (s)", [1e-3]) == (1.0, "t (s)")
    assert scaled_label("position (rad)", [2.0]) == (1.0, "position (rad)")
    assert scaled_label("amplitude A (m)", [5e-6]) == (1e6, "amplitude A (µm)")


def test_no_plot_axis_adds_a_multiplier_to_its_unit(window):
    """pyqtgraph's automatic SI prefix wrote "position (rad) (x0.001)" on the live plot; every axis says its unit
    in its label and nothing else."""
    import pyqtgraph as pg

    plots = [*window.live.plots]
    window.browser.show_result(_result("good fit"))
    plots += [item for item in window.browser.figures.ci.items if isinstance(item, pg.PlotItem)]
    assert len(plots) >= 5
    for plot in plots:
        for side in ("left", "bottom"):
            axis = plot.getAxis(side)
            assert not axis.autoSIPrefix or not plot.getAxis(side).isVisible(), (side, axis.labelText)


def _state(name: str, faults=(), counters=None) -> DeviceState:
    return DeviceState(name, list(faults), 1 if faults else 0, 10, 0.0, counters or {"host_crc_errors": 0})


def test_green_only_for_healthy_and_ready():
    for name in ("UNCONFIGURED", "DISARMED"):
        colour, verdict = state_colour(_state(name))
        assert colour != GREEN and "ready" in verdict and GREEN in verdict
    for name in ("ARMED", "STREAMING"):
        colour, verdict = state_colour(_state(name))
        assert colour != GREEN and GREEN not in verdict
    colour, verdict = state_colour(_state("DISARMED", faults=["ESTOP"]))
    assert colour == "#c00000" and GREEN not in verdict
    colour, verdict = state_colour(_state("DISARMED", counters={"host_crc_errors": 3}))
    assert GREEN not in colour + verdict and "3 link errors" in verdict


def test_messages_are_words_without_class_names():
    from hilbench.drivers.errors import DeviceFaultError

    assert one_line(BenchError("bad\n  input")) == "bad input"
    assert one_line(DeviceFaultError("device fault: ESTOP")) == "device fault: ESTOP"
    assert "Error" not in one_line(RuntimeError()) and one_line(KeyError("t")) == "missing entry 't'"


def test_a_red_error_clears_on_a_tab_change(window, qtbot):
    window.show_message("cannot open x.h5: not an HDF5 file", error=True)
    assert "not an HDF5 file" in window.banner.text()
    window.tabs.setCurrentWidget(window.browser)
    assert window.banner.text() == "" and window.messages[-1][1].startswith("cannot open")
    window.show_message("opened y.h5", error=False)
    window.tabs.setCurrentWidget(window.live)
    assert "opened y.h5" in window.banner.text()  # information stays


def test_side_panels_keep_their_width(window, qtbot):
    widths = (window.connection.width(), window.protocol.width())
    long = "x" * 400
    window.connection.show_state(_state("DISARMED", counters={f"host_{long}": 1}))
    window.connection.identity_label.setText(long)
    window.protocol.summary.setText(long)
    _settle(qtbot)
    assert (window.connection.width(), window.protocol.width()) == widths
    assert window.width() == SIZE[0]


def _write_run(path) -> None:
    from hilbench.firmware_sim.engine.plant import PlantParams
    from tests.analysis.afrf.test_afrf_run import C, K, M
    from tests.analysis.afrf.test_afrf_run import _write_run as write_stepped_sine

    write_stepped_sine(path, PlantParams(inertia=M, spring=K, viscous=C), [2.0], [0.5])


def test_one_click_opens_a_run(window, qtbot, tmp_path):
    _write_run(tmp_path / "a.h5")
    browser = window.browser
    window.tabs.setCurrentWidget(browser)
    browser.refresh_files()
    _settle(qtbot)
    item = browser.files.item(0)
    rect = browser.files.visualItemRect(item)
    qtbot.mouseClick(browser.files.viewport(), QtCore.Qt.MouseButton.LeftButton, pos=rect.center())
    assert browser.run is not None and str(browser.run.path).endswith("a.h5")


def test_the_model_is_saved_as_identify_writes_it_and_starts_the_residual_loop(window, qtbot, tmp_path):
    """Save model... writes the document `hilbench identify RUN --json` writes (same parameters, same schema,
    read back by the model file reader); the residual loop started from that file starts from its terms."""
    from hilbench.analysis.models.model_file import read_model
    from hilbench.bench.cli import main
    from tests.bench.test_identify_command import _write_run as write_identification_run

    run = tmp_path / "ident.h5"
    write_identification_run(run, 1)
    browser = window.browser
    assert not browser.save_model(str(tmp_path / "none.json"))  # nothing identified yet: a message, no file
    assert not (tmp_path / "none.json").exists()
    result = analyses.run_analysis("identify", run)
    browser.path_edit.setText(str(run))
    browser.show_result(result)
    assert browser.save_model_button.isEnabled()
    assert not browser.save_model(str(run))  # never over the run it came from
    assert browser.save_model(str(tmp_path / "gui.json"))
    assert main(["identify", str(run), "--json", str(tmp_path / "cli.json")]) == 0
    gui, cli = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("gui", "cli"))
    assert gui["schema"] == cli["schema"] and gui["parameters"] == cli["parameters"]
    assert gui["data"]["train"] == cli["data"]["train"]
    model, _doc = read_model(tmp_path / "gui.json")
    assert model.ms_stiffness.size == len(cli["parameters"]["ms_stiffness"])

    # the saved model starts the GUI's residual loop as `hilbench residual --start MODEL.json` does: same call,
    # same start figure (identify's definition), same verdict
    res = analyses.run_analysis("residual", run, {"start_model": str(tmp_path / "gui.json")})
    shown = {q: v for q, v, _u in res.numbers}
    assert main(["residual", str(run), "--start", str(tmp_path / "gui.json"), "--json", str(tmp_path / "r.json"),
                 "-q"]) == 0
    cli_res = json.loads((tmp_path / "r.json").read_text())
    start_figure = [v for q, v in shown.items() if q.startswith("start model (") and "torque NRMSE" in q]
    assert start_figure, shown
    figs = cli_res["inputs"]["start_model"]["figures"]
    where = "validation_torque_nrmse" if "validation_torque_nrmse" in figs else "train_torque_nrmse"
    assert float(start_figure[0]) == pytest.approx(100 * figs[where], rel=5e-3)  # shown to 3 digits
    assert shown["verdict"] == str(cli_res["verdict"])


class _FakePlan:
    runs = {"identification": object(), "chirp": object()}

    def lines(self) -> list[str]:
        return ["probe: 1 run(s), peak 7.5 A", "identification: amplitude 12 A <sized>"]

    def write(self, path) -> None:
        from pathlib import Path

        Path(path).write_text("[defaults]\ndevice = \"sim://\"\n")


def test_plan_experiments_calls_the_planner_with_the_connected_bench(window, qtbot, tmp_path, monkeypatch):
    """The button's path: plan_experiments(bench, the form's device settings, probe_dir under the runs folder,
    progress) in the run thread; the campaign TOML written where asked, put in the Campaign tab, the plan's lines
    shown. A stand-in planning module records the call (the real probe is tests/bench/test_plan.py's)."""
    import sys
    import types

    calls = []

    def plan_experiments(bench, settings, *, probe_dir, progress):
        calls.append((bench, settings, probe_dir, progress))
        return _FakePlan()

    monkeypatch.setitem(sys.modules, "hilbench.bench.acquisition.planning",
                        types.SimpleNamespace(plan_experiments=plan_experiments))
    assert not window.start_plan(str(tmp_path / "plan.toml"))  # not connected: refused in words
    assert "connect to a device" in window.messages[-1][1]
    bench = types.SimpleNamespace(settings=None)
    monkeypatch.setattr(window.device, "bench", bench)
    monkeypatch.setattr(window.device, "url", "sim://")
    window.device_info = {"url": "sim://"}
    try:
        assert window.start_plan(str(tmp_path / "plan.toml"))
        qtbot.waitUntil(lambda: window.run_worker is None, timeout=10000)
    finally:
        window.device_info = None
    (called_bench, settings, probe_dir, progress), = calls
    assert called_bench is bench and settings.current_limit == float(window.protocol.device_form.fields[
        "current_limit"].text()) and str(probe_dir).startswith(str(window.runs_dir / "plan-probe-"))
    assert callable(progress)
    assert (tmp_path / "plan.toml").read_text().startswith("[defaults]")
    assert window.campaign.path_edit.text() == str(tmp_path / "plan.toml")
    assert window.banner.toolTip().splitlines() == _FakePlan().lines()
    assert "loaded in the Campaign tab" in window.banner.text() and window.tabs.currentWidget() is window.campaign


def test_campaign_results_are_whole_and_styled_like_the_live_plots(window, qtbot, tmp_path):
    """Issue 38: the Results tab's table showed one row, its header read "reak-away (N", its charts were black
    while the live plots are white. At 1280x800 with a 12-run table: the first rows (up to TABLE_ROWS) are all in
    view, every header line and every value fits its column, the charts share the live plots' background."""
    import pyarrow.parquet as pq

    from hilbench.bench.campaign_analysis.table import TABLE_NAME, to_table
    from hilbench.bench.gui.campaign_view import TABLE_ROWS
    from tests.bench.gui.test_campaign_results import _rows

    pq.write_table(to_table(_rows()[:12]), tmp_path / TABLE_NAME)
    results = window.campaign.results
    window.tabs.setCurrentWidget(window.campaign)
    window.campaign.tabs.setCurrentWidget(results)
    results.path_edit.setText(str(tmp_path))
    assert results.load()
    _settle(qtbot)
    table, header = results.table, results.table.horizontalHeader()
    assert table.rowCount() == 12
    for row in range(TABLE_ROWS):  # whole rows in the viewport, not one row and a scroll bar
        assert table.rowViewportPosition(row) + table.rowHeight(row) <= table.viewport().height(), row
    metrics = header.fontMetrics()
    for col in range(table.columnCount()):
        lines = table.horizontalHeaderItem(col).text().split("\n")
        assert header.sectionSize(col) >= max(metrics.horizontalAdvance(line) for line in lines), lines
        assert header.height() >= len(lines) * metrics.height(), lines
        for row in range(table.rowCount()):
            assert table.columnWidth(col) >= table.fontMetrics().horizontalAdvance(table.item(row, col).text())
    live = window.live.graphics.backgroundBrush().color()
    assert results.graphics.backgroundBrush().color() == live == QtGui.QColor("white")
    assert not layout_problems(window)
