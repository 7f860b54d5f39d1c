"""The identification's entry in the analysis registry (hilbench.analysis.protocol): read within a memory budget
(whole arrays, else chunk by chunk), analyse (identification.analyse / analyse_stream), report (the model file
and the plots)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.maxwell_fit import LipSettings
from hilbench.analysis.protocol import STREAMED, Analysis, Inputs, ReadOptions, Result, whole, write_json
from hilbench.common.units import mib


@dataclass(frozen=True)
class IdentifySettings:
    """``lip``: the fit's settings (thresholds, cutoff, terms, fixed inertia); ``method``: lip, oe or paper."""

    lip: LipSettings = field(default_factory=LipSettings)
    method: str = "lip"


def read(paths: Sequence[str | Path], options: ReadOptions) -> Inputs:
    """Whole arrays when every run fits ``options.memory`` together (identification.array_cost), else chunk by
    chunk (identification.stream_cost); refused in one line before any sample is read when neither fits, or when
    a host-clocked run (resampled whole) does not fit whole."""
    from hilbench.analysis.identification import array_cost, stream_cost
    from hilbench.analysis.record import stream_record

    heads = [stream_record(p, **options.loader()) for p in paths]
    samples = sum(h.n_samples for h, _ in heads)
    budget = options.memory
    if budget is None or array_cost(samples) <= budget:
        return whole(paths, options, heads)  # a host-clocked run came back whole from stream_record: not read twice
    if any(src is None for _, src in heads):
        raise AnalysisError(f"{samples} samples need about {mib(array_cost(samples))} read whole, over --memory "
                            f"{mib(budget)}; a host-clocked run is resampled whole: raise --memory")
    if stream_cost(samples) > budget:
        raise AnalysisError(f"{samples} samples need about {mib(stream_cost(samples))} even read chunk by chunk, "
                            f"over --memory {mib(budget)}")
    return Inputs([h for h, _ in heads], [s for _, s in heads], [STREAMED] * len(heads), budget)


def compute(inputs: Inputs, settings: IdentifySettings, validation: Inputs | None, progress=None):
    from hilbench.analysis.identification import analyse, analyse_stream, array_cost

    if not inputs.streamed and (validation is None or not validation.streamed):
        return analyse(inputs.record, settings.lip, method=settings.method,
                       validation=validation.record if validation is not None else None)
    if validation is not None and not validation.streamed:
        raise AnalysisError("the training run is read chunk by chunk and the validation run whole: read them "
                            "together (protocol.read_runs)")
    if settings.method not in ("lip", "oe"):
        samples = sum(r.n_samples for r in inputs.records + (validation.records if validation else []))
        raise AnalysisError(f"--method {settings.method} reads the record whole ({mib(array_cost(samples))} for "
                            f"{samples} samples, over --memory {mib(inputs.budget or 0)}): use --method lip or oe, "
                            "or raise --memory")
    # analyse_stream checks the validation run, its sample rate included (both are read at one rate)
    return analyse_stream(inputs.record, inputs.sources[0], settings.lip, method=settings.method,
                          validation=(validation.record, validation.sources[0]) if validation is not None else None)


def breakaway_se(model) -> float:
    """Standard error of the break-away sum k_i*Delta_i from the elements' own errors (their covariance is not
    kept in the model, so correlations are ignored: an approximation that says so in docs/campaign-analysis.md)."""
    import numpy as np

    se = np.asarray(model.std_errors.get("ms_stiffness", []), dtype=float)
    if se.size != model.ms_stiffness.size:
        return math.nan
    return float(np.sqrt(np.sum((se * np.asarray(model.ms_delta)) ** 2)))


FIGURES = ("train_torque_nrmse", "train_position_nrmse", "train_position_nrmse_segmented",
           "validation_torque_nrmse", "validation_position_nrmse", "validation_position_nrmse_segmented",
           "train_force_nrmse", "validation_force_nrmse")


def summarise(result: Result) -> dict[str, Any]:
    """The model's parameters with their standard errors and the figures (fractions), flat."""
    m, f = result.value.model, result.value.figures
    se = m.std_errors
    row: dict[str, Any] = {
        "inertia": m.inertia, "inertia_se": se.get("inertia", math.nan),
        "breakaway": m.breakaway, "breakaway_se": se.get("breakaway", breakaway_se(m)),
        "viscous": m.viscous, "viscous_se": se.get("viscous", math.nan),
        "coulomb": m.coulomb, "coulomb_se": se.get("coulomb", math.nan),
        "offset": m.offset, "offset_se": se.get("offset", math.nan),
        "n_elements": int(m.ms_stiffness.size), "model": "maxwell_slip", "method": result.value.method,
    }
    row.update({k: f[k] for k in FIGURES if k in f})
    return row


def document(result: Result) -> dict:
    """The model file (docs/model-file.md) of the identification, with the runs' provenance."""
    from hilbench.analysis.models.model_file import model_document
    from hilbench.analysis.protocol import provenance

    res = result.value
    return model_document(res.model, method=res.method, settings=res.settings, figures=res.figures,
                          data=provenance(result.inputs, result.validation))


def write(result: Result, out: Path) -> list[Path]:
    """``model.json`` and, when the curves were kept (a run read whole), the plots."""
    from hilbench.analysis.identification import report

    files = [write_json(out / "model.json", document(result))]
    if result.value.curves and "train_force_nrmse" not in result.value.figures:
        runs = {"train": result.inputs.record.path}
        if result.validation is not None:
            runs["validation"] = result.validation.record.path
        files += report(result.value, out, runs=runs)
    return files


COLUMNS = {
    "inertia": ("float64", "inertia"), "inertia_se": ("float64", "inertia"),
    "breakaway": ("float64", "torque"), "breakaway_se": ("float64", "torque"),
    "viscous": ("float64", "viscous"), "viscous_se": ("float64", "viscous"),
    "coulomb": ("float64", "torque"), "coulomb_se": ("float64", "torque"),
    "offset": ("float64", "torque"), "offset_se": ("float64", "torque"),
    "n_elements": ("int64", "1"),
    "train_torque_nrmse": ("float64", "1"), "validation_torque_nrmse": ("float64", "1"),
    "validation_position_nrmse": ("float64", "1"), "validation_position_nrmse_segmented": ("float64", "1"),
}

ENTRY = Analysis("identify", "Identification (Maxwell-slip, NNLS)", read, compute, summarise, IdentifySettings,
                 write=write, matches=("axis", "kind", "timing"), protocols=("identification", "chirp"),
                 columns=COLUMNS)
