"""What a record can identify (issue 29): an element wider than every travel is a spring the start model must hold,
and a Stribeck curve needs the record to slide past it.

- A training record that hardly slides (the default bench's identification run of seed 3 moved 1.6 mrad) leaves its
  never-slipping elements as a linear spring; the threshold grid ended at half the largest travel, so the start
  model could not hold it and the loop took it for an offset drift. Oracle: a pure spring plant
  tau = J*theta'' + b*theta' + K*(theta - theta_0), whose stiffness the start model must recover.
- A Stribeck velocity at the top of the record's speeds is a curvature over the whole speed range: on clean Dahl
  data over a 4 rad stroke it corrected the start model's biased viscous slope and was added (11 % held-out gain).
"""

from __future__ import annotations

import numpy as np
import pytest

from hilbench.analysis.identification.regressors import threshold_grid
from hilbench.analysis.residual import LoopOptions, prepare_run, residual_loop
from hilbench.analysis.residual.candidates import REGISTRY, stribeck_top
from hilbench.analysis.residual.selection import with_spring_element

J, B, K = 0.0022, 0.004, 300.0  # kg*m^2, N*m*s/rad, N*m/rad
FS = 1000.0
NOISE = 2e-4  # N*m rms, white (the spring torque is about 0.1 N*m peak)


def _spring_run(seed: int, amplitude: float = 3e-4):
    """A smooth small motion (rad) of a spring-mass-damper and the torque that drives it exactly."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(10 * FS)) / FS
    f = rng.uniform(0.3, 8.0, 12)
    ph = rng.uniform(0, 2 * np.pi, 12)
    a = amplitude / np.sqrt(12) / (1 + f)
    w = 2 * np.pi * f
    x = (a * np.sin(np.outer(t, w) + ph)).sum(1)
    v = (a * w * np.cos(np.outer(t, w) + ph)).sum(1)
    acc = -(a * w**2 * np.sin(np.outer(t, w) + ph)).sum(1)
    tau = J * acc + B * v + K * (x - x[0]) + NOISE * rng.standard_normal(t.size)
    return prepare_run(x, tau, FS, name=f"spring-{seed}", timing="instant")


def test_a_record_that_never_slips_is_held_by_a_spring_element():
    train, valid = _spring_run(1), _spring_run(2)
    grid = threshold_grid(train.position, 40)
    th = with_spring_element(grid, [train])
    reach = float(np.max(np.abs(train.position - train.position[0])))
    assert th.size == grid.size + 1 and th[-1] == reach > grid[-1]
    res = residual_loop(train, valid, start=("inertia", "maxwell_slip", "viscous"),
                        options=LoopOptions(sim_window=None))
    ms = res.model_before["maxwell_slip"]["parameters"]
    # the widest element never slips: its stiffness is the spring's (the narrower ones slip and stay near zero;
    # J and b are barely excited by a 0.3 mrad motion and are not the oracle here)
    assert ms["ms_delta"][-1] == pytest.approx(reach)
    assert ms["ms_stiffness"][-1] == pytest.approx(K, rel=0.02)
    assert res.names_added == [] and not res.unexplained
    # without the spring element: 66 % validation error, J 20x too large, and the residual's mean flagged
    assert res.error_before["validation"]["torque_rel_pct"] < 1.0


def test_a_record_that_slides_keeps_its_grid():
    """Over several revolutions every presliding element slips: the start model's residual does not correlate with
    position, and the loop keeps the plain grid (a spring element there would be a load, not friction)."""
    from tests.truth.generator import Truth
    from tests.truth.matrix import START, prepared, record

    run = prepared(record(Truth(family="maxwell"), 1), "maxwell-1")
    grid = threshold_grid(run.position, 40)
    reach = float(np.max(np.abs(run.position - run.position[0])))
    assert with_spring_element(grid, [run])[-1] == reach > grid[-1]  # what the loop would add
    wide = np.geomspace(grid[0], reach, 40)  # a grid whose top already reaches the excursion is left alone
    assert np.array_equal(with_spring_element(wide, [run]), wide)
    res = residual_loop(run, None, start=START, options=LoopOptions(sim_window=None, candidates=()))
    assert not res.diagnostics_before["position"].significant
    assert max(res.model_before["maxwell_slip"]["parameters"]["ms_delta"]) <= grid[-1]


def test_every_stribeck_velocity_leaves_a_tenth_of_the_record_past_twice_it():
    from tests.truth.matrix import CASES, prepared, record

    run = prepared(record(CASES["clean-stroke4-dahl"][0], 1), "dahl-1")
    speed = np.abs(run.velocity_fast)
    settings = REGISTRY["stribeck"].settings([run], {})
    top = max(s["v_s"] for s in settings)
    assert top == pytest.approx(stribeck_top(speed))
    assert np.mean(speed >= 2 * top) >= 0.1 - 1e-3
    assert top < np.percentile(speed, 90)  # the old grid's top, 5.09 rad/s here, where the spurious curve sat


def test_clean_dahl_over_a_stroke_adds_no_stribeck_curve():
    """clean-stroke4-dahl seed 1 added stribeck (v_s 5.09 rad/s, the grid's top) before the identifiability rule."""
    from tests.truth.matrix import run_case

    out = run_case("clean-stroke4-dahl", 1)
    assert out.added == ()
