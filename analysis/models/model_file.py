"""The model file: JSON with the parameters, their standard errors, the data, settings and figures.

Schema: docs/model-file.md (``"schema": "hilbench.friction-model/2"``; version 1 files are still read). Version 2
adds ``family``: ``maxwell_slip`` (the file of ``hilbench identify``, laid out as in version 1) or any family of
:mod:`analysis.models.families` (written by ``hilbench compare``: the family's parameters, their standard
errors and units, and the plant). NaN (a standard error that does not exist, e.g. a parameter at its bound) is
written as null.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.models.friction_model import FrictionModel
from hilbench.common.units import AXIS_UNITS as AXES

SCHEMA = "hilbench.friction-model/2"
READABLE = ("hilbench.friction-model/1", SCHEMA)
#: Largest model or comparison file read, bytes. A model of 1024 elements with its standard errors is ~60 KB and
#: a comparison of every family ~100 KB; the size is checked before the file is read (a 74 MB file took 1.4 GB
#: and 10.8 s to parse before its element count was refused).
MAX_MODEL_BYTES = 8 * 2**20
#: Largest magnitude of a model parameter, SI (kg*m^2, N*m/rad, rad, N*m, ...): no bench has a parameter near
#: it, and a value like 1e300 overflows the feed-forward (J*q'' = inf) instead of being refused.
MAX_PARAMETER = 1e12
#: A name taken from a file (a family, a comparison row) becomes part of output file names: plain identifiers only.
NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,63}$")


def _clean(value):
    """JSON-safe copy: arrays to lists, NaN/inf to None."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        v = float(value)
        return v if math.isfinite(v) else None
    return value


def model_document(model: FrictionModel, *, method: str, settings: dict, figures: dict, data: dict) -> dict:
    """The JSON document (a dict) of one identification."""

    return _clean(
        {
            "schema": SCHEMA,
            "family": "maxwell_slip",
            "model": "J*theta'' + sum_i k_i*S_Delta_i[theta] + b*theta' + Fc*sign(theta') + c0 + K*theta = tau",
            "method": method,
            "parameters": model.to_dict(),
            "data": data,
            "settings": settings,
            "figures": figures,
        }
    )


def write_model(path: str | Path, document: dict) -> None:
    """Write the document as indented JSON (NaN-free)."""
    Path(path).write_text(json.dumps(_clean(document), indent=2, allow_nan=False) + "\n")


def family_document(fit, *, method: str, settings: dict, figures: dict, data: dict) -> dict:
    """The JSON document of one identified family (``families.FamilyFit``): schema version 2."""
    params = {"axis": fit.axis, "units": fit.units, **fit.params, "std_errors": fit.std_errors}
    return _clean({"schema": SCHEMA, "family": fit.family, "model": f"J*theta'' + F_{fit.family} + c0 = tau",
                   "method": method, "n_parameters": fit.n_parameters, "parameters": params,
                   "plant": fit.plant.to_dict(), "data": data, "settings": settings, "figures": figures})


@dataclass
class FamilyModel:
    """A model file read back: the family, its parameters with standard errors (None: none exists) and units,
    and the plant (``firmware_sim.engine.plant.PlantParams``) that simulates it."""

    family: str
    axis: str
    parameters: dict
    std_errors: dict
    units: dict
    plant: object

    def uncertainty(self, name: str) -> float | list | None:
        """Standard error of ``name`` (same unit), None where it does not exist."""
        return self.std_errors.get(name)


def load_document(path: str | Path, what: str = "model file") -> dict:
    """The JSON object of a model or comparison file; its size is checked against :data:`MAX_MODEL_BYTES` before
    it is read, and anything unreadable (not UTF-8, not JSON, nested too deep, not an object) is one
    :class:`AnalysisError`."""
    try:
        size = os.stat(path).st_size
        if size > MAX_MODEL_BYTES:
            raise AnalysisError(f"{path}: {size} bytes, above the {MAX_MODEL_BYTES} bytes a {what} may have "
                                f"(MAX_MODEL_BYTES)")
        with open(path, "rb") as fh:  # a FIFO or a device grows while read: read at most the bound plus one byte
            raw = fh.read(MAX_MODEL_BYTES + 1)
        if len(raw) > MAX_MODEL_BYTES:
            raise AnalysisError(f"{path}: above the {MAX_MODEL_BYTES} bytes a {what} may have (MAX_MODEL_BYTES)")
        doc = json.loads(raw.decode("utf-8"))
    except (OSError, ValueError) as exc:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise AnalysisError(f"cannot read {what} {path}: {' '.join(str(exc).split())}") from None
    except RecursionError:
        raise AnalysisError(f"cannot read {what} {path}: nested too deep") from None
    if not isinstance(doc, dict):
        raise AnalysisError(f"{path}: not a hilbench {what} (a JSON object is expected)")
    return doc


def _load(path: str | Path) -> dict:
    doc = load_document(path)
    if doc.get("schema") not in READABLE:
        raise AnalysisError(f"{path}: not a hilbench friction model (schema {str(doc.get('schema'))[:60]!r})")
    return doc


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def check_number(value, where: str, minimum: float | None = None, positive: bool = False) -> float:
    """``value`` as a float if it is a JSON number (not a string, not true/false), finite, within
    :data:`MAX_PARAMETER`, and >= ``minimum`` (> 0 when ``positive``); else :class:`AnalysisError`."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise AnalysisError(f"{where} must be a number, got {_short(value)}")
    try:
        v = float(value)
    except OverflowError:
        v = math.inf
    if not (math.isfinite(v) and abs(v) <= MAX_PARAMETER):
        raise AnalysisError(f"{where} must be finite and within +-{MAX_PARAMETER:g} (SI), got {_short(value)}")
    if positive and not v > 0:
        raise AnalysisError(f"{where} must be > 0, got {_short(value)}")
    if minimum is not None and v < minimum:
        raise AnalysisError(f"{where} must be >= {minimum:g}, got {_short(value)}")
    return v


def check_numbers(value, where: str, minimum: float | None = None, nullable: bool = False) -> list:
    """A JSON list of numbers (each as :func:`check_number`; ``None`` allowed when ``nullable``), at most
    ``firmware_sim.engine.plant.MAX_ELEMENTS`` long (the C plant's element limit)."""
    from hilbench.firmware_sim.engine.plant import MAX_ELEMENTS

    if not isinstance(value, list):
        raise AnalysisError(f"{where} must be a list of numbers, got {_short(value)}")
    if len(value) > MAX_ELEMENTS:
        raise AnalysisError(f"{where} has {len(value)} values, above the limit of {MAX_ELEMENTS}")
    return [None if (nullable and v is None) else check_number(v, f"{where}[{i}]", minimum)
            for i, v in enumerate(value)]


def check_name(value, where: str) -> str:
    """A name read from a file that may become part of a file name: a plain identifier (:data:`NAME`)."""
    if not isinstance(value, str) or not NAME.match(value):
        raise AnalysisError(f"{where} must be a plain identifier (letters, digits, '_'), got {_short(value)}")
    return value


def _check_std_errors(se, where: str) -> None:
    if not isinstance(se, dict):
        raise AnalysisError(f"{where}.std_errors must be an object, got {_short(se)}")
    for key, value in se.items():
        if isinstance(value, list):
            check_numbers(value, f"{where}.std_errors.{key}", 0.0, nullable=True)
        elif value is not None:
            check_number(value, f"{where}.std_errors.{key}", 0.0)


def _check_units(units, where: str) -> None:
    if not isinstance(units, dict) or not all(isinstance(u, str) for u in units.values()):
        raise AnalysisError(f"{where}.units must be an object of unit names, got {_short(units)}")


def check_maxwell_slip(params, where: str) -> None:
    """Refuse, naming the field, every value of a Maxwell-slip parameter block that would otherwise be changed
    on the way to the model: a string or true where a number belongs, a negative J, k_i, Delta_i, b or Fc,
    stiffnesses and Delta of different lengths, a non-finite or huge value."""
    if not isinstance(params, dict):
        raise AnalysisError(f"{where} must be an object, got {_short(params)}")
    if not isinstance(params.get("axis"), str) or params["axis"] not in AXES:
        raise AnalysisError(f"{where}.axis must be 'rotary' or 'linear', got {_short(params.get('axis'))}")
    for key in ("inertia", "ms_stiffness", "ms_delta"):
        if key not in params:
            raise AnalysisError(f"{where} lacks the field {key!r}")
    check_number(params["inertia"], f"{where}.inertia", positive=True)
    k = check_numbers(params["ms_stiffness"], f"{where}.ms_stiffness", 0.0)
    delta = check_numbers(params["ms_delta"], f"{where}.ms_delta", 0.0)
    if len(k) != len(delta):
        raise AnalysisError(f"{where}: {len(k)} stiffnesses (ms_stiffness) but {len(delta)} slip displacements "
                            "(ms_delta); they pair element by element")
    if "ms_slip" in params:
        check_numbers(params["ms_slip"], f"{where}.ms_slip", 0.0)
    for key, minimum in (("viscous", 0.0), ("coulomb", 0.0), ("offset", None), ("spring", None)):
        if key in params:
            check_number(params[key], f"{where}.{key}", minimum)
    if "std_errors" in params:
        _check_std_errors(params["std_errors"], where)
    if "units" in params:
        _check_units(params["units"], where)


#: plant fields that are counts or seeds, not SI quantities
_PLANT_INTEGERS = {"counts_per_rev", "delay_samples", "seed", "stack", "order"}
#: plant fields written as the string "inf" for an infinite value (PlantParams.to_dict)
_PLANT_INF = {"current_limit", "attraction"}
#: plant fields that may be null (not present in the model)
_PLANT_NULLABLE = {"viscous_neg", "coulomb_neg", "static", "restoring_table", "damping_table", "lugre", "gms",
                   "hysteresis"}


def check_plant(plant, where: str) -> None:
    """Types and signs of a plant block (``firmware_sim.engine.plant.PlantParams.to_dict``) before it is rebuilt:
    numbers where numbers belong (``"inf"`` only where to_dict writes it), no negative element stiffness or
    slip force, stiffnesses and slip forces of the same length; the plant checks the rest when it is built."""
    if not isinstance(plant, dict):
        raise AnalysisError(f"{where} must be an object, got {_short(plant)}")
    for key, value in plant.items():
        here = f"{where}.{key}"
        if (value is None and key in _PLANT_NULLABLE) or (key in _PLANT_INF and value == "inf"):
            continue
        if key in _PLANT_INTEGERS:
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**63:
                raise AnalysisError(f"{here} must be a whole number >= 0, got {_short(value)}")
        elif key in ("ms_stiffness", "ms_slip"):
            check_numbers(value, here, 0.0)
        elif key in ("restoring_table", "damping_table"):
            if not (isinstance(value, list) and len(value) == 2):
                raise AnalysisError(f"{here} must be [positions, values], got {_short(value)}")
            for i, column in enumerate(value):
                check_numbers(column, f"{here}[{i}]")
        elif key == "cogging":
            if not isinstance(value, list) or len(value) > 64:
                raise AnalysisError(f"{here} must be a list of at most 64 harmonics, got {_short(value)}")
            for i, harmonic in enumerate(value):
                check_plant(harmonic, f"{here}[{i}]")
        elif key in ("lugre", "gms", "hysteresis"):
            check_plant(value, here)
        elif key in ("stiffness", "fractions"):
            check_numbers(value, here, 0.0)
        else:
            check_number(value, here, 0.0 if key == "inertia" else None)
    for a, b in (("ms_stiffness", "ms_slip"), ("stiffness", "fractions")):
        if isinstance(plant.get(a), list) and isinstance(plant.get(b), list) and len(plant[a]) != len(plant[b]):
            raise AnalysisError(f"{where}: {len(plant[a])} values in {a} but {len(plant[b])} in {b}; they pair "
                                "element by element")


def check_family(family, where: str) -> str:
    """A family name of :data:`analysis.models.families.FAMILIES`."""
    from hilbench.analysis.models.families import FAMILIES

    if family not in FAMILIES:
        raise AnalysisError(f"{where}: family must be one of {', '.join(FAMILIES)}, got {_short(family)}")
    return family


def read_family(path: str | Path) -> tuple[FamilyModel, dict]:
    """Read any model file (version 1 or 2, any family); returns the model and the whole document."""
    from hilbench.firmware_sim.engine.plant import PlantParameterError, PlantParams

    doc = _load(path)
    family = check_family(doc.get("family", "maxwell_slip"), str(path))
    if "plant" in doc:
        check_plant(doc["plant"], f"{path}: plant")
        if not isinstance(doc.get("parameters", {}), dict):
            raise AnalysisError(f"{path}: parameters must be an object")
    else:
        check_maxwell_slip(doc.get("parameters"), f"{path}: parameters")
    params = dict(doc.get("parameters") or {})
    se = params.pop("std_errors", {}) or {}
    units = params.pop("units", {}) or {}
    axis = params.pop("axis", "rotary")
    if not isinstance(axis, str) or axis not in AXES:
        raise AnalysisError(f"{path}: parameters.axis must be 'rotary' or 'linear', got {_short(axis)}")
    if not isinstance(se, dict):
        raise AnalysisError(f"{path}: parameters.std_errors must be an object")
    _check_units(units, f"{path}: parameters")
    try:
        plant = PlantParams.from_dict(doc["plant"]) if "plant" in doc else FrictionModel.from_dict(
            {**doc["parameters"], "std_errors": {}}).plant_params()
    except (KeyError, TypeError, ValueError, PlantParameterError) as exc:
        raise AnalysisError(f"{path}: the {family} model cannot be rebuilt: {exc}") from None
    return FamilyModel(family, axis, params, se, units, plant), doc


def read_model(path: str | Path) -> tuple[FrictionModel, dict]:
    """Read a Maxwell-slip model file (``hilbench identify``); returns the model and the whole document."""
    doc = _load(path)
    if check_family(doc.get("family", "maxwell_slip"), str(path)) != "maxwell_slip":
        raise AnalysisError(f"{path}: a {doc['family']} model, not Maxwell-slip (read it with read_family)")
    check_maxwell_slip(doc.get("parameters"), f"{path}: parameters")
    params = dict(doc["parameters"])
    params["std_errors"] = {k: (np.nan if v is None else v) for k, v in params.get("std_errors", {}).items()}
    return FrictionModel.from_dict(params), doc
