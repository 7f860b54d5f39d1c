"""The presliding analysis's entry in the analysis registry (hilbench.analysis.protocol): read within a memory
budget (whole, else chunk by chunk: analysis.presliding.streamed), analyse (the record checks, force against the
imposed displacement), report (presliding.json, summary.md, reversals.csv and the figures)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.presliding.identify import PreslidingSettings
from hilbench.analysis.protocol import STREAMED, Analysis, Inputs, ReadOptions, Result, whole


@dataclass(frozen=True)
class PreslidingAnalysis:
    """``fit``: the force model's settings; ``inertia`` (kg*m^2 or kg; None: the presliding protocol's, else 0);
    ``counts_per_rev`` (None: the run's calibration); ``hysteresis`` (m or rad; None: 1.5 position steps);
    ``fraction`` of the sliding level that defines the presliding distance; bootstrap ``replicates``."""

    fit: PreslidingSettings = field(default_factory=PreslidingSettings)
    inertia: float | None = None
    counts_per_rev: float | None = None
    hysteresis: float | None = None
    fraction: float = 0.9
    replicates: int = 20

    def options(self) -> dict[str, Any]:
        return {"inertia": self.inertia, "counts_per_rev": self.counts_per_rev, "hysteresis": self.hysteresis,
                "fraction": self.fraction, "replicates": self.replicates}


def read(paths: Sequence[str | Path], options: ReadOptions) -> Inputs:
    """One displacement-driven run: whole when it fits ``options.memory`` (or is host-clocked), else chunk by
    chunk; refused in one line before the samples are read when neither fits."""
    from hilbench.analysis import presliding
    from hilbench.analysis.record import stream_record
    from hilbench.common.units import mib

    if len(paths) != 1:
        raise AnalysisError(f"the presliding analysis reads one run, got {len(paths)}")
    head, source = stream_record(paths[0], **options.loader())
    budget = options.memory
    if source is None:
        return Inputs([head], budget=budget)
    if budget is None or presliding.array_cost(head.n_samples) <= budget:
        return whole(paths, options)
    if presliding.stream_cost(head.n_samples) > budget:
        raise AnalysisError(f"{paths[0]}: needs about {mib(presliding.stream_cost(head.n_samples))} even read "
                            f"chunk by chunk, over --memory {mib(budget)}: raise --memory")
    return Inputs([head], [source], [STREAMED], budget)


def compute(inputs: Inputs, settings: PreslidingAnalysis, validation: Inputs | None, progress=None):
    from hilbench.analysis import presliding

    rec = inputs.record
    if not inputs.streamed:
        return presliding.analyse(rec, settings.fit, **settings.options())
    res, _ = presliding.analyse_stream(rec.path, settings.fit, torque_channel=rec.torque_channel,
                                       timing=rec.timing, allow_incomplete=rec.incomplete is not None,
                                       progress=progress, **settings.options())
    return res


def summarise(result: Result) -> dict[str, Any]:
    """The quantities of docs/presliding.md with their standard uncertainties, the relative rms error of the force
    simulated from the measured displacement, and the warnings."""
    res = result.value
    q, e = res.quantities, res.uncertainties
    row: dict[str, Any] = {"validation_force_relative_error": res.fit.relative_rms, "warnings": "; ".join(res.warnings)}
    for name, column in (("breakaway", "presliding_breakaway"), ("initial_stiffness", "initial_stiffness"),
                         ("presliding_distance", "presliding_distance")):
        row[column], row[f"{column}_se"] = q[name], e[name]
    return row


def document(result: Result) -> dict:
    from hilbench.analysis import presliding

    return presliding.document(result.value, result.inputs.record, result.inputs.reads[0])


def write(result: Result, out: Path) -> list[Path]:
    from hilbench.analysis import presliding

    return presliding.report(result.value, out, document(result))


COLUMNS = {
    # the quantities of docs/presliding.md with their standard uncertainties (axis units: rotary N*m, N*m/rad,
    # rad; linear N, N/m, m) and the force simulated from the displacement against the measured one
    "presliding_breakaway": ("float64", "torque"), "presliding_breakaway_se": ("float64", "torque"),
    "initial_stiffness": ("float64", "stiffness"), "initial_stiffness_se": ("float64", "stiffness"),
    "presliding_distance": ("float64", "position"), "presliding_distance_se": ("float64", "position"),
    "validation_force_relative_error": ("float64", "1"), "warnings": ("string", ""),
}

ENTRY = Analysis("presliding", "Presliding (force from displacement)", read, compute, summarise, PreslidingAnalysis,
                 write=write, protocols=("presliding",), columns=COLUMNS)
