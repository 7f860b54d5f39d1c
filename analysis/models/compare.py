"""Every friction family fitted on one run and scored on another, side by side (``hilbench compare``).

Figures on the validation run (docs/compare.md), scored by the one scoring function (``analysis.scoring``), so a
row reads as ``hilbench identify`` reads the same model on the same run:

- ``torque_nrmse`` is the equation error: rms(L[tau] - L[tau_model])/std(L[tau]) on the filtered rows. The
  model's friction is evaluated along the measured path from the run's first sample (a held-out tail: from the
  state the run before it left).
- ``position_nrmse_segmented`` is the simulation error, restarted every ``segment`` s from the measured state.
- ``n_parameters`` is the parameter count. ``fit_time_s`` is the wall time of the identification on the
  training run (the Maxwell-slip NNLS fit that several families start from is timed once, in its own row).

A family whose fit or evaluation fails keeps its row, named, with ``error`` holding the reason and no figures;
the other families complete.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.maxwell_fit import LipSettings
from hilbench.analysis.models.families import (
    FAMILIES,
    FamilyFit,
    RunData,
    fit_family,
    maxwell_slip_start,
    predicted_torque,
)
from hilbench.analysis.scoring import ScoredRun, ScoreSettings, score_run
from hilbench.common.metrics import percent
from hilbench.firmware_sim.engine.plant import PlantParameterError, PlantParams

SCHEMA = "hilbench.compare/1"


@dataclass
class Row:
    name: str
    n_parameters: int
    fit_time_s: float
    train: dict
    validation: dict
    fit: FamilyFit | None = None
    plant: PlantParams | None = None
    curves: dict = field(default_factory=dict)
    error: str | None = None  # why the family could not be fitted or evaluated (then no figures)


@dataclass
class Comparison:
    train: RunData
    validation: RunData
    rows: list[Row]
    segment_s: float


def compare(train: RunData, validation: RunData, *, timing: str, train_position: np.ndarray,
            train_torque: np.ndarray, families: tuple[str, ...] = FAMILIES, segment: float = 1.0,
            max_nfev: int = 40, published: dict[str, PlantParams] | None = None,
            progress: Callable[[str], None] | None = None, lip: LipSettings | None = None,
            scored: tuple[ScoredRun, ScoredRun] | None = None) -> Comparison:
    """Fit every family in ``families`` on ``train``; score it (and each ``published`` model) on both runs;
    ``progress(name)`` after each row. ``lip``: the terms of the Maxwell-slip fit (identify's defaults: J, k_i,
    Delta_i, b); ``scored``: the runs as the scorer reads them (a held-out tail with the run before it; default:
    ``train`` and ``validation`` from their first samples)."""
    rows: list[Row] = []
    t0 = time.perf_counter()
    runs = scored or (_scored(train), _scored(validation))
    ms = maxwell_slip_start(train, timing, train_position, train_torque, lip)
    ms_time = time.perf_counter() - t0
    for family in families:
        t1 = time.perf_counter()
        try:
            fit = fit_family(family, train, timing=timing, position=train_position, torque=train_torque,
                             segment=segment, max_nfev=max_nfev, ms_fit=ms)
            if family == "maxwell_slip":
                fit.fit_time_s = ms_time
            rows.append(_row(family, fit.n_parameters, fit.fit_time_s, fit.plant, validation, runs, segment, fit))
        except (AnalysisError, PlantParameterError, FloatingPointError, np.linalg.LinAlgError) as exc:
            # our own one-line refusals say what and why; another error is named by its type
            reason = str(exc) if isinstance(exc, AnalysisError) else f"{type(exc).__name__}: {exc}"
            rows.append(failed_row(family, reason, time.perf_counter() - t1))
        if progress is not None:
            progress(family)
    for name, plant in (published or {}).items():
        rows.append(_row(name, 4, math.nan, plant, validation, runs, segment, None))
    return Comparison(train, validation, rows, segment)


def failed_row(name: str, reason: str, fit_time: float) -> Row:
    """The row of a family that could not be fitted or evaluated: named, with its reason, no figures."""
    blank = {"torque_nrmse": math.nan, "position_nrmse_segmented": math.nan, "position_rms_segmented": math.nan}
    return Row(name, 0, fit_time, dict(blank), dict(blank), error=reason)


def _scored(run: RunData) -> ScoredRun:
    """A run of the families as the scorer reads it (the held torque with hold_next timing is the same torque)."""
    return ScoredRun(run.x, run.u, run.fs, "hold_next")


def _row(name: str, n_par: int, fit_time: float, plant: PlantParams, validation: RunData,
         runs: tuple[ScoredRun, ScoredRun], segment: float, fit: FamilyFit | None) -> Row:
    scoring = ScoreSettings(segment=segment)
    keys = ("torque_nrmse", "position_nrmse_segmented", "position_rms_segmented")
    figures = []
    sim = np.full_like(validation.x, np.nan)
    for i, run in enumerate(runs):
        try:
            sc = score_run(plant, run, scoring, keep=i == 1)
        except AnalysisError:  # a model that cannot be simulated keeps its torque figure
            sc = score_run(plant, run, ScoreSettings(segment=segment, simulate=False))
        figures.append({k: sc.figures.get(k, math.nan) for k in keys})
        if i == 1 and sc.position_sim_segmented is not None:
            sim = sc.position_sim_segmented
    torque = predicted_torque(plant, validation)  # the plots' curves, at the validation run's own rows
    friction = torque - plant.inertia * validation.data.acceleration + plant.torque_offset
    return Row(name, n_par, fit_time, figures[0], figures[1], fit, plant,
               curves={"torque_predicted": torque, "position_simulated": sim, "friction_predicted": friction,
                       "friction_measured": validation.data.torque - plant.inertia * validation.data.acceleration
                       + plant.torque_offset})


def markdown_table(result: Comparison) -> str:
    """The comparison as a Markdown table (validation figures first)."""
    unit = "rad" if result.train.axis == "rotary" else "m"
    lines = [
        f"Train: {result.train.name} ({result.train.x.size} samples at {result.train.fs:g} Hz); validation: "
        f"{result.validation.name} ({result.validation.x.size} samples). NRMSE = 100*rms(error)/std(measured), in % "
        "(docs/metrics.md); "
        f"position simulated with restarts every {result.segment_s:g} s ({unit}).",
        "",
        f"| model | parameters | fit time (s) | validation torque NRMSE (%) | validation position NRMSE (segmented, "
        f"%) | validation position rms error ({unit}) | train torque NRMSE (%) | train position NRMSE (segmented, %) |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def f(v: float) -> str:
        return "–" if v is None or not math.isfinite(v) else f"{v:.4g}"

    for r in result.rows:
        if r.error is not None:
            lines.append(f"| {r.name} | – | {f(r.fit_time_s)} | FAILED: {r.error.replace('|', '/')} | | | | |")
            continue
        v, t = r.validation, r.train  # NRMSE fractions; the table shows percent (common.metrics.percent)
        lines.append(f"| {r.name} | {r.n_parameters} | {f(r.fit_time_s)} | {f(percent(v['torque_nrmse']))} | "
                     f"{f(percent(v['position_nrmse_segmented']))} | {f(v['position_rms_segmented'])} "
                     f"| {f(percent(t['torque_nrmse']))} | {f(percent(t['position_nrmse_segmented']))} |")
    return "\n".join(lines) + "\n"


def _clean(value):
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_clean(v) for v in value]
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def document(result: Comparison, data: dict) -> dict:
    """The JSON document (schema ``hilbench.compare/1``, docs/compare.md)."""
    return _clean({
        "schema": SCHEMA,
        "axis": result.train.axis,
        "segment_s": result.segment_s,
        "data": data,
        "rows": [{"model": r.name, "n_parameters": None if r.error else r.n_parameters,
                  "fit_time_s": r.fit_time_s, "train": r.train,
                  "validation": r.validation, "fit": None if r.fit is None else r.fit.to_dict(),
                  "plant": None if r.plant is None else r.plant.to_dict(), "error": r.error}
                 for r in result.rows],
    })


def write_json(path: str | Path, doc: dict) -> None:
    Path(path).write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")


# --- the front door: records in, a Comparison out (docs/compare.md, docs/long-runs.md) ------------------------------

#: peak bytes per sample of the comparison (training plus validation, at the rate compared) and its fixed part, from
#: the peaks measured on 10 and 20 kHz runs (docs/long-runs.md), with margin
COMPARE_BYTES_PER_SAMPLE = 400
COMPARE_BYTES_FIXED = 160 << 20
#: the lowest rate a record over the memory budget is reduced to (Hz): the families' regression low-pass (fs/20)
#: must pass the presliding mode (186 Hz on the default DC motor), so fs/20 >= 250 Hz. At 2 kHz (a 100 Hz low-pass)
#: the segmented position error of the presliding families rose from 1.6 % to 5.4 % (docs/long-runs.md)
DECIMATED_RATE = 5000.0
#: the shortest span (s) worth comparing when a budget bounds it: a few periods of the identification protocol's
#: 4 s envelope, and segments enough for the segmented simulation error
MIN_SPAN_S = 10.0


@dataclass(frozen=True)
class CompareSettings:
    """``families`` to fit; ``segment`` (s) between restarts of the segmented simulation; ``max_nfev`` output-error
    evaluations per family; ``published`` models scored as extra rows (name -> plant); ``lip`` the terms of the
    Maxwell-slip fit (``maxwell_slip`` row; identify's defaults when None: its row is identify's model)."""

    families: tuple[str, ...] = FAMILIES
    segment: float = 1.0
    max_nfev: int = 40
    published: dict[str, PlantParams] = field(default_factory=dict)
    lip: LipSettings | None = None  # terms of the maxwell_slip row (None: identify's defaults, no offset)


def cost(samples: int) -> int:
    """Estimated peak bytes of :func:`analyse` on ``samples`` (training plus validation)."""
    return COMPARE_BYTES_FIXED + COMPARE_BYTES_PER_SAMPLE * int(samples)


def span_samples(budget: int, runs: int = 2) -> int:
    """The most samples (at the rate compared) each of ``runs`` runs may give :func:`analyse` for its estimated
    peak (:func:`cost`) to stay within ``budget`` bytes (docs/long-runs.md, "A bounded span")."""
    from hilbench.analysis.record import bounded_span

    return bounded_span(budget, COMPARE_BYTES_FIXED, COMPARE_BYTES_PER_SAMPLE, runs)


def reading_plan(headers, budget: int) -> tuple[list[int], int | None] | None:
    """How :func:`analyse` reads ``headers`` (training and validation records of
    :func:`hilbench.analysis.record.stream_record`, arrays not loaded) within ``budget`` bytes: None when the
    whole runs fit at the recorded rate (:func:`cost`); else (the reduction factor of each run: the largest that
    keeps at least :data:`DECIMATED_RATE`, the bounded span in samples per run at that rate or None when the
    reduced runs fit whole). Raises :class:`AnalysisError` in one line, before any sample is read, when not even
    the first :data:`MIN_SPAN_S` s (or the shortest run) of each run fit (docs/long-runs.md, "A bounded span")."""
    from hilbench.common.units import mib

    samples = sum(h.n_samples for h in headers)
    if cost(samples) <= budget:
        return None
    qs = [max(1, int(h.sample_rate // DECIMATED_RATE)) for h in headers]  # the smallest copy the physics allows
    if cost(sum(h.n_samples // q for h, q in zip(headers, qs, strict=True))) <= budget:
        return qs, None
    span = span_samples(budget, len(headers))
    shortest = min(min(int(MIN_SPAN_S * h.sample_rate / q), h.n_samples // q) for h, q in zip(headers, qs, strict=True))
    if span < shortest:
        raise AnalysisError(f"compare on {samples} samples needs about {mib(cost(samples))}, and on the first "
                            f"{MIN_SPAN_S:g} s of each run reduced to {DECIMATED_RATE:g} Hz about "
                            f"{mib(cost(shortest * len(headers)))}, over --memory {mib(budget)}: raise --memory")
    return qs, span


def run_data(record) -> RunData:
    """A :class:`hilbench.analysis.record.Record` as the families read it."""
    return RunData.from_arrays(record.name, record.axis, record.sample_rate, record.position, record.torque,
                               record.timing)


def analyse(record, validation, settings: CompareSettings | None = None, *,
            progress: Callable[[str], None] | None = None) -> Comparison:
    """Every family of ``settings`` fitted on ``record`` and scored on ``validation`` (records of
    :mod:`hilbench.analysis.record`, same axis); ``progress(family)`` is called as each family is done."""
    s = settings or CompareSettings()
    if validation.axis != record.axis:
        raise AnalysisError(f"validation run axis {validation.axis!r} differs from the training run's {record.axis!r}")
    from hilbench.analysis.scoring import scored_run

    train, val = run_data(record), run_data(validation)
    return compare(train, val, timing=record.timing, train_position=train.x, train_torque=record.torque,
                   families=s.families, segment=s.segment, max_nfev=s.max_nfev, published=s.published,
                   progress=progress, lip=s.lip, scored=(scored_run(record), scored_run(validation)))
