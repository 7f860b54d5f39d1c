"""Slow drift of the simulated device over a campaign: winding temperature and wear (off unless given).

A lab characterises friction over weeks; between the first run and the last the motor warms up and the
contact wears. This module drifts a :class:`~hilbench.firmware_sim.engine.plant.PlantParams` by two laws
(docs/campaign-analysis.md, "Drift physics"):

* Temperature T (degC), first-order thermal model of the winding to ambient, heated by the copper loss::

      C_th dT/dt = R_w i^2 - (T - T_amb)/R_th,   tau_th = R_th*C_th

  integrated exactly for a current held over each sample (zero-order hold), so a constant current gives
  T(t) = T_amb + R_th*R_w*i^2*(1 - exp(-t/tau_th)) to rounding.
* Friction level (Maxwell-slip stiffnesses, hence the break-away, and the Coulomb level)::

      L(T, s) = (1 + alpha*(T - T_ref)) * (1 + w*s + step*H(s - s_step))

  linear in temperature, and growing with the cumulative sliding distance s = integral |omega| dt (rad):
  a wear rate w (1/rad) and optionally a relative step at s_step (a sudden change of the contact).
* Viscous term, Reynolds' law of a lubricant's viscosity::

      b(T) = b_ref * exp(-beta*(T - T_ref))

Within a run the laws are applied block by block (``block`` seconds, 50 ms by default): the plant's state
is carried from block to block, only its friction parameters change, so the mechanics stay continuous.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hilbench.firmware_sim.engine.plant import Plant, PlantOutput, PlantParameterError, PlantParams

#: unit of the temperatures here (and of the run files' ``temperature`` channel)
TEMPERATURE_UNIT = "degC"


@dataclass(frozen=True)
class Drift:
    """The drift laws' constants (SI, temperatures in degC). All-zero coefficients leave the plant as given."""

    winding_resistance: float = 1.0       # R_w, ohm
    thermal_resistance: float = 2.0       # R_th, K/W (winding to ambient)
    thermal_time_constant: float = 600.0  # tau_th, s
    reference_temperature: float = 23.0   # T_ref, degC: the plant's parameters hold at T_ref, s = 0
    level_temperature_coefficient: float = 0.0    # alpha, 1/K
    viscous_temperature_coefficient: float = 0.0  # beta, 1/K
    wear_rate: float = 0.0                # w, relative level increase per rad slid
    wear_step: float = 0.0                # relative level step at wear_step_distance
    wear_step_distance: float = math.inf  # s_step, rad

    def __post_init__(self) -> None:
        for name in ("winding_resistance", "thermal_resistance", "thermal_time_constant"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise PlantParameterError(f"drift {name} must be finite and > 0, got {value}")
        for name in ("reference_temperature", "level_temperature_coefficient", "viscous_temperature_coefficient",
                     "wear_rate", "wear_step"):
            if not math.isfinite(getattr(self, name)):
                raise PlantParameterError(f"drift {name} must be finite, got {getattr(self, name)}")
        if self.wear_rate < 0 or self.wear_step <= -1:
            raise PlantParameterError("drift wear_rate must be >= 0 and wear_step > -1 (the level stays positive)")
        if not self.wear_step_distance >= 0:
            raise PlantParameterError(f"drift wear_step_distance must be >= 0, got {self.wear_step_distance}")

    def level_factor(self, temperature: float, distance: float) -> float:
        """L(T, s): the friction level relative to the plant's parameters."""
        thermal = 1.0 + self.level_temperature_coefficient * (temperature - self.reference_temperature)
        wear = 1.0 + self.wear_rate * distance + (self.wear_step if distance >= self.wear_step_distance else 0.0)
        if thermal <= 0:
            raise PlantParameterError(f"friction level law gives {thermal:.3g} <= 0 at {temperature:.4g} degC")
        return thermal * wear

    def viscous_factor(self, temperature: float) -> float:
        """b(T)/b_ref."""
        return math.exp(-self.viscous_temperature_coefficient * (temperature - self.reference_temperature))


@dataclass
class DriftState:
    """Where the device is on the drift laws: winding temperature and ambient (degC), distance slid (rad)."""

    temperature: float
    ambient: float
    distance: float = 0.0


def drifted_params(params: PlantParams, drift: Drift, state: DriftState) -> PlantParams:
    """``params`` with the friction level and viscous term of ``state`` (Maxwell-slip slip displacements kept)."""
    level = drift.level_factor(state.temperature, state.distance)
    visc = drift.viscous_factor(state.temperature)
    return replace(
        params,
        ms_stiffness=tuple(level * k for k in params.ms_stiffness),
        ms_slip=tuple(level * w for w in params.ms_slip),  # slip forces W_i = k_i*Delta_i scale with k_i
        coulomb=level * params.coulomb,
        coulomb_neg=None if params.coulomb_neg is None else level * params.coulomb_neg,
        static=None if params.static is None else level * params.static,
        viscous=visc * params.viscous,
        viscous_neg=None if params.viscous_neg is None else visc * params.viscous_neg,
    )


def heat(drift: Drift, state: DriftState, current: np.ndarray, dt: float) -> np.ndarray:
    """Advance ``state.temperature`` over ``current`` (A, one value held per sample of ``dt`` s); returns the
    temperature at the start of every sample (degC), shape of ``current``."""
    i = np.asarray(current, dtype=float)
    a = math.exp(-dt / drift.thermal_time_constant)
    # T_k+1 = T_amb + a*(T_k - T_amb) + (1 - a)*R_th*R_w*i_k^2: a first-order recursion, solved in closed form
    # as a discounted sum so that a long run costs numpy, not a Python loop
    gain = (1 - a) * drift.thermal_resistance * drift.winding_resistance * i ** 2
    powers = a ** np.arange(i.size + 1, dtype=float)
    excess0 = state.temperature - state.ambient
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        if i.size and powers[-1] > 1e-250:
            sums = np.concatenate([[0.0], np.cumsum(gain / powers[1:])]) * powers
        else:  # a very long record: the plain recursion (no underflowing powers)
            sums = np.empty(i.size + 1)
            sums[0] = 0.0
            for k in range(i.size):
                sums[k + 1] = a * sums[k] + gain[k]
    excess = excess0 * powers + sums
    state.temperature = float(state.ambient + excess[-1])
    return state.ambient + excess[:-1]


def rest(drift: Drift, state: DriftState, duration: float) -> None:
    """Let the winding cool towards ambient for ``duration`` s with no current."""
    if duration < 0:
        raise PlantParameterError(f"rest duration must be >= 0, got {duration}")
    state.temperature = state.ambient + (state.temperature - state.ambient) * math.exp(
        -duration / drift.thermal_time_constant)


def simulate_drifting(params: PlantParams, u: np.ndarray, dt: float, drift: Drift, state: DriftState, *,
                      substeps: int = 1, mode: str = "current", block: float = 0.05
                      ) -> tuple[PlantOutput, np.ndarray]:
    """Simulate ``u`` from rest with the drift laws applied every ``block`` s; advances ``state``.

    Returns the plant's outputs and the winding temperature at every sample (degC). The current that heats
    the winding is the plant's actual motor current."""
    u = np.ascontiguousarray(u, dtype=float)
    if u.ndim != 1:
        raise PlantParameterError(f"input must be 1-D, got shape {u.shape}")
    n_block = max(1, int(round(block / dt)))
    parts, temperatures = [], []
    saved: bytes | None = None
    for start in range(0, u.size, n_block):
        plant = Plant(drifted_params(params, drift, state), dt, substeps, mode)
        if saved is not None:
            plant.set_state(saved)
        out = plant.run(u[start:start + n_block])
        saved = plant.get_state()
        temperatures.append(heat(drift, state, out.current_meas, dt))
        # out.theta is each sample's start; the block's last sample ends at the plant's state
        state.distance += float(np.sum(np.abs(np.diff(np.concatenate([out.theta, [plant.theta]])))))
        parts.append(out)
    return PlantOutput.concatenate(parts), np.concatenate(temperatures) if temperatures else np.empty(0)
