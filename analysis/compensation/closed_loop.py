"""Offline prediction: the device's position loop plus feed-forward around the C plant, sample by sample.

This is not the device: the device runs its own loop (firmware/core/hb_device.c, docs/protocol.md "Position
mode"). It is the same control law on the same engine, so a lab can see what a compensator should do before a
run, and the tests can check the metrics and the feed-forward in closed loop without a device. Per sample k
(q[k] measured at t_k before the input acts, docs/architecture.md; quantised to the encoder's ``resolution``
when it is > 0):

    e[k] = q_ref[k] - q[k]                                          (rad)
    D[k] = a*D[k-1] + (1 - a)*(e[k] - e[k-1])*fs,  a = exp(-2*pi*d_cutoff/fs)   (D[0] = 0)
    I'   = clip(I[k-1] + ki*e[k]/fs, +-i_limit)                       (A)
    i[k] = clip(kp*e[k] + kd*D[k] + I' + i_ff[k], +-current_limit)    (A)
    I[k] = I' unless the output saturates with the error driving it further (anti-windup), then I[k-1]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.models.families import substeps_for
from hilbench.firmware_sim.engine.plant import Plant, PlantParams


@dataclass(frozen=True)
class PositionGains:
    """PID gains at the motor shaft: kp A/rad, ki A/(rad*s), kd A*s/rad, i_limit A (integrator clamp),
    d_cutoff Hz (derivative filter; 0 = unfiltered). Defaults: the device's (drivers POSITION_GAINS)."""

    kp: float = 3000.0
    ki: float = 300000.0
    kd: float = 5.0
    i_limit: float = 5.0
    d_cutoff: float = 300.0

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd", "i_limit", "d_cutoff"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise AnalysisError(f"position gain {name} must be finite and >= 0, got {value!r}")


@dataclass
class TrackingRun:
    position: np.ndarray   # rad, measured at t_k
    current: np.ndarray    # A, commanded over [t_k, t_k+1)


def simulate_tracking(params: PlantParams, reference: np.ndarray, feedforward: np.ndarray, fs: float,
                      gains: PositionGains, current_limit: float, resolution: float = 0.0) -> TrackingRun:
    """Run the loop above on ``params`` (input in A through its torque constant) from rest at 0 rad;
    ``reference`` rad and ``feedforward`` A, shape (n,); ``resolution`` rad per encoder count (0: exact)."""
    ref = np.asarray(reference, float)
    ff = np.asarray(feedforward, float)
    if ref.shape != ff.shape or ref.ndim != 1:
        raise AnalysisError(f"reference and feed-forward must be 1-D of equal length, got {ref.shape}, {ff.shape}")
    plant = Plant(params, 1.0 / fs, substeps_for(params, fs))
    lsb = float(resolution)
    alpha = math.exp(-2 * math.pi * gains.d_cutoff / fs) if gains.d_cutoff > 0 else 0.0
    q = np.empty(ref.size)
    u = np.empty(ref.size)
    integ, deriv, e_prev = 0.0, 0.0, None
    one = np.zeros(1)
    for k in range(ref.size):
        q[k] = round(plant.theta / lsb) * lsb if lsb else plant.theta
        e = ref[k] - q[k]
        deriv = alpha * deriv + (1 - alpha) * ((e - e_prev) * fs if e_prev is not None else 0.0)
        e_prev = e
        trial = min(max(integ + gains.ki * e / fs, -gains.i_limit), gains.i_limit)
        cmd = gains.kp * e + gains.kd * deriv + trial + ff[k]
        if (cmd > current_limit and e > 0) or (cmd < -current_limit and e < 0):
            cmd = gains.kp * e + gains.kd * deriv + integ + ff[k]
        else:
            integ = trial
        u[k] = one[0] = min(max(cmd, -current_limit), current_limit)
        plant.run(one)
    return TrackingRun(q, u)
