"""Edge-pinned points against an independent truth (tests/truth: exact stop operators) on a path that a position
loop pins at count edges: the position is then known exactly where the count changes."""

from __future__ import annotations

import numpy as np
import pytest

from hilbench.analysis.presliding.analyse import analyse, is_quantised
from hilbench.analysis.presliding.edges import edge_points
from tests.analysis.presliding.records import dc_elements
from tests.truth.generator import stop_operator_forces

STEP = 2 * np.pi / 65536  # rad, one count at 2^16 counts/rev
DITHER = 0.003  # steps: the pinned contact's excursion across the edge


def pinned_path(turns=(20, -15, 10), transit: int = 12, dwell: int = 40, start: float = 0.0,
                wobble: float | None = None) -> np.ndarray:
    """rad: from rest at ``start`` (steps from the rest count's centre), count edge by count edge to each turning
    edge (k + 1/2 steps). At every edge the path dwells, crossing it back and forth by DITHER steps as a position
    loop on the encoder does. ``wobble`` (an edge, in steps): there the path also runs 0.4 steps on into the next
    count, holds 60 samples and comes back to dwell at the edge again, as sliding dither does."""
    x, parts = start * STEP, [np.full(50, start * STEP)]
    for turn in turns:
        sign = 1 if turn > 0 else -1
        here = round(x / STEP - 0.5 * sign) if x else 0  # the count the path is in
        edges = np.arange(here, turn + sign, sign) + 0.5 * sign
        for b in edges:
            target = b * STEP
            parts.append(np.linspace(x, target, transit + 1)[1:])
            parts.append(target + sign * DITHER * STEP * np.where(np.arange(dwell) % 8 < 4, 1.0, -1.0))
            x = target
            if wobble is not None and b == wobble:
                wobble = None
                parts += [np.linspace(x, x + 0.4 * STEP, transit + 1)[1:], np.full(60, x + 0.4 * STEP),
                          np.linspace(x + 0.4 * STEP, x, transit + 1)[1:],
                          target + DITHER * STEP * np.where(np.arange(dwell) % 8 < 4, 1.0, -1.0)]
    return np.concatenate(parts)


def record(seed: int = 1, noise: float = 4e-4):
    k, w = dc_elements()
    theta = pinned_path()
    force = stop_operator_forces(k, w, theta) + np.random.default_rng(seed).normal(0, noise, theta.size)
    counts = np.floor(theta / STEP + 0.5)
    return theta, counts * STEP, force, k, w


def test_edge_points_sit_exactly_on_count_edges_with_the_truth_force():
    theta, x, force, k, w = record()
    e = edge_points(x, force, STEP)
    assert e.size > 60
    halves = e.x[1:] / STEP - 0.5
    assert np.max(np.abs(halves - np.round(halves))) < 1e-9  # every dwell on an edge (k + 1/2 steps)
    truth = stop_operator_forces(k, w, e.x[:22])[1:]  # from rest to the virgin edges 0.5 .. 20.5 steps
    # the dither's minor loops (3e-3 steps) and 4e-4 N*m noise over ~40 samples: measured within 0.14 % of sum W
    assert np.max(np.abs(e.force[1:22] - e.force[0] - truth)) / w.sum() < 2e-3
    assert is_quantised(x, STEP) and not is_quantised(theta, STEP)


def test_the_edge_pinned_virgin_curve_beats_count_centres():
    """The truth's virgin curve against the identified one over the ramp. Measured: edge-pinned 0.85 % of sum W
    (what remains is the bend inside the first half step, where no edge is), at count centres 4.0 %."""
    theta, x, force, k, w = record()
    res = analyse(np.arange(x.size) / 1e4, x, force, 1e4, counts_per_rev=65536, replicates=2)
    assert res.edge_fit is not None, res.edge_error
    s = np.linspace(0, 20.5 * STEP, 400)
    truth = np.minimum.outer(s, w / k) @ k
    edge = np.sqrt(np.mean((res.edge_fit.model.virgin_curve(s) - truth) ** 2)) / w.sum()
    centres = np.sqrt(np.mean((res.fit.model.virgin_curve(s) - truth) ** 2)) / w.sum()
    assert edge < 0.012
    assert edge < 0.5 * centres


def test_sum_k_from_the_edge_points_finds_the_relaxed_position_and_skips_a_minor_loop():
    """The DC polygon along a pinned path whose relaxed contact sits 0.3 steps off its count's centre, with a
    wobble on the ramp (past edge 12.5 and back: a minor loop). analyse() fits the ramp and the first branch with
    x0 free, leaving out the wobble's points (only the monotone path has Masing's closed form): sum(k) within
    2 % of the truth's (measured -0.9 %; -2.0 % with the wobble in), x0 within 0.05 steps (measured 0.304), p free.
    Forces exact but for 0.4 mN*m noise."""
    k, w = dc_elements()
    theta = pinned_path(start=0.3, wobble=12.5)
    force = stop_operator_forces(k, w, theta - theta[0]) + np.random.default_rng(4).normal(0, 4e-4, theta.size)
    x = np.floor(theta / STEP + 0.5) * STEP
    res = analyse(np.arange(x.size) / 1000.0, x, force, 1000.0, counts_per_rev=65536, replicates=2)
    fit = res.edge_rolling
    assert fit is not None and fit.exponent_free and fit.origin is not None
    assert fit.quantities(0.9)["initial_stiffness"] == pytest.approx(k.sum(), rel=0.02)
    assert fit.origin / STEP == pytest.approx(0.3, abs=0.05)
    # rest, 20 edges 0.5..19.5, the turn at 20.5, 36 edges 19.5..-15.5; the turn's own force is left out, and
    # the wobble's two points (the excursion and the dwell back at 12.5) too
    assert fit.samples == 1 + 20 + 36
    print(f"sum(k) {fit.quantities(0.9)['initial_stiffness'] / k.sum() - 1:+.4f}, x0 {fit.origin / STEP:+.3f} steps")


def test_a_short_record_keeps_its_analysis_when_the_edge_nnls_has_too_few_points():
    """Ramp to 12.5 steps and back to -8.5, the record ending on the branch: 35 edge points, fewer than the NNLS
    takes. The analysis used to stop there; now the edge NNLS says why it is missing and the edge-point sum(k) is
    still made from the ramp and the branch to the record's end (measured +2.7 %, 5 % allowed on a 12-count ramp)."""
    k, w = dc_elements()
    theta = pinned_path(turns=(12, -8))
    force = stop_operator_forces(k, w, theta) + np.random.default_rng(5).normal(0, 4e-4, theta.size)
    x = np.floor(theta / STEP + 0.5) * STEP
    res = analyse(np.arange(x.size) / 1000.0, x, force, 1000.0, counts_per_rev=65536, replicates=2)
    assert res.edge_fit is None and "NNLS on the edge points" in res.edge_error
    assert res.edge_rolling is not None and res.edge_rolling.origin is not None
    assert res.edge_rolling.quantities(0.9)["initial_stiffness"] == pytest.approx(k.sum(), rel=0.05)
