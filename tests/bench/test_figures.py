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


def test_the_checker_catches_overlapping_ticks_offsets_and_a_legend_over_the_data():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3, 2))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    x = np.linspace(1e-4, 2e-4, 50)
    ax.plot(x, 1000.0 + 1e-3 * x, label="a curve with a long name")  # offset text on y, tiny values on x
    ax.set_xticks(x[::5], [f"{v:.6f} rad" for v in x[::5]])  # ten long labels on a 3 inch axis
    ax.set_xlabel("position (rad)")
    ax.set_ylabel("torque (N*m)")
    ax.legend(loc="center", fontsize=14)
    fig.canvas.draw()
    problems = figure_problems(fig)
    assert any("overlap" in p for p in problems), problems
    assert any("offset/multiplier" in p for p in problems), problems
    assert any("legend covers" in p for p in problems), problems


def _curves(amplitudes: list[np.ndarray]):
    """Skeleton curves of runs covering the given amplitude ranges (rad): k_eq*A = 5*A, points on the bins."""
    from hilbench.analysis.skeleton.forcevib import SkeletonCurves

    a = np.concatenate(amplitudes)
    run = np.concatenate([np.full(x.size, i) for i, x in enumerate(amplitudes)])
    v = 20.0 * a
    return SkeletonCurves(amplitude=a, stiffness=np.full(a.size, 5.0), restoring_force=5.0 * a,
                          energy=a, amplitude_count=np.full(a.size, 30), velocity=v, damping=np.full(a.size, 0.1),
                          damping_force=0.1 * v, velocity_count=np.full(a.size, 30), points_amplitude=a,
                          points_restoring_force=5.0 * a, points_velocity=v, points_damping_force=0.1 * v,
                          points_run=run)


def test_skeleton_of_two_runs_breaks_at_the_gap_with_readable_ticks_and_a_title():
    """Issue 28: the composed curve of two runs whose amplitude ranges do not meet (2-20 urad and 1-10 mrad) is not
    joined across the gap; log ticks do not overlap; small values in mrad and mN*m; the title names the runs."""
    from hilbench.analysis.skeleton.figure import skeleton_figure

    low, high = np.geomspace(2e-6, 2e-5, 12), np.geomspace(1e-3, 1e-2, 12)
    fig = skeleton_figure(_curves([low, high]), ["g0.5.h5", "g5.h5"], "rad", "N*m")
    fig.canvas.draw()
    assert not figure_problems(fig), figure_problems(fig)
    composed = [line for line in fig.axes[0].get_lines() if line.get_color() == "k"][0]
    x = np.asarray(composed.get_xdata(), float)
    gap = np.flatnonzero(np.isnan(x))
    assert gap.size == 1 and x[gap[0] - 1] == pytest.approx(1e3 * low[-1]) and x[gap[0] + 1] == pytest.approx(
        1e3 * high[0])  # one break, exactly between the runs, drawn in mrad
    assert fig.axes[0].get_xlabel().endswith("(mrad)") and "(mN*m)" in fig.axes[0].get_ylabel()
    assert "g0.5.h5" in fig._suptitle.get_text() and "g5.h5" in fig._suptitle.get_text()
    one = skeleton_figure(_curves([np.geomspace(1e-3, 1e-2, 24)]), ["g5.h5"], "rad", "N*m")
    assert not np.isnan(np.asarray(one.axes[0].get_lines()[-1].get_xdata(), float)).any()  # no gap: no break


def test_skeleton_of_a_narrow_amplitude_range_has_ticks_apart():
    """The default chirp's 0.220-0.237 mrad (7 %): a log axis labelled it with overlapping minor labels."""
    from hilbench.analysis.skeleton.figure import skeleton_figure

    fig = skeleton_figure(_curves([np.linspace(2.20e-4, 2.37e-4, 20)]), ["chirp.h5"], "rad", "N*m")
    fig.canvas.draw()
    assert not figure_problems(fig), figure_problems(fig)
    labels = [t.get_text() for t in fig.axes[0].get_xticklabels() if t.get_visible() and t.get_text()]
    assert len(labels) >= 2


def test_compare_figures_are_small_multiples_with_the_legend_outside(tmp_path):
    """Issue 28: one panel per family (measured and that family only), no legend inside an axes, readable."""
    from tests.bench.test_compare_command import _write

    _write(tmp_path / "a.h5", 1)
    _write(tmp_path / "b.h5", 2)
    figures: dict = {}
    with recording_figures(figures) as seen:
        assert main(["compare", str(tmp_path / "a.h5"), "--validate", str(tmp_path / "b.h5"), "-o",
                     str(tmp_path / "out"), "--families", "coulomb_viscous,dahl,continuous", "--torque-timing",
                     "hold_next", "--max-evaluations", "30"]) == 0
    _assert_readable(seen, {"compare_hysteresis.png", "compare_time.png"})
    loops = [ax for ax in figures["compare_hysteresis.png"].axes if ax.get_visible()]
    assert [ax.get_title() for ax in loops] == ["coulomb_viscous", "dahl", "continuous"]
    assert all(len(ax.get_lines()) == 2 and ax.get_legend() is None for ax in loops)
    time = figures["compare_time.png"]
    assert len(time.axes) == 2 * 4 and all(len(ax.get_lines()) <= 2 + 1 for ax in time.axes)
    assert all(ax.get_legend() is None for ax in time.axes) and len(time.legends) == 1


def test_engineering_units_and_gaps_against_hand_values():
    from hilbench.analysis.figure_style import engineering, with_gaps

    assert engineering("rad", [0.05, -0.02]) == (1e3, "mrad")
    assert engineering("rad", [0.1]) == (1.0, "rad")  # 0.1 rad reads well as it is
    assert engineering("rad", [5e-5]) == (1e6, "µrad")
    assert engineering("N*m", [np.nan, -0.01]) == (1e3, "mN*m")  # NaN ignored, sign ignored
    assert engineering("rad/s", [0.002]) == (1e3, "mrad/s")
    for unit in ("mrad", "mm", "mN*m", "1", "%", "s", "Hz", "kg*m^2", ""):
        assert engineering(unit, [1e-5]) == (1.0, unit)
    assert engineering("rad", [0.0]) == (1.0, "rad") and engineering("rad", []) == (1.0, "rad")
    x = np.array([1.0, 2.0, 4.0, 8.0, 64.0, 128.0])  # log steps ln 2, one of ln 8: one break
    gx, gy = with_gaps(x, 10 * x)
    np.testing.assert_array_equal(np.isnan(gx), [False] * 4 + [True] + [False] * 2)
    np.testing.assert_array_equal(gy[~np.isnan(gy)], 10 * x)
    lx, = with_gaps(np.array([0.0, 1.0, 2.0, 3.0, 4.0, 10.0]), log=False)
    assert np.isnan(lx[5]) and lx.size == 7


def test_presliding_figures_are_readable_with_the_legend_below():
    """Issue 28: the presliding legends were 6-7 pt inside the data; now one legend per figure below the axes at
    8.5 pt or more, ticks in mrad (a 2^16 counts/rev ramp of 20 counts spans 1.9 mrad), no offset text."""
    from hilbench.analysis.presliding.analyse import analyse, figures
    from tests.analysis.presliding.test_edges import record

    _theta, x, force, _k, _w = record()
    res = analyse(np.arange(x.size) / 1e4, x, force, 1e4, counts_per_rev=65536, replicates=2)
    for name, fig in figures(res).items():
        fig.canvas.draw()
        assert not figure_problems(fig), (name, figure_problems(fig))
        assert len(fig.legends) == 1 and all(ax.get_legend() is None for ax in fig.axes), name
        assert min(t.get_fontsize() for t in fig.legends[0].get_texts()) >= 8.5, name
        assert "(mrad" in fig.axes[0].get_xlabel(), name
