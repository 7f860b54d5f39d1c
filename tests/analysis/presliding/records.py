"""Presliding test records: a nested-reversal displacement path (a virgin ramp, then reversals of decreasing
amplitude, then one stroke past everything that wipes the memory out) and the force of an independent truth along
it (tests/truth/generator: exact stop operators for Maxwell-slip, a fine-step GMS element set)."""

from __future__ import annotations

import numpy as np

from hilbench.firmware_sim.engine.friction_models import dc_motor
from tests.truth.generator import Truth, _Friction, stop_operator_forces

#: turning points of the nested sequence, in units of the scale (the paper's Fig. 1 sequence, nested deeper)
SEQUENCE = (6.0, -4.0, 3.0, -2.0, 1.5, -1.0, 0.5, -0.25, 2.5, -5.0, 8.0)


def dc_elements() -> tuple[np.ndarray, np.ndarray]:
    """(k_i N*m/rad, W_i N*m) of the DC-motor preset (the truth for the done-when figures)."""
    p = dc_motor()
    return np.asarray(p.ms_stiffness), np.asarray(p.ms_slip)


def smooth_path(scale: float, samples_per_scale: int = 60, sequence=SEQUENCE) -> np.ndarray:
    """Cosine-shaped strokes between the turning points (rad or m), every turning point on a sample."""
    turns = [0.0] + [a * scale for a in sequence]
    parts = []
    for a, b in zip(turns[:-1], turns[1:], strict=True):
        m = int(abs(b - a) / scale * samples_per_scale) + 20
        parts.append(a + (b - a) * 0.5 * (1 - np.cos(np.pi * np.arange(m) / m)))
    return np.concatenate(parts + [[turns[-1]]])


def grid_path(step: float, sequence=(8, -6, 4, -2, 1, -1, 3, -7, 10)) -> np.ndarray:
    """A path on the grid of ``step`` (turning points in steps), the virgin ramp sampled at half steps: every
    value the Masing and wiping-out rules need lies on a sample, so the rules hold exactly."""
    turns = [0] + list(sequence)
    parts = [np.arange(0, 2 * turns[1]) * (step / 2)]
    for a, b in zip(turns[1:-1], turns[2:], strict=True):
        parts.append(np.arange(a, b, 1 if b > a else -1) * step)
    return np.concatenate(parts + [[turns[-1] * step]])


def gms_force(x: np.ndarray, breakaway: float, presliding: float, substeps: int = 20, stribeck_excess: float = 0.0,
              stribeck_velocity: float = 2.0) -> np.ndarray:
    """Force (N) of the truth generator's GMS element set along x (m), one sample per ms (slip relaxation at a rate
    fixed per sample). With a slip level that depends on speed (``stribeck_excess`` N over the Coulomb level,
    falling off over ``stribeck_velocity`` m/s) and a path whose speed differs between branches, it breaks Masing's
    rule and wiping-out; at one speed, or with a constant level, its elements stick and slip at the same forces as
    Maxwell-slip elements and the rules hold."""
    tr = Truth(family="gms", coulomb=breakaway, presliding=presliding, n_elements=20, viscous=0.0, gms_rate=2000.0,
               stribeck_excess=stribeck_excess, stribeck_velocity=stribeck_velocity)
    fr = _Friction(tr)
    z = np.zeros(tr.n_elements)
    out = np.empty(x.size)
    out[0] = 0.0
    h = 1e-3 / substeps
    for i in range(1, x.size):
        dx = (x[i] - x[i - 1]) / substeps
        for _ in range(substeps):
            f = fr.step(z, dx, dx / h, x[i], h)
        out[i] = f
    return out


def maxwell_force(x: np.ndarray, k: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Exact Maxwell-slip force along x (independent stop operators of tests/truth/generator)."""
    return stop_operator_forces(k, w, x)


#: turning points of a repeatable nested path (units of the scale): it ends where it began, after a stroke past every
#: other turning point, so from its second repeat on a Maxwell-slip state repeats exactly
REPEAT_SEQUENCE = (6.0, -4.0, 3.0, -2.0, 1.5, -1.0, 0.5, -0.25, 2.5, -5.0, 8.0, 0.0)


def repeated_path(scale: float, stroke: int, repeats: int) -> np.ndarray:
    """``repeats`` of the nested path :data:`REPEAT_SEQUENCE` (rad or m), cosine strokes of ``stroke`` samples each,
    as benchmarks/long_run_paper.py writes the long presliding record."""
    turns = np.array((0.0, *REPEAT_SEQUENCE)) * scale
    s = 0.5 * (1 - np.cos(np.pi * np.arange(stroke) / stroke))
    cycle = np.concatenate([a + (b - a) * s for a, b in zip(turns[:-1], turns[1:], strict=True)])
    return np.tile(cycle, repeats)


def repeated_force(x: np.ndarray, period: int, k: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Maxwell-slip force along a path of whole repeats of ``period`` samples: two repeats simulated, the second
    tiled (the state repeats from there on), so a long record costs no more than two repeats."""
    two = maxwell_force(x[: 2 * period], k, w)
    reps = -(-x.size // period)
    return np.concatenate([two[:period], *([two[period:]] * (reps - 1))])[: x.size]
