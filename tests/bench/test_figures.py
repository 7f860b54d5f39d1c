"""Issue 13 item 6: every figure the commands write has, on every axis that shows tick labels, a label naming a
unit, and no empty legend (tests/figure_checks.py). identify's and residual's figures are checked in
tests/bench/test_identify_command.py and test_residual_command.py, the paper's in
tests/analysis/reproductions/test_paper.py, on the runs those tests already make."""

import numpy as np
import pytest

from hilbench.bench.cli import main
from hilbench.firmware_sim.engine.plant import PlantParams
from tests.analysis.afrf.test_afrf_run import C, K, M
from tests.analysis.afrf.test_afrf_run import _write_run as write_stepped_sine
from tests.bench.test_paper_skeleton_commands import _write_chirp
from tests.figure_checks import figure_problems, recording_figures


def _assert_readable(seen: dict, expected: set[str]) -> None:
    assert expected <= set(seen), f"figures written: {sorted(seen)}"
    bad = {name: problems for name, problems in seen.items() if problems}
    assert not bad, bad


def test_the_checker_catches_what_it_should():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure()
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.plot([0, 1], [0, 1], label="_hidden")
    ax.set_xlabel("time")  # no unit
    ax.legend(["" ])
    fig.canvas.draw()
    problems = figure_problems(fig)
    assert any("names no unit" in p for p in problems)  # x: 'time'
    assert any("no label" in p for p in problems)  # y: ticks but no label
    assert any("empty legend" in p for p in problems)


def test_afrf_figure(tmp_path):
    path = tmp_path / "s.h5"
    write_stepped_sine(path, PlantParams(inertia=M, spring=K, viscous=C), [1.0, 3.0], [0.5, 2.0])
    with recording_figures() as seen:
        assert main(["afrf", str(path), "--plot", str(tmp_path / "afrf.png")]) == 0
    _assert_readable(seen, {"afrf.png"})


def test_afrf_figure_has_one_legend_and_plain_frequency_ticks(tmp_path):
    from hilbench.analysis.afrf.frf import afrf_from_run, plot_afrf

    path = tmp_path / "s.h5"
    write_stepped_sine(path, PlantParams(inertia=M, spring=K, viscous=C), [2.0, 5.0, 10.0, 20.0], [0.5, 2.0])
    fig = plot_afrf(afrf_from_run(path), measured=True)
    fig.canvas.draw()
    assert len(fig.legends) == 1 and all(ax.get_legend() is None for ax in fig.axes)
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["G = 0.5 A", "G = 2 A"]
    ticks = {t.get_text() for t in fig.axes[0].get_xticklabels() if t.get_visible() and t.get_text()}
    assert {"2", "5", "10", "20"} <= ticks  # a 2-20 Hz axis is not labelled by a lone "10^1"
    for ax in fig.axes[1:]:  # higher harmonics of measured steps: points, not lines through the noise
        assert all(line.get_linestyle() == "None" for line in ax.get_lines())


def test_skeleton_figure(tmp_path):
    files = [tmp_path / f"g{g}.h5" for g in (0.5, 5.0)]
    for f, g in zip(files, (0.5, 5.0), strict=True):
        _write_chirp(f, g, duration=30.0)
    with recording_figures() as seen:
        assert main(["skeleton", *map(str, files), "--spring", "50", "--plot", str(tmp_path / "s.png")]) == 0
    _assert_readable(seen, {"s.png"})


def test_demo_paper_figure(tmp_path):
    from hilbench.bench.cli.demo import paper_figure

    with recording_figures() as seen:
        paper_figure(tmp_path)
    _assert_readable(seen, {"paper_chirp_hysteresis.png"})


@pytest.mark.parametrize("n_points", [1, 3])
def test_busiest_window_finds_the_reversals(n_points):
    from hilbench.analysis.identification.plots import busiest_window

    t = np.arange(0, 10, 1e-3)
    x = np.where((t > 6) & (t < 7), np.sin(2 * np.pi * 10 * n_points * t), 0.01 * t)  # reversals only in 6..7 s
    i0, i1 = busiest_window(t, x, 1.0)
    assert 5.75 <= t[i0] <= 6.0 and 6.75 <= t[i1 - 1] <= 7.0
