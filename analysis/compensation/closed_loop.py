"""Offline prediction: a position PID plus feed-forward around the C plant, sample by sample.

This is not the device: the device runs its own position loop (docs/protocol.md, position mode). It is the
same control law on the same engine, so a lab can see what a compensator should do before a run, and the
tests can check the metrics and the feed-forward in closed loop without a device. The law, per sample k
(measured q[k] at t_k before the input acts, docs/architecture.md):

    e[k] = q_ref[k] - q[k]                      (rad)
    I[k] = clip(I[k-1] + ki*e[k]/fs, +-i_limit)   (A)
    i[k] = clip(kp*e[k] + I[k] + kd*(e[k] - e[k-1])*fs + i_ff[k], +-current_limit)   (A)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.models.families import substeps_for
from hilbench.firmware_sim.plant import Plant, PlantParams


@dataclass(frozen=True)
class PositionGains:
    """PID gains: kp A/rad, ki A/(rad*s), kd A*s/rad; i_limit A (integrator clamp)."""

    kp: float = 300.0
    ki: float = 3000.0
    kd: float = 3.0
    i_limit: float = 5.0

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd", "i_limit"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise AnalysisError(f"position gain {name} must be finite and >= 0, got {value!r}")


@dataclass
class TrackingRun:
    position: np.ndarray   # rad, measured at t_k
    current: np.ndarray    # A, commanded over [t_k, t_k+1)


def simulate_tracking(params: PlantParams, reference: np.ndarray, feedforward: np.ndarray, fs: float,
                      gains: PositionGains, current_limit: float) -> TrackingRun:
    """Run the loop above on ``params`` (input in A through its torque constant) from rest at 0 rad."""
    ref = np.asarray(reference, float)
    ff = np.asarray(feedforward, float)
    if ref.shape != ff.shape or ref.ndim != 1:
        raise AnalysisError(f"reference and feed-forward must be 1-D of equal length, got {ref.shape}, {ff.shape}")
    plant = Plant(params, 1.0 / fs, substeps_for(params, fs))
    q = np.empty(ref.size)
    u = np.empty(ref.size)
    integ, e_prev = 0.0, 0.0
    one = np.zeros(1)
    for k in range(ref.size):
        q[k] = plant.theta
        e = ref[k] - q[k]
        integ = min(max(integ + gains.ki * e / fs, -gains.i_limit), gains.i_limit)
        cmd = gains.kp * e + integ + gains.kd * (e - e_prev) * fs + ff[k]
        u[k] = one[0] = min(max(cmd, -current_limit), current_limit)
        e_prev = e
        plant.run(one)
    return TrackingRun(q, u)
