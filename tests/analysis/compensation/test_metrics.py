"""Tracking metrics and references against hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hilbench.analysis.compensation.closed_loop import PositionGains, simulate_tracking
from hilbench.analysis.compensation.feedforward import Compensator, coulomb_at_breakaway, feedforward
from hilbench.analysis.compensation.metrics import reversal_glitch, settling_times, tracking_metrics
from hilbench.analysis.compensation.references import make_reference, point_to_point, slow_sine, triangle
from hilbench.analysis.errors import AnalysisError
from hilbench.firmware_sim.engine.friction_models import dc_motor


def test_sine_reference_is_the_closed_form_with_its_reversals():
    fs, a, f = 1000.0, 0.01, 2.0
    ref = slow_sine(fs, amplitudes=(a,), frequency=f, cycles=2, rest=0.1)
    t = np.arange(1000) / fs
    assert np.allclose(ref.position[100:1100], a * (1 - np.cos(2 * np.pi * f * t)), atol=1e-15)
    assert np.allclose(ref.acceleration[100:1100], a * (2 * np.pi * f) ** 2 * np.cos(2 * np.pi * f * t))
    # peaks at t = 0.25, 0.75 s (velocity turns negative), trough at 0.5 s: 3 reversals, one sample after each
    assert ref.reversals().tolist() == [100 + 251, 100 + 501, 100 + 751]


def test_triangle_speed_corners_and_closure():
    fs, a, f, c = 10000.0, 0.02, 1.0, 0.02
    ref = triangle(fs, amplitude=a, frequency=f, cycles=2, corner=c, rest=0.0)
    speed = 4 * a * f
    assert np.max(np.abs(ref.velocity)) == pytest.approx(speed)
    assert np.max(np.abs(ref.acceleration)) == pytest.approx(2 * speed / c)
    assert ref.position[-1] == pytest.approx(0.0, abs=1e-12)
    # the blend (velocity S -> 0 over c/2 before the peak) shaves S*c/4 off each peak of the sharp triangle
    assert np.max(ref.position) == pytest.approx(a - speed * c / 4, rel=1e-6)
    assert np.allclose(np.diff(ref.position) * fs, (ref.velocity[1:] + ref.velocity[:-1]) / 2, atol=1e-9)
    assert len(ref.reversals()) == 4


def test_point_to_point_minimum_jerk():
    fs = 1000.0
    ref = point_to_point(fs, targets=(0.1, -0.1), move_time=0.5, rest=0.2)
    assert ref.moves.tolist() == [[200, 700], [900, 1400]]
    mid = 200 + 250
    assert ref.position[mid] == pytest.approx(0.05)                 # half way at half time
    assert ref.velocity[mid] == pytest.approx(0.1 * 1.875 / 0.5)     # peak speed 15/8 * d/T
    assert ref.position[700:900].tolist() == [0.1] * 200
    assert ref.reversals().tolist() == [901]


@pytest.mark.parametrize("kind, params, match", [
    ("sine", {"amplitudes": ()}, "at least one amplitude"),
    ("sine", {"frequency": -1}, "frequency"),
    ("triangle", {"corner": 1.0}, "quarter period"),
    ("point_to_point", {"targets": (math.nan,)}, "finite targets"),
    ("square", {}, "must be one of"),
    ("sine", {"bogus": 1}, "bogus"),
])
def test_bad_reference_parameters(kind, params, match):
    with pytest.raises(AnalysisError, match=match):
        make_reference(kind, 1000.0, **params)


def test_metrics_closed_forms():
    fs = 1000.0
    ref = point_to_point(fs, targets=(0.01, 0.0), move_time=0.1, rest=0.2)
    # error: 2 mrad decaying as exp(-t/tau) after each move ends, zero elsewhere
    e = np.zeros(ref.n)
    tau = 0.02
    for _, stop in ref.moves:
        k = np.arange(200)
        e[stop:stop + 200] = 2e-3 * np.exp(-k / fs / tau)
    q = ref.position - e
    current = np.full(ref.n, 2.0)
    current[: ref.n // 2] = -2.0
    m = tracking_metrics(ref, q, current, window=0.05, tolerance=1e-4)
    assert m.rms_error == pytest.approx(math.sqrt(np.sum(e ** 2) / ref.n))
    assert m.max_error == pytest.approx(2e-3)
    assert m.effort_rms == pytest.approx(2.0)
    # |e| <= 1e-4 from k > tau*fs*ln(20) = 59.9 samples: the last sample above is 59, settled at 60/fs
    assert m.settling.tolist() == pytest.approx([0.060, 0.060])
    # the reversal (start of the second move) is at sample 301 + ... : its window holds the first move's tail
    rev = ref.reversals()
    assert rev.tolist() == [ref.moves[1, 0] + 1]
    assert m.glitch.tolist() == pytest.approx([np.max(e[rev[0]:rev[0] + 50])])


def test_glitch_window_and_unsettled_move():
    e = np.array([0, 0, 3, -5, 0.2, 0, 0, 9, 0, 0], float)
    assert reversal_glitch(e, np.array([1, 5]), fs=1.0, window=3).tolist() == [5, 9]
    moves = np.array([[0, 2], [5, 7]])
    s = settling_times(e, moves, fs=1.0, tolerance=0.5)
    assert s.tolist() == [2.0, 1.0]
    s = settling_times(np.r_[e[:9], 4.0], moves, fs=1.0, tolerance=0.5)
    assert math.isnan(s[1])


def test_maxwell_slip_feedforward_removes_the_glitch_in_closed_loop():
    """The prediction: on the true DC-motor plant the Maxwell-slip feed-forward of the true model cuts the
    mean reversal glitch by more than 50x against none and 20x against Coulomb at the same break-away."""
    truth = dc_motor(16)
    fs = 1000.0
    ref = slow_sine(fs, amplitudes=(1e-3, 1e-2), frequency=1.0, cycles=1, rest=0.1)
    ms = truth.replace(torque_constant=1.0)
    glitch = {}
    for comp in (Compensator("none", None), coulomb_at_breakaway(ms), Compensator("maxwell_slip", ms)):
        ff = feedforward(comp, ref, truth.torque_constant, 1.0, 20.0)
        run = simulate_tracking(truth, ref.position, ff.current, fs, PositionGains(), 20.0)
        glitch[comp.name] = tracking_metrics(ref, run.position, run.current, window=0.05).glitch_mean
    assert glitch["none"] / glitch["maxwell_slip"] > 50
    assert glitch["coulomb"] / glitch["maxwell_slip"] > 20


def test_glitch_by_sine_amplitude():
    from hilbench.analysis.compensation.report import CaseResult, section_glitch, section_table

    fs = 1000.0
    ref = slow_sine(fs, amplitudes=(1e-3, 1e-2), frequency=1.0, cycles=1, rest=0.1)
    assert [s[0] for s in ref.sections] == ["A = 1 mrad", "A = 10 mrad"]
    assert [s[1:] for s in ref.sections] == [(100, 1100), (1200, 2200)]
    e = np.zeros(ref.n)
    rev = ref.reversals()  # 601 (first peak), 1200 (second sine starts), 1701 (its peak)
    e[rev] = [1e-3, 2e-3, 4e-3]
    m = tracking_metrics(ref, ref.position - e, np.zeros(ref.n), window=0.01)
    g = section_glitch(CaseResult(ref, "none", m, e, 0))
    assert g == pytest.approx({"A = 1 mrad": 1e-3, "A = 10 mrad": 3e-3})
    assert "| none | 1 (1) | 3 (1) |" in section_table([CaseResult(ref, "none", m, e, 0)])


def test_table_reduction_factors_against_none_and_coulomb():
    from hilbench.analysis.compensation.report import CaseResult, markdown_table

    ref = triangle(1000.0, amplitude=0.01, frequency=1.0, cycles=1, corner=0.01, rest=0.05)
    rev = ref.reversals()
    rows = []
    for name, peak in (("none", 8e-3), ("coulomb", 2e-3), ("maxwell_slip", 1e-3)):
        e = np.zeros(ref.n)
        e[rev] = peak
        m = tracking_metrics(ref, ref.position - e, np.ones(ref.n), window=0.01)
        rows.append(CaseResult(ref, name, m, e, 0))
    table = markdown_table(rows)
    assert "| triangle | maxwell_slip | " in table
    line = next(t for t in table.splitlines() if "| maxwell_slip |" in t).split("|")
    # columns: glitch mean 1 mrad, max 1 mrad, vs none 8x, vs coulomb 2x
    assert [c.strip() for c in line[6:10]] == ["1", "1", "8", "2"]
