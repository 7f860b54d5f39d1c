"""The simulator's TOML configuration: device identity, buffer size, the plant with its injected effects and,
optionally, the drift of a motor that warms up and wears (``[drift]``, off when absent).

See ``firmware_sim/devices/default_sim.toml``. Bad files raise :class:`SimConfigError` with a one-line message.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from hilbench.drivers.protocol import SAMPLE_RATES
from hilbench.firmware_sim.engine.drift import (
    MAX_DISTANCE,
    MAX_TEMPERATURE,
    Drift,
    drift_keys,
    reachable_extremes,
    scaled_params,
)
from hilbench.firmware_sim.engine.friction_models import dc_motor, paper_system
from hilbench.firmware_sim.engine.plant import (
    MAX_ELEMENTS,
    PlantParameterError,
    PlantParams,
    stiffest_eigenvalue,
    validate,
)

IDENTITY_TEXT_BYTES = 255  # model and serial travel in IDENTITY as strings of at most 255 UTF-8 bytes
MAX_SUBSTEPS = 10_000  # RK4 sub-steps per sample; beyond it one sample costs more than a realtime tick

DEFAULT_PATH = Path(__file__).with_name("default_sim.toml")
PRESETS = {"dc_motor": dc_motor, "paper_system": paper_system}


class SimConfigError(ValueError):
    """A simulator configuration file that cannot be used."""


@dataclass(frozen=True)
class SimConfig:
    plant: PlantParams
    substeps: int = 0  # 0 = automatic (:func:`substeps_for`)
    model: str = "HB-SIM-1"
    serial: str = "SIM-0001"
    buffer_capacity: int = 8192
    drift: Drift | None = None   # None: no thermal model, no wear, no temperature sensor
    ambient: float = 23.0        # degC, the winding's temperature when the device starts
    drift_block: float = 0.05    # s between updates of the drifted friction parameters
    max_temperature: float = MAX_TEMPERATURE  # degC: the hottest winding the drift laws are checked at
    max_distance: float = MAX_DISTANCE        # rad: the farthest sliding distance they are checked at

    def reachable_plants(self) -> list[tuple[float, float, PlantParams]]:
        """(temperature degC, distance rad, plant) at the extremes of the drift laws over the range a device can
        reach (firmware_sim.engine.drift.reachable_extremes); [] without [drift]."""
        if self.drift is None:
            return []
        return [(t, s, scaled_params(self.plant, level, viscous)) for t, s, level, viscous in
                reachable_extremes(self.drift, self.ambient, self.max_temperature, self.max_distance)]

    def substeps_at(self, sample_rate: int) -> int:
        """RK4 sub-steps per sample at ``sample_rate``: as configured, else the fewest stable for the plant and
        for every plant the drift laws reach (a warm motor's viscous term or a worn contact's stiffness may be
        stiffer than the cold, new one)."""
        if self.substeps:
            return self.substeps
        dt = 1.0 / sample_rate
        return max(substeps_for(params, dt) for params in [self.plant, *(p for *_, p in self.reachable_plants())])

    def plant_for(self, current_limit: float, torque_constant: float, counts_per_rev: int) -> PlantParams:
        """The plant a CONFIG runs: the motor takes the host's declared calibration (torque constant,
        encoder counts/rev) as its nominal values, as a real drive's datasheet values would be; a deviation
        from them is an injected effect of this file (``torque_constant_error``), never a silent mismatch."""
        return self.plant.replace(current_limit=current_limit, torque_constant=torque_constant,
                                  counts_per_rev=int(counts_per_rev))


def substeps_for(params: PlantParams, dt: float) -> int:
    """Fewest RK4 sub-steps per sample that keep the stiffest mode stable: ceil(|lambda|*dt / 2.5); above
    MAX_SUBSTEPS (or for a non-finite mode) MAX_SUBSTEPS + 1, which validation then refuses."""
    from hilbench.firmware_sim.engine.plant import RK4_STABLE_RADIUS

    try:
        with np.errstate(all="ignore"):
            need = stiffest_eigenvalue(params) * dt / RK4_STABLE_RADIUS * (1 + 1e-12)
    except (ArithmeticError, ValueError, np.linalg.LinAlgError):  # a non-finite parameter: validation names it
        return MAX_SUBSTEPS + 1
    return max(1, math.ceil(need)) if need <= MAX_SUBSTEPS else MAX_SUBSTEPS + 1


def load_sim_config(path: str | Path | None = None, seed: int | None = None) -> SimConfig:
    """Read a simulator TOML file (the packaged default when ``path`` is None); ``seed`` overrides it."""
    path = Path(path) if path is not None else DEFAULT_PATH
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SimConfigError(f"cannot read simulator config {path}: {exc}") from exc
    return sim_config_from_dict(data, seed=seed, source=str(path))


def sim_config_from_dict(data: dict, seed: int | None = None, source: str = "config") -> SimConfig:
    unknown = sorted(set(data) - {"device", "plant", "drift"})
    if unknown:
        raise SimConfigError(f"{source}: unknown section(s) {', '.join(unknown)}")
    device = dict(data.get("device", {}))
    plant = dict(data.get("plant", {}))
    bad = sorted(set(device) - {"model", "serial", "buffer_capacity"})
    if bad:
        raise SimConfigError(f"{source}: unknown [device] key(s) {', '.join(bad)}")
    preset = plant.pop("preset", "dc_motor")
    elements = plant.pop("elements", 16)
    substeps = plant.pop("substeps", 0)
    declared = sorted({"torque_constant", "counts_per_rev"} & set(plant))
    if declared:
        raise SimConfigError(f"{source}: [plant] {', '.join(declared)} come from the host's CONFIG (its declared "
                             f"calibration); inject a deviation with torque_constant_error instead")
    if seed is not None:
        plant["seed"] = seed
    # sizes are checked against their bounds before anything is allocated
    if isinstance(elements, bool) or not isinstance(elements, int) or not 1 <= elements <= MAX_ELEMENTS:
        raise SimConfigError(f"{source}: [plant] elements must be a whole number in 1..{MAX_ELEMENTS} "
                             f"(the plant's limit), got {elements!r}")
    if isinstance(substeps, bool) or not isinstance(substeps, int) or not 0 <= substeps <= MAX_SUBSTEPS:
        raise SimConfigError(f"{source}: [plant] substeps must be a whole number in 0..{MAX_SUBSTEPS} "
                             f"(0 = automatic), got {substeps!r}")
    capacity = device.get("buffer_capacity", 8192)
    if isinstance(capacity, bool) or not isinstance(capacity, int) or not 256 <= capacity <= 2**20:
        raise SimConfigError(f"{source}: buffer_capacity must be a whole number in 256..1048576 samples, "
                             f"got {capacity!r}")
    for key in ("model", "serial"):
        text = device.get(key, "")
        if not isinstance(text, str) or len(text.encode("utf-8")) > IDENTITY_TEXT_BYTES:
            raise SimConfigError(f"{source}: [device] {key} must be a string of at most {IDENTITY_TEXT_BYTES} "
                                 f"UTF-8 bytes (the IDENTITY message's limit)")
    if preset == "none":
        values = plant
    elif preset in PRESETS:
        values = PRESETS[preset](int(elements)).to_dict()
        values.update(plant)
    else:
        raise SimConfigError(f"{source}: unknown plant preset {preset!r} (use {', '.join(PRESETS)} or none)")
    try:
        params = PlantParams.from_dict(values)
        dt = 1e-4  # validate at 10 kHz; the firmware re-validates at the configured rate
        validate(params, dt, int(substeps) or substeps_for(params, dt))
    except (PlantParameterError, TypeError) as exc:
        raise SimConfigError(f"{source}: bad [plant]: {exc}") from exc
    drift, extra = _drift(data.get("drift"), source)
    config = SimConfig(plant=params, substeps=int(substeps), model=str(device.get("model", "HB-SIM-1")),
                       serial=str(device.get("serial", "SIM-0001")), buffer_capacity=capacity,
                       drift=drift, ambient=extra["ambient"], drift_block=extra["block"],
                       max_temperature=extra["max_temperature"], max_distance=extra["max_distance"])
    _check_drift_range(config, source)
    return config


#: [drift] keys beyond the laws' constants (firmware_sim.engine.drift.Drift): the winding's temperature at start
#: (degC), the period of the friction updates (s), and the range the laws are checked over (degC, rad)
DRIFT_EXTRA = {"ambient": 23.0, "block": 0.05, "max_temperature": MAX_TEMPERATURE, "max_distance": MAX_DISTANCE}


def _check_drift_range(config: SimConfig, source: str) -> None:
    """Refuse, in one line naming the key, drift laws that leave what a motor can be anywhere in the range a device
    can reach before it starts (not at the first run that gets there): every extreme plant of that range must be
    valid and stable at every sample rate the device accepts."""
    drift = config.drift
    if drift is None:
        return
    try:
        extremes = reachable_extremes(drift, config.ambient, config.max_temperature, config.max_distance)
    except PlantParameterError as exc:
        raise SimConfigError(f"{source}: [drift] {exc}") from None
    for rate in SAMPLE_RATES:
        dt = 1.0 / rate
        try:
            validate(config.plant, dt, config.substeps or substeps_for(config.plant, dt))
        except PlantParameterError:
            continue  # the device refuses a CONFIG at this rate anyway (INVALID_CONFIG)
        substeps = config.substeps_at(rate)
        for temperature, distance, level, viscous in extremes:
            params = scaled_params(config.plant, level, viscous)
            try:  # non-finite parameters first, then stability at the sub-steps the device will use (at most 10 000)
                validate(params, dt, min(substeps, MAX_SUBSTEPS))
            except PlantParameterError as exc:
                why = str(exc)
                if why.startswith("unstable step") and substeps_for(params, dt) > MAX_SUBSTEPS:
                    why = (f"its stiffest mode ({stiffest_eigenvalue(params):.3g} 1/s) needs more than {MAX_SUBSTEPS} "
                           f"RK4 sub-steps per sample")
                raise SimConfigError(
                    f"{source}: [drift] {drift_keys(level, viscous, drift)}: at {temperature:.4g} degC and "
                    f"{distance:.4g} rad slid (friction level x{level:.3g}, viscous x{viscous:.3g}) the plant is "
                    f"refused at {rate} Hz: {why}") from None


def _drift(table, source: str) -> tuple[Drift | None, dict[str, float]]:
    """The [drift] table: the constants of :class:`Drift` plus the keys of :data:`DRIFT_EXTRA`."""
    if table is None:
        return None, dict(DRIFT_EXTRA)
    if not isinstance(table, dict):
        raise SimConfigError(f"{source}: [drift] must be a table")
    laws = {f.name for f in fields(Drift)}
    bad = sorted(set(table) - laws - set(DRIFT_EXTRA))
    if bad:
        raise SimConfigError(f"{source}: unknown [drift] key(s) {', '.join(bad)}; known: "
                             f"{', '.join(sorted(laws | set(DRIFT_EXTRA)))}")
    for key, value in table.items():
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise SimConfigError(f"{source}: [drift] {key} must be a number, got {value!r}")
    extra = {key: float(table.get(key, default)) for key, default in DRIFT_EXTRA.items()}
    if not 0.0 < extra["block"] <= 10.0:
        raise SimConfigError(f"{source}: [drift] block in (0, 10] s is required, got {extra['block']!r}")
    try:
        drift = Drift(**{k: float(v) for k, v in table.items() if k in laws})
    except PlantParameterError as exc:
        raise SimConfigError(f"{source}: [drift] {str(exc).removeprefix('drift ')}") from exc
    return drift, extra
