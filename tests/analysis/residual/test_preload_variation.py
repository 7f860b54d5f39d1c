"""``preload_variation`` (issue 29) recovers a friction level that varies over a period longer than the stroke, on
records of the independent truth generator (tests/truth/generator.py, a PD position loop keeping the motor within
the stroke): an eccentric preload once per revolution, level x (1 + m*sin(theta + phi)), seen over 5 rad, and a
level slope along a linear axis' travel, level x (1 + g*x). Closed forms: the term's sin/cos coefficients are
A*(cos phi, sin phi) with A = m*F_c, and on a linear axis its slope is g*F_c (N/m)."""

from __future__ import annotations

import numpy as np
import pytest

from hilbench.analysis.residual import LoopOptions, residual_loop
from tests.truth.matrix import CASES, START, prepared, record


def _loop(case: str):
    truth, _ = CASES[case]
    return truth, residual_loop(prepared(record(truth, 1), "train"), prepared(record(truth, 1001), "valid"),
                                start=START, options=LoopOptions(sim_window=None))


def test_eccentric_preload_over_5_rad():
    truth, res = _loop("eccentric-stroke5")
    assert res.names_added == ["preload_variation"]
    p = res.effect("preload_variation")["parameters"]
    _, depth, phase = truth.angle_level
    # the depth relative to the fitted sliding level, and the phase of sin(theta + phi): 10 % and 0.1 rad (the
    # sliding level itself absorbs the level's mean over the stroke, a few per cent)
    assert p["relative_depth"] == pytest.approx(depth, rel=0.1)
    assert p["level_variation"] == pytest.approx(depth * truth.coulomb, rel=0.1)
    assert abs(np.angle(np.exp(1j * (p["phase"] - phase)))) < 0.1
    assert res.error_after["validation"]["torque_rel_pct"] < 0.5 * res.error_before["validation"]["torque_rel_pct"]


def test_level_slope_along_a_linear_axis():
    truth, res = _loop("preload-linear")
    assert res.names_added == ["preload_variation"]
    p = res.effect("preload_variation")["parameters"]
    assert p["slope"] == pytest.approx(truth.level_slope * truth.coulomb, rel=0.1)  # N/m
    assert abs(p["curvature"]) < 0.1 * abs(p["level_variation"])  # no P2 part in a linear slope
