"""The residual loop on records: :func:`read` (a run file, decimated chunk by chunk), :func:`analyse` (records in, a
:class:`ResidualAnalysis` out) and :func:`report` (the figures). ``hilbench residual``, the GUI and campaign steps
call these, so one run gives one answer (docs/long-runs.md, docs/residual-report.md).

The loop runs at most at :data:`~hilbench.analysis.residual.rundata.MAX_RATE` (2 kHz): ``prepare_run`` reduces a
faster record by :func:`hilbench.analysis.record.block_average`. :func:`read` does that reduction while reading the
file chunk by chunk, so the full-rate record is never held; the result is the same bit for bit as loading the whole
record (tests/analysis/residual/test_record_analysis.py). Over a memory budget, :func:`span_for` gives the bounded
span (the first samples of each run that fit) and :func:`read` stops there (docs/long-runs.md, "A bounded span").
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.residual.rundata import MAX_RATE

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from hilbench.analysis.models.friction_model import FrictionModel
    from hilbench.analysis.record import Record
    from hilbench.analysis.residual.rundata import RunData
    from hilbench.analysis.residual.selection import LoopResult

#: peak bytes of the loop per sample it analyses (after the reduction to 2 kHz; training plus validation) and its
#: fixed part, from the peaks measured on the default identification runs (docs/long-runs.md), with margin
LOOP_BYTES_PER_SAMPLE = 2400
LOOP_BYTES_FIXED = 200 << 20
#: the shortest span (s at the loop's rate) worth analysing when a budget bounds it: below it the blocked
#: cross-validation has folds of a fraction of a second
MIN_SPAN_S = 10.0


@dataclass(frozen=True)
class ResidualSettings:
    """What :func:`analyse` does: ``start`` (terms, or one friction family to identify first), ``cutoff`` (Hz,
    default fs/20 of the analysed rate), ``fixed_inertia`` (kg*m^2 or kg; None: estimated), ``candidates`` (None:
    every registered one)."""

    start: tuple[str, ...] = ("inertia", "maxwell_slip")
    cutoff: float | None = None
    fixed_inertia: float | None = None
    candidates: tuple[str, ...] | None = None
    start_model: FrictionModel | None = None  # start from this model, not refitted (``start`` is then ignored)
    start_model_document: dict | None = None  # its model file (identify's cutoff and thinning for its figures)


@dataclass
class ResidualAnalysis:
    """The loop's result with the runs it read: ``loop`` (:class:`LoopResult`), ``train`` and ``validation``
    (:class:`RunData` as the loop saw them) and the records they came from."""

    loop: LoopResult
    train: RunData
    validation: list[RunData]
    record: Record
    validation_records: list[Record] = field(default_factory=list)
    fixed_inertia: float | None = None  # the settings' J, 0 for a displacement-driven record
    start_model: dict | None = None  # the identified start model and its own figures (identify's definition)

    def start_figure(self) -> tuple[str, float] | None:
        """The start model's own torque NRMSE (fraction) as identify reports it: ("validation" or "train", value);
        None when the loop did not start from an identified model."""
        if self.start_model is None:
            return None
        f = self.start_model["figures"]
        where = "validation" if "validation_torque_nrmse" in f else "train"
        return where, f[f"{where}_torque_nrmse"]


def analysed_samples(n_samples: int, sample_rate: float) -> int:
    """Samples the loop analyses of a record of ``n_samples`` at ``sample_rate`` Hz (after the reduction)."""
    from hilbench.analysis.record import decimation_factor

    return int(n_samples) // decimation_factor(sample_rate, MAX_RATE)


def cost(samples: int) -> int:
    """Estimated peak bytes of :func:`analyse` over ``samples`` analysed samples (:func:`analysed_samples`)."""
    return LOOP_BYTES_FIXED + LOOP_BYTES_PER_SAMPLE * int(samples)


def span_samples(budget: int, runs: int) -> int:
    """The most samples (at the loop's rate) each of ``runs`` runs may give the loop for its estimated peak
    (:func:`cost`) to stay within ``budget`` bytes; 0 when not even the fixed part fits (docs/long-runs.md,
    "A bounded span")."""
    from hilbench.analysis.record import bounded_span

    return bounded_span(budget, LOOP_BYTES_FIXED, LOOP_BYTES_PER_SAMPLE, runs)


def span_for(headers: Sequence[Record], budget: int) -> int | None:
    """How the loop reads ``headers`` (records of :func:`hilbench.analysis.record.stream_record`, arrays not
    loaded) within ``budget`` bytes: None when the whole runs fit (:func:`cost`), else the bounded span
    (:func:`span_samples`, samples per run at the loop's rate). Raises :class:`AnalysisError` in one line, before
    any sample is read, when not even the first :data:`MIN_SPAN_S` s (or the shortest run) of each run fit."""
    from hilbench.common.units import mib

    samples = sum(analysed_samples(h.n_samples, h.sample_rate) for h in headers)
    if cost(samples) <= budget:
        return None
    from hilbench.analysis.record import decimation_factor

    span = span_samples(budget, len(headers))
    rates = [h.sample_rate / decimation_factor(h.sample_rate, MAX_RATE) for h in headers]
    shortest = min(min(int(MIN_SPAN_S * r) for r in rates),
                   min(analysed_samples(h.n_samples, h.sample_rate) for h in headers))
    if span < shortest:
        raise AnalysisError(f"the residual loop on {samples} samples (at most 2 kHz) needs about {mib(cost(samples))}"
                            f", and on the first {shortest} samples of each run about "
                            f"{mib(cost(shortest * len(headers)))}, over --memory {mib(budget)}: raise --memory")
    return span


def read(path: str | Path, *, torque_channel: str | None = None, timing: str = "auto", allow_incomplete: bool = False,
         chunk: int | None = None, progress: Callable[[int], None] | None = None,
         max_samples: int | None = None) -> Record:
    """The run file as the loop reads it: :func:`hilbench.analysis.record.decimated_record` at :data:`MAX_RATE`;
    ``max_samples`` (None: all) bounds the copy to the run's first ``max_samples`` samples at that rate
    (:func:`span_samples` gives the bound of a memory budget)."""
    from hilbench.analysis.record import STREAM_CHUNK, decimated_record

    return decimated_record(path, MAX_RATE, torque_channel=torque_channel, timing=timing,
                            allow_incomplete=allow_incomplete, chunk=chunk or STREAM_CHUNK, progress=progress,
                            max_samples=max_samples)


def _prepared(record: Record, cutoff: float | None) -> RunData:
    from hilbench.analysis.residual.rundata import prepare_run

    return prepare_run(record.position, record.torque, record.sample_rate, axis=record.axis, name=str(record.path),
                       cutoff=cutoff, timing=record.timing)


def analyse(record: Record, settings: ResidualSettings | None = None, *,
            validation: Sequence[Record] = ()) -> ResidualAnalysis:
    """The residual loop of ``record`` from ``settings.start``, its candidates judged on ``validation`` (never
    fitted; none: blocked cross-validation). Records at any rate (a faster one is reduced to 2 kHz, as
    :func:`read` does). Raises :class:`AnalysisError` in one line for runs that do not go together."""
    from hilbench.analysis.models.families import FAMILIES
    from hilbench.analysis.residual.family_start import family_start
    from hilbench.analysis.residual.published import published_metric
    from hilbench.analysis.residual.selection import LoopOptions, residual_loop

    s = settings or ResidualSettings()
    for v in validation:
        if v.kind != record.kind:
            raise AnalysisError(f"{record.path} is {record.kind}; every validation run must be too ({v.path} is "
                                f"{v.kind})")
    start: tuple | list = tuple(s.start)
    if len(start) == 1 and start[0] not in FAMILIES and start[0] != "inertia":
        raise AnalysisError(f"--start {start[0]!r} is neither a friction family ({', '.join(FAMILIES)}) nor a "
                            "comma-separated list of terms with inertia")
    if s.fixed_inertia == 0 and record.kind == "torque-driven":  # J = 0 leaves the loop nothing to fit
        raise AnalysisError(f"--inertia 0 is for a displacement-driven record; {record.path} is torque-driven: "
                            "give J > 0 or leave --inertia out to estimate it")
    train = _prepared(record, s.cutoff)
    val = [_prepared(v, s.cutoff) for v in validation]
    start_model = None
    if s.start_model is not None or start == ("maxwell_slip",):
        start, start_model = _identified_start(record, list(validation), s)
    elif len(start) == 1:
        if record.kind == "displacement-driven" or s.fixed_inertia is not None:
            raise AnalysisError("--start FAMILY identifies J with the family; it takes neither --inertia nor a "
                                "displacement-driven record (start from terms instead)")
        start = tuple(family_start(start[0], [train]))
    opts = LoopOptions(fixed_inertia=s.fixed_inertia, candidates=s.candidates, record=record.kind)
    loop = residual_loop(train, val or None, start=start, options=opts)
    loop.published_metric = published_metric(record.source, loop.fit_before, loop.fit_after, [train], val)
    fixed = 0.0 if record.kind == "displacement-driven" and s.fixed_inertia is None else s.fixed_inertia
    rescore(loop, record, list(validation), fixed)
    return ResidualAnalysis(loop, train, val, record, list(validation), fixed, start_model)


#: the figures of the start and the final model that the one scoring function gives (analysis.scoring)
SCORED = ("torque_nrmse", "torque_rel_pct", "position_nrmse", "position_nrmse_segmented", "force_nrmse",
          "force_rel_pct")


def rescore(loop: LoopResult, record: Record, validation: list[Record], fixed_inertia: float | None) -> None:
    """The start and the final model's figures (``loop.error_before`` / ``error_after``) scored by the one scoring
    function on the records as given (their own rate; a held-out tail from the state the run before it left), as
    identify and compare score theirs: the same model on the same data reads the same figure through every door.
    The loop's own held-out figures, on its design rows at its rate, which chose the terms, stay under ``loop``.
    With several validation runs a figure is the rms over the runs (as the loop's simulation figures)."""
    import copy
    import math

    from hilbench.analysis.residual.simulation_error import plant_params
    from hilbench.analysis.scoring import ScoreSettings, score_run, scored_run
    from hilbench.firmware_sim.engine.plant import PlantParameterError

    force = loop.record == "displacement-driven"
    settings = ScoreSettings(force=force)
    # the loop may hand back one dict for both (nothing added); the rounds' own figures stay the loop's
    loop.error_before, loop.error_after = copy.deepcopy(loop.error_before), copy.deepcopy(loop.error_after)
    for errors, fit in ((loop.error_before, loop.fit_before), (loop.error_after, loop.fit_after)):
        try:
            params = plant_params(fit, fixed_inertia or 0.0)
        except (AnalysisError, PlantParameterError) as exc:  # a term the plant lacks: the loop's figures, said so
            for part in ("train", "validation"):
                errors[part]["scoring_note"] = f"not scored by analysis.scoring ({exc}); the loop's own figures"
            continue
        for part, runs in (("train", [record]), ("validation", validation)):
            if not runs:
                continue
            own = {k: errors[part].pop(k) for k in list(errors[part]) if k in SCORED}
            figures = []
            for run in runs:
                try:
                    figures.append(score_run(params, scored_run(run), settings).figures)
                except AnalysisError as exc:  # a model the plant refuses keeps its torque figure, says why
                    figures.append(score_run(params, scored_run(run), ScoreSettings(force=force,
                                                                                    simulate=False)).figures)
                    errors[part]["simulation_note"] = str(exc)
            for key in SCORED:
                values = [f[key] for f in figures if key in f]
                if len(values) == len(figures):
                    errors[part][key] = float(math.sqrt(sum(v * v for v in values) / len(values)))
            if force:  # the force figures are the torque figures of a displacement-driven record (as the loop's)
                errors[part]["torque_nrmse"] = errors[part]["force_nrmse"]
                errors[part]["torque_rel_pct"] = errors[part]["force_rel_pct"]
                errors[part].update(position_nrmse=None, position_nrmse_segmented=None)
            errors[part]["loop"] = own


def _identified_start(record: Record, validation: list[Record], s: ResidualSettings) -> tuple[list, dict]:
    """The loop's start from an identified Maxwell-slip model: ``s.start_model`` (a model file's), else identify's
    fit of ``record`` (:func:`hilbench.analysis.identification.analyse`, the same call as ``hilbench identify``).
    Returns (start entries, the model's own figures by identify's definition on the runs the loop reads)."""
    from hilbench.analysis.identification import analyse as identify
    from hilbench.analysis.residual.model_start import document_settings, model_start, start_figures

    if record.kind == "displacement-driven" or s.fixed_inertia is not None:
        raise AnalysisError("--start maxwell_slip or MODEL.json identifies J with the model; it takes neither "
                            "--inertia nor a displacement-driven record (start from terms instead)")
    runs = {"train": record} | ({"validation": validation[0]} if validation else {})
    if s.start_model is not None:
        model = s.start_model
        if model.axis != record.axis:
            raise AnalysisError(f"the start model is for a {model.axis} axis; {record.path} is {record.axis}")
        cutoff, order, decimation = document_settings(s.start_model_document or {}, record.sample_rate)
        figures = start_figures(model, runs, cutoff, order, decimation)
        source = "model file, not refitted"
    else:
        ident = identify(record, validation=validation[0] if validation else None)
        model = ident.model
        figures = {k: ident.figures[k] for k in ("train_torque_nrmse", "validation_torque_nrmse")
                   if k in ident.figures}
        source = "identify's fit"
    return model_start(model), {"source": source, "parameters": model.to_dict(), "figures": figures,
                                "sample_rate_hz": record.sample_rate}


def report(result: ResidualAnalysis, out_dir: str | Path, title: str | None = None) -> list[Path]:
    """The loop's figures and summary in ``out_dir``: summary.md, diagnostics_before.png, diagnostics_after.png
    (force.png for a displacement-driven record) and hysteresis.png. Returns the paths written."""
    from hilbench.analysis.residual.report import write_report

    title = title or f"Residual loop on {result.record.path}"
    paths = list(write_report(result.loop, out_dir, title=title))
    paths.append(_hysteresis(result, out_dir, f"{title}: friction against displacement"))
    return paths


def _inertia(model: dict, fixed: float | None) -> float:
    term = model.get("inertia")
    if term is not None:
        return float(term["parameters"]["inertia"])
    return float(fixed or 0.0)


def _hysteresis(result: ResidualAnalysis, directory: str | Path, title: str) -> Path:
    """Friction against displacement on the first training run: measured (torque - J*acceleration, J of the final
    model) against the starting and the final model (measured minus each one's residual)."""
    from hilbench.analysis.identification.plots import hysteresis_figure
    from hilbench.common.units import AXIS_UNITS as AXES

    loop = result.loop
    fixed = result.fixed_inertia
    before, after = loop.signals_before, loop.signals_after
    i0, i1 = after.run_rows[0]
    j_after, j_before = _inertia(loop.model_after, fixed), _inertia(loop.model_before, fixed)
    measured = (after.command - j_after * after.acceleration)[i0:i1]
    model_after = measured - after.residual[i0:i1]
    model_before = (before.command - j_before * before.acceleration - before.residual)[i0:i1]
    added = ", ".join(loop.names_added) or "nothing added"
    return hysteresis_figure(after.position[i0:i1], measured,
                             [(f"final model (+ {added})", model_after),
                              (f"starting model ({', '.join(loop.start)})", model_before)],
                             AXES[after.axis], title, Path(directory) / "hysteresis.png", t=after.time[i0:i1])
