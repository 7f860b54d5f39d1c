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

from hilbench.common.physical_bounds import ABSOLUTE_ZERO_DEGC, WINDING_TEMPERATURE_MAX_DEGC, temperature_possible
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
    return scaled_params(params, drift.level_factor(state.temperature, state.distance),
                         drift.viscous_factor(state.temperature))


#: Defaults of the range the laws are checked over (docs/campaign-analysis.md, "Drift physics"): the hottest the
#: winding is taken to get (degC; class H insulation is rated 180 degC) and the farthest it slides (rad).
MAX_TEMPERATURE = 180.0
MAX_DISTANCE = 1e6


def reachable_extremes(drift: Drift, ambient: float, max_temperature: float = MAX_TEMPERATURE,
                       max_distance: float = MAX_DISTANCE) -> list[tuple[float, float, float, float]]:
    """``(temperature degC, distance rad, L, b/b_ref)`` at the states where the laws take their extreme values over
    every state a device can reach: the winding between ``ambient`` (it starts there and only cools towards it)
    and ``max_temperature``, the distance slid between 0 and ``max_distance``. L is linear in T and monotone in s
    between the wear step's two sides, b/b_ref monotone in T, so these corners bound both.

    Raises :class:`PlantParameterError`, naming the [drift] key, for a value a motor cannot have: an ambient at or
    below absolute zero or not below ``max_temperature``, a ``max_temperature`` at which copper has melted, a
    friction level that reaches zero or a factor that is not finite."""
    for key, value in (("ambient", ambient), ("reference_temperature", drift.reference_temperature)):
        if not temperature_possible(value):
            raise PlantParameterError(f"{key} = {value!r} degC is not a temperature a winding has (it must lie "
                                      f"above absolute zero, {ABSOLUTE_ZERO_DEGC} degC, and below "
                                      f"{WINDING_TEMPERATURE_MAX_DEGC:g} degC, where copper melts)")
    if not (math.isfinite(max_temperature) and ambient < max_temperature < WINDING_TEMPERATURE_MAX_DEGC):
        raise PlantParameterError(f"max_temperature = {max_temperature!r} degC must lie above ambient ({ambient:g} "
                                  f"degC) and below {WINDING_TEMPERATURE_MAX_DEGC:g} degC, where copper melts")
    if not (math.isfinite(max_distance) and max_distance >= 0):
        raise PlantParameterError(f"max_distance = {max_distance!r} rad must be finite and >= 0")
    distances = {0.0, max_distance} | ({math.nextafter(drift.wear_step_distance, 0.0), drift.wear_step_distance}
                                       if drift.wear_step_distance <= max_distance else set())
    out = []
    for temperature in (ambient, max_temperature):
        thermal = 1.0 + drift.level_temperature_coefficient * (temperature - drift.reference_temperature)
        if not thermal > 0:
            raise PlantParameterError(
                f"level_temperature_coefficient = {drift.level_temperature_coefficient!r} 1/K makes the friction "
                f"level 1 + alpha*(T - T_ref) = {thermal:.3g} <= 0 at {temperature:.4g} degC, within the winding's "
                f"range {ambient:g}..{max_temperature:g} degC")
        with np.errstate(over="ignore"):
            viscous = float(np.exp(-drift.viscous_temperature_coefficient
                                   * (temperature - drift.reference_temperature)))
        if not (math.isfinite(viscous) and viscous > 0):
            raise PlantParameterError(
                f"viscous_temperature_coefficient = {drift.viscous_temperature_coefficient!r} 1/K makes the viscous "
                f"factor exp(-beta*(T - T_ref)) = {viscous:.3g} at {temperature:.4g} degC, within the winding's range "
                f"{ambient:g}..{max_temperature:g} degC")
        for distance in sorted(distances):
            level = drift.level_factor(temperature, distance)
            if not (math.isfinite(level) and level > 0):
                raise PlantParameterError(f"wear_rate = {drift.wear_rate!r} 1/rad makes the friction level {level:.3g} "
                                          f"after {distance:.4g} rad slid (max_distance {max_distance:g} rad)")
            out.append((temperature, distance, level, viscous))
    return out


def drift_keys(level: float, viscous: float, drift: Drift) -> str:
    """The [drift] keys, with their values, that moved the plant to friction level ``level`` and viscous factor
    ``viscous`` (for a one-line refusal), e.g. ``viscous_temperature_coefficient = -1.0``."""
    keys = []
    if level != 1.0:
        keys += [k for k in ("level_temperature_coefficient", "wear_rate", "wear_step") if getattr(drift, k)]
    if viscous != 1.0:
        keys.append("viscous_temperature_coefficient")
    return ", ".join(f"{k} = {getattr(drift, k)!r}" for k in keys)


def scaled_params(params: PlantParams, level: float, viscous: float) -> PlantParams:
    """``params`` at friction level ``level`` and viscous factor ``viscous`` (what :func:`drifted_params` does)."""
    return replace(
        params,
        ms_stiffness=tuple(level * k for k in params.ms_stiffness),
        ms_slip=tuple(level * w for w in params.ms_slip),  # slip forces W_i = k_i*Delta_i scale with k_i
        coulomb=level * params.coulomb,
        coulomb_neg=None if params.coulomb_neg is None else level * params.coulomb_neg,
        static=None if params.static is None else level * params.static,
        viscous=viscous * params.viscous,
        viscous_neg=None if params.viscous_neg is None else viscous * params.viscous_neg,
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
