"""Simulating models with the one C engine (``firmware_sim.engine.plant``).

analysis simulates identified and equivalent models with the same engine the simulated device runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hilbench.firmware_sim.engine.friction_models import dc_motor, paper_system
from hilbench.firmware_sim.engine.plant import PlantOutput, PlantParams, simulate

__all__ = ["ChirpRun", "PlantParams", "chirp_force", "dc_motor", "paper_system", "simulate", "simulate_chirp"]


def chirp_force(t: np.ndarray, amplitude: float, rate: float = 0.1) -> np.ndarray:
    """F(t) = G*sin(pi*a*t^2); instantaneous frequency a*t Hz (science.md §4: a = 0.1 Hz/s)."""
    return amplitude * np.sin(np.pi * rate * np.asarray(t, float) ** 2)


@dataclass
class ChirpRun:
    t: np.ndarray       # s
    force: np.ndarray   # input force/torque held over each sample, N (or N*m)
    out: PlantOutput


def simulate_chirp(params: PlantParams, amplitude: float, duration: float = 20.0, fs: float = 1000.0,
                   rate: float = 0.1, substeps: int = 4) -> ChirpRun:
    """Simulate ``params`` under the chirp G*sin(pi*a*t^2) for ``duration`` s sampled at ``fs`` Hz.

    The input is a force (torque_constant = 1 in the paper's system), held over each sample.
    """
    t = np.arange(int(round(duration * fs))) / fs
    force = chirp_force(t, amplitude, rate)
    current = force / params.torque_constant
    return ChirpRun(t=t, force=force, out=simulate(params, current, 1.0 / fs, substeps=substeps))
