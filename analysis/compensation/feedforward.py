"""Model-based feed-forward along a reference, and the models it can use.

The feed-forward torque of a model with the equation of motion ``J*q'' + F(q, q', state) + K*q + c0 = tau``
(docs/model-file.md, analysis.models.families) is that equation evaluated on the reference:

    tau_ff[k] = J*a_ref[k] + F_k + K*q_ref[k] + c0

where F_k is the model's friction at sample k when its state (element deflections, bristle, GMS element
forces, hysteresis stack) is driven by the reference displacement q_ref from rest: the C engine's
``Plant.friction_path``, the same code that simulates the model. The current is
``i_ff = tau_ff/(k_t*ratio)`` (load-side N*m to motor A, the calibration's inverse), clipped to the current
limit; the clipped samples are counted.

Models (:func:`compensators`): ``none``; ``coulomb``: Fc*sgn(v) + b*v with Fc at the Maxwell-slip model's
break-away sum(W_i) + Fc and the same J, b, c0 (the fair Coulomb comparison: same break-away level);
``maxwell_slip``: the identified model file; and every family of a ``hilbench compare`` document.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hilbench.analysis.compensation.references import Reference
from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.models.families import substeps_for
from hilbench.analysis.models.model_file import READABLE as MODEL_SCHEMAS
from hilbench.analysis.models.model_file import check_name, check_plant, load_document, read_family, read_model
from hilbench.common.units import AXIS_UNITS as AXES
from hilbench.firmware_sim.engine.plant import Plant, PlantParameterError, PlantParams

COMPARE_SCHEMA = "hilbench.compare/1"


@dataclass
class Compensator:
    """A named feed-forward model: ``params`` in load units (N*m, rad; torque_constant 1), or None for
    no compensation."""

    name: str
    params: PlantParams | None
    source: str = ""


@dataclass
class FeedForward:
    """Feed-forward of one compensator along a reference: torque N*m (load), current A (motor, clipped),
    shape (n,) each, and the number of clipped samples."""

    torque: np.ndarray
    current: np.ndarray
    clipped: int


def feedforward_torque(params: PlantParams, ref: Reference) -> np.ndarray:
    """tau_ff = J*a_ref + F(q_ref) + K*q_ref - torque_offset (N*m), shape (n,); F from rest along q_ref."""
    try:
        friction = Plant(params, 1.0 / ref.fs, substeps_for(params, ref.fs)).friction_path(ref.position,
                                                                                           ref.velocity)
    except PlantParameterError as exc:
        raise AnalysisError(f"model cannot be simulated: {exc}") from None
    return params.inertia * ref.acceleration + friction + params.spring * ref.position - params.torque_offset


def feedforward(comp: Compensator, ref: Reference, torque_constant: float, ratio: float,
                current_limit: float) -> FeedForward:
    """Feed-forward current (A) of ``comp`` along ``ref``: tau_ff/(k_t*ratio) clipped to +-``current_limit``."""
    for name, value, unit in (("torque_constant", torque_constant, "N*m/A"), ("ratio", ratio, "1"),
                              ("current_limit", current_limit, "A")):
        if not (math.isfinite(value) and value > 0):
            raise AnalysisError(f"{name} must be finite and > 0 {unit}, got {value!r}")
    if comp.params is None:
        zero = np.zeros(ref.n)
        return FeedForward(zero, zero.copy(), 0)
    torque = feedforward_torque(comp.params, ref)
    current = torque / (torque_constant * ratio)
    clipped = int(np.count_nonzero(np.abs(current) > current_limit))
    return FeedForward(torque, np.clip(current, -current_limit, current_limit), clipped)


def coulomb_at_breakaway(params: PlantParams, name: str = "coulomb") -> Compensator:
    """Coulomb+viscous at the break-away level of ``params`` (sum W_i + Fc), same J, b, K and offset."""
    level = params.breakaway
    if params.lugre is not None or params.gms is not None or params.hysteresis is not None:
        raise AnalysisError("the Coulomb comparison is taken from a Maxwell-slip model (no LuGre/GMS/hysteresis)")
    return Compensator(name, PlantParams(inertia=params.inertia, spring=params.spring, viscous=params.viscous,
                                         coulomb=level, torque_offset=params.torque_offset),
                       f"Fc = {level:.4g} N*m (Maxwell-slip break-away)")


def _check_units(units: dict, axis: str, where: str) -> None:
    expected = AXES[axis]
    table = {"inertia": "inertia", "ms_stiffness": "stiffness", "ms_delta": "position", "viscous": "viscous",
             "coulomb": "torque", "offset": "torque"}
    for key, kind in table.items():
        if key in units and units[key] != expected[kind]:
            raise AnalysisError(f"{where}: {key} is in {units[key]}, not {expected[kind]} as a {axis} axis needs")


def load_compensators(path: str | Path, device_axis: str = "rotary") -> tuple[list[Compensator], dict]:
    """Compensators of a model file (``hilbench identify``: none, coulomb, maxwell_slip; a family file of
    ``hilbench compare``: none and that family) or a comparison
    (``hilbench compare``: none, coulomb from its Maxwell-slip row, and every family row). Refuses a model
    whose axis or units are not those of ``device_axis``. Returns the list and the document."""
    doc = load_document(path, "model or comparison file")
    schema = doc.get("schema")
    out = [Compensator("none", None, "no feed-forward")]
    if schema in MODEL_SCHEMAS and doc.get("family", "maxwell_slip") != "maxwell_slip":
        fam, doc = read_family(path)  # one family of `hilbench compare` (OUT/models/FAMILY.json)
        if fam.axis != device_axis:
            raise AnalysisError(f"{path}: the model is for a {fam.axis} axis; the device is {device_axis}")
        _check_units(fam.units, fam.axis, str(path))
        return out + [Compensator(fam.family, fam.plant, f"{path}")], doc
    if schema in MODEL_SCHEMAS:
        model, doc = read_model(path)
        if model.axis != device_axis:
            raise AnalysisError(f"{path}: the model is for a {model.axis} axis; the device is {device_axis}")
        _check_units(doc["parameters"].get("units", {}), model.axis, str(path))
        ms = model.plant_params()
        return out + [coulomb_at_breakaway(ms), Compensator("maxwell_slip", ms, f"{path}")], doc
    if schema == COMPARE_SCHEMA:
        axis = doc.get("axis")
        if axis != device_axis:
            raise AnalysisError(f"{path}: the comparison is for a {axis} axis; the device is {device_axis}")
        rows: dict[str, PlantParams] = {}
        if not isinstance(doc.get("rows", []), list):
            raise AnalysisError(f"{path}: rows must be a list")
        for i, row in enumerate(doc.get("rows", [])):
            if not isinstance(row, dict):
                raise AnalysisError(f"{path}: rows[{i}] must be an object")
            if row.get("plant") is None or row.get("fit") is None:
                continue
            # the row's name becomes part of run and plot file names: a plain identifier, once
            name = check_name(row.get("model"), f"{path}: rows[{i}].model")
            if name in rows:
                raise AnalysisError(f"{path}: two rows are named {name!r}")
            if not isinstance(row["fit"], dict) or not isinstance(row["fit"].get("units", {}), dict):
                raise AnalysisError(f"{path}: rows[{i}].fit must be an object with a units object")
            _check_units(row["fit"].get("units", {}), axis, f"{path} ({name})")
            check_plant(row["plant"], f"{path}: rows[{i}].plant")
            try:
                rows[name] = PlantParams.from_dict(row["plant"])
            except (PlantParameterError, TypeError, ValueError) as exc:
                raise AnalysisError(f"{path}: row {row.get('model')!r}: {exc}") from None
        if "maxwell_slip" not in rows:
            raise AnalysisError(f"{path}: the comparison has no maxwell_slip row (the Coulomb level comes from it)")
        out.append(coulomb_at_breakaway(rows["maxwell_slip"]))
        return out + [Compensator(name, p, f"{path}") for name, p in rows.items()], doc
    raise AnalysisError(f"{path}: not a hilbench model or comparison (schema {schema!r})")
