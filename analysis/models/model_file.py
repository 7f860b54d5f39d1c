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
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.models.friction_model import FrictionModel

SCHEMA = "hilbench.friction-model/2"
READABLE = ("hilbench.friction-model/1", SCHEMA)


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
    and the plant (``firmware_sim.plant.PlantParams``) that simulates it."""

    family: str
    axis: str
    parameters: dict
    std_errors: dict
    units: dict
    plant: object

    def uncertainty(self, name: str) -> float | list | None:
        """Standard error of ``name`` (same unit), None where it does not exist."""
        return self.std_errors.get(name)


def _load(path: str | Path) -> dict:
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise AnalysisError(f"cannot read model file {path}: {exc}") from None
    if not isinstance(doc, dict) or doc.get("schema") not in READABLE:
        schema = doc.get("schema") if isinstance(doc, dict) else None
        raise AnalysisError(f"{path}: not a hilbench friction model (schema {schema!r})")
    return doc


def read_family(path: str | Path) -> tuple[FamilyModel, dict]:
    """Read any model file (version 1 or 2, any family); returns the model and the whole document."""
    from hilbench.firmware_sim.plant import PlantParameterError, PlantParams

    doc = _load(path)
    family = doc.get("family", "maxwell_slip")
    params = dict(doc.get("parameters") or {})
    se = params.pop("std_errors", {}) or {}
    units = params.pop("units", {}) or {}
    axis = params.pop("axis", "rotary")
    try:
        plant = PlantParams.from_dict(doc["plant"]) if "plant" in doc else FrictionModel.from_dict(
            {**doc["parameters"], "std_errors": {}}).plant_params()
    except (KeyError, TypeError, ValueError, PlantParameterError) as exc:
        raise AnalysisError(f"{path}: the {family} model cannot be rebuilt: {exc}") from None
    return FamilyModel(family, axis, params, se, units, plant), doc


def read_model(path: str | Path) -> tuple[FrictionModel, dict]:
    """Read a Maxwell-slip model file (``hilbench identify``); returns the model and the whole document."""
    doc = _load(path)
    if doc.get("family", "maxwell_slip") != "maxwell_slip":
        raise AnalysisError(f"{path}: a {doc['family']} model, not Maxwell-slip (read it with read_family)")
    params = dict(doc["parameters"])
    params["std_errors"] = {k: (np.nan if v is None else v) for k, v in params.get("std_errors", {}).items()}
    return FrictionModel.from_dict(params), doc
