"""Foreign-data regression record of the residual loop (issue 29): on data its own engine did not make (EMPS, a
tribometer-style displacement record of the independent truth generator, the Bouc-Wen records of the second
independent generator (tests/foreign), HSM150 when ``HILBENCH_REAL_DATA`` holds
it) the loop's validation error after the loop may not get worse than its floor in
tests/data/residual_foreign_floors.json by more than ``FLOOR_MARGIN`` (3 %, relative). A change that improves a
figure lowers its floor by editing that file (say so in the commit); one that worsens it fails here, not unseen.
Runtime about 25 s of CPU (EMPS and the tribometer; HSM150 adds about 40 s)."""

from __future__ import annotations

import json

import pytest

from benchmarks.bench_residual import FLOORS, foreign_figures, regressions


@pytest.fixture(scope="module")
def figures():
    return foreign_figures()


def test_every_figure_has_a_floor_and_none_is_worse(figures):
    floors = json.loads(FLOORS.read_text())["floors"]
    assert "EMPS validation force error (torque_rel_pct, %)" in figures
    assert "tribometer validation force error (force_rel_pct, %)" in figures
    # the second independent generator (tests/foreign, issue 39): Bouc-Wen, its own RK4 and noise
    assert {"Bouc-Wen tribometer validation force error (force_rel_pct, %)",
            "Bouc-Wen tribometer, level slope, validation force error (force_rel_pct, %)",
            "Bouc-Wen eccentric preload over 0.3 rev validation torque error (torque_rel_pct, %)",
            "Bouc-Wen pure delay validation torque error (torque_rel_pct, %)"} <= set(figures)
    # EMPS back at or under the 3.151 % of before the Stribeck grid changed (issue 39)
    assert figures["EMPS validation force error (torque_rel_pct, %)"]["value"] <= 3.151
    worse = regressions(figures, floors)
    assert not worse, "; ".join(worse)


def test_a_regression_of_the_size_of_issue_29_is_caught():
    """Issue 29's tribometer went from 4.66 % to 5.30 % (+14 %): caught; +2 % is within the margin; a figure
    without a floor is reported."""
    floors = {"tribometer": 4.66}
    assert len(regressions({"tribometer": {"value": 5.30}}, floors)) == 1
    assert regressions({"tribometer": {"value": 4.66 * 1.02}}, floors) == []
    assert regressions({"new figure": {"value": 1.0}}, floors) == ["new figure: no floor (the current value is 1)"]
