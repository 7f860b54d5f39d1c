"""The model file: JSON with the parameters, their standard errors, the data, settings and figures.

Schema: docs/model-file.md (``"schema": "hilbench.friction-model/1"``). NaN (a standard error that
does not exist, e.g. a parameter at its bound) is written as null.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.models.friction_model import FrictionModel

SCHEMA = "hilbench.friction-model/1"


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


def read_model(path: str | Path) -> tuple[FrictionModel, dict]:
    """Read a model file; returns the model and the whole document."""
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise AnalysisError(f"cannot read model file {path}: {exc}") from None
    if doc.get("schema") != SCHEMA:
        raise AnalysisError(f"{path}: not a hilbench friction model (schema {doc.get('schema')!r})")
    params = dict(doc["parameters"])
    params["std_errors"] = {k: (np.nan if v is None else v) for k, v in params.get("std_errors", {}).items()}
    return FrictionModel.from_dict(params), doc
