"""The analysis protocol: every analysis has the same three entry points, and one line in :data:`ANALYSES`.

- ``read(paths, options) -> Inputs``: the runs, read from their files within ``options.memory`` bytes. The
  analysis chooses how: whole, chunk by chunk (streamed), or decimated; when nothing fits it refuses in one line
  (:class:`AnalysisError`) before reading any sample.
- ``analyse(inputs, settings, validation=None, progress=None) -> Result``: ``validation`` (an :class:`Inputs` of
  runs never fitted) is checked against the training runs by :func:`check_validation`, on the fields the entry
  names (:attr:`Analysis.matches`); ``progress(done, total)`` reports the work.
- ``report(result, out_dir) -> (files written, summary)``: the analysis's files in ``out_dir`` (none when it is
  None) and a flat JSON-able summary whose keys are the figures' names (a campaign row takes them as columns).

:data:`ANALYSES` maps a name to where its entry lives, ``(module, attribute)``, imported on first use, as
python-can's backend table does; the CLI (``hilbench analyse --steps``, ``hilbench report``), the GUI's run
browser, the campaign steps and the campaign page iterate it. A new analysis is a package with an
:class:`Analysis` entry and one line here, or one :func:`register` call (docs/architecture.md, "The analysis
protocol").
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hilbench.analysis.errors import AnalysisError

if TYPE_CHECKING:
    from hilbench.analysis.record import Record

#: ``progress(done, total)``: the only way an analysis reports progress (the CLI draws a bar, the GUI a status)
Progress = Callable[[int, int], None]
#: a chunk source: a callable returning a fresh iterator of ``(position, torque)`` pairs (record.stream_record)
ChunkSource = Callable[[], Any]

#: how a run read whole says so (``Inputs.reads``; the model file's ``data.train.read``)
WHOLE = "whole"
STREAMED = "chunk by chunk (--memory)"


@dataclass(frozen=True)
class ReadOptions:
    """How ``read`` reads: ``memory`` (bytes, None: no budget), the torque channel (None: the loader's choice),
    its timing (``auto``: the file's), whether an incomplete record is let through, and ``progress(done, total)``
    for a long read (samples)."""

    memory: int | None = None
    torque_channel: str | None = None
    timing: str = "auto"
    allow_incomplete: bool = False
    progress: Progress | None = None

    def loader(self) -> dict[str, Any]:
        """The options of :func:`hilbench.analysis.record.load_record` and its streamed and decimated twins."""
        return {"torque_channel": self.torque_channel, "timing": self.timing or "auto",
                "allow_incomplete": self.allow_incomplete}


@dataclass
class Inputs:
    """Runs as an analysis reads them, one entry per run in the order given: ``records`` (arrays loaded, or the
    header alone, ``position`` None, when the run is streamed), ``sources`` (the chunk source of a streamed run,
    else None), ``reads`` (how each was read: :data:`WHOLE`, :data:`STREAMED`, or the decimation's note),
    and ``budget`` (bytes the read kept to; None: none)."""

    records: list[Record]
    sources: list[ChunkSource | None] = field(default_factory=list)
    reads: list[str] = field(default_factory=list)
    budget: int | None = None

    def __post_init__(self) -> None:
        n = len(self.records)
        self.sources = list(self.sources) or [None] * n
        self.reads = list(self.reads) or [WHOLE] * n

    @property
    def record(self) -> Record:
        """The first run's record (the training run of a one-run analysis)."""
        if not self.records:
            raise AnalysisError("no run was read")
        return self.records[0]

    @property
    def paths(self) -> list[Path]:
        return [Path(r.path) for r in self.records]

    @property
    def streamed(self) -> bool:
        """Whether a run is read chunk by chunk (its arrays are not in memory)."""
        return any(r.position is None for r in self.records)

    def part(self, start: int, stop: int | None = None) -> Inputs:
        """Runs ``start:stop`` as their own Inputs (the budget is the whole read's)."""
        s = slice(start, stop)
        return Inputs(self.records[s], self.sources[s], self.reads[s], self.budget)


def whole(paths: Sequence[str | Path], options: ReadOptions, heads: Sequence | None = None,
          **loader: Any) -> Inputs:
    """Every run read whole by the one loader (:func:`hilbench.analysis.record.load_record`) with ``options`` and
    the analysis's own ``loader`` keywords (channels, protocol arrays, ...). ``heads``: the runs'
    :func:`~hilbench.analysis.record.stream_record` answers, read with ``options`` alone; a host-clocked run
    came back whole there (resampled onto the uniform grid) and is not read again."""
    from hilbench.analysis.record import load_record

    kw = {**options.loader(), **loader}
    done = [h if src is None and not loader else None for h, src in heads] if heads else [None] * len(paths)
    return Inputs([d if d is not None else load_record(p, **kw) for p, d in zip(paths, done, strict=True)],
                  budget=options.memory)


def one_run_whole(paths: Sequence[str | Path], options: ReadOptions, what: str, fixed: int, per_sample: int,
                  **loader: Any) -> Inputs:
    """One short run read whole (:func:`whole` with ``loader``), refused in one line before its samples are read
    when ``fixed + per_sample * samples`` bytes exceed ``options.memory``; ``what`` names the analysis."""
    from hilbench.analysis.record import stream_record
    from hilbench.common.units import mib

    if len(paths) != 1:
        raise AnalysisError(f"{what} reads one run, got {len(paths)}")
    n = stream_record(paths[0], allow_incomplete=options.allow_incomplete)[0].n_samples
    need = fixed + per_sample * n
    if options.memory is not None and need > options.memory:
        raise AnalysisError(f"{paths[0]}: {n} samples need about {mib(need)} read whole, over --memory "
                            f"{mib(options.memory)}: raise --memory")
    return whole(paths, options, **loader)


def write_json(path: Path, document: Any) -> Path:
    """``document`` as strict, indented JSON at ``path``, complete or absent (output_files.atomic_path)."""
    from hilbench.analysis.output_files import atomic_path, dumps

    with atomic_path(path) as tmp:
        tmp.write_text(dumps(document, indent=2))
    return path


def read_runs(entry: Analysis, paths: Sequence[str | Path], validation: Sequence[str | Path],
              options: ReadOptions) -> tuple[Inputs, Inputs | None]:
    """The training runs and the validation runs read together by ``entry.read`` (one memory budget for all of
    them, as the analysis holds them together), then parted: (training, validation or None)."""
    paths, validation = [p for p in paths if p], [p for p in validation if p]
    both = entry.read([*paths, *validation], options)
    return both.part(0, len(paths)), (both.part(len(paths)) if validation else None)


def held_out(inputs: Inputs, fraction: float) -> tuple[Inputs, Inputs | None]:
    """(head, tail): the last ``fraction`` of the one run's samples held out as the validation input
    (:func:`hilbench.analysis.record_split.split`; fraction 0: the whole run and no tail). A streamed run is
    refused in one line: its tail would have to be read apart."""
    from hilbench.analysis.record_split import split

    if len(inputs.records) != 1:
        raise AnalysisError(f"a held-out tail is cut from one run, got {len(inputs.records)}")
    if inputs.streamed:
        raise AnalysisError(f"{inputs.record.path}: a held-out tail needs the run in memory, and it is read chunk by "
                            "chunk (over the memory budget): raise the budget, or validate on a run of its own")
    head, tail = split(inputs.record, fraction)
    wrap = lambda r: Inputs([r], reads=inputs.reads, budget=inputs.budget)  # noqa: E731
    return wrap(head), (wrap(tail) if tail is not None else None)


#: what a validation run may have to share with the training run, and how a mismatch is said
MATCHES = {
    "axis": ("axis", "a {v} axis; {p} is {t}"),
    "kind": ("kind", "a {v} record; {p} is {t}"),
    "timing": ("timing", "torque timing {v}; {p}: {t}; give both runs the same --torque-timing"),
    "sample_rate": ("sample_rate", "sampled at {v:g} Hz; {p}: {t:g} Hz"),
}


def check_validation(inputs: Inputs, validation: Inputs, needs: Sequence[str]) -> None:
    """The one check that each validation run goes with the (first) training run: equal on every field of
    ``needs`` (keys of :data:`MATCHES`: axis, record kind, torque timing, sample rate). One-line AnalysisError."""
    train = inputs.record
    for rec in validation.records:
        for need in needs:
            attr, text = MATCHES[need]
            v, t = getattr(rec, attr), getattr(train, attr)
            same = abs(v - t) <= 1e-9 * abs(t) if need == "sample_rate" else v == t
            if not same:
                raise AnalysisError(f"validation run {rec.path}: " + text.format(v=v, t=t, p=train.path))


def provenance(inputs: Inputs, validation: Inputs | None = None) -> dict[str, Any]:
    """The ``data`` block of a model file or a report (docs/model-file.md): which runs were read, how, and what
    of them (samples, rate, axis, torque channel and timing, completeness, a bounded span)."""
    from hilbench.analysis.record import span_note

    def entry(rec: Record, read: str) -> dict[str, Any]:
        return {"file": str(Path(rec.path).resolve()), "samples": int(rec.n_samples),
                "sample_rate_hz": float(rec.sample_rate), "axis": rec.axis, "read": read,
                "torque_channel": rec.torque_channel, "torque_timing": rec.timing, "incomplete": rec.incomplete,
                "span": span_note(rec)}

    data = {"train": entry(inputs.record, inputs.reads[0])}
    if validation is not None and validation.records:
        data["validation"] = entry(validation.record, validation.reads[0])
    return data


@dataclass
class Result:
    """An analysis's result with what it was computed from: ``value`` (the analysis's own result object), the
    ``inputs``, the ``validation`` inputs and the ``settings``."""

    name: str
    value: Any
    inputs: Inputs
    validation: Inputs | None
    settings: Any


@dataclass(frozen=True)
class Analysis:
    """One registry entry. ``read``, ``compute`` (inputs, settings, validation, progress) -> the analysis's value,
    ``summarise`` (Result) -> flat dict of figures, ``write`` (Result, folder) -> files; ``settings``: its settings
    class (constructible without arguments); ``matches``: what a validation run must share with the training run
    (:data:`MATCHES`), None when the analysis takes no validation; ``needs_validation``: it scores only on one;
    ``protocols``: run protocols a campaign step applies it to; ``columns``: its summary's columns, name -> (Arrow
    type, unit)."""

    name: str
    title: str
    read: Callable[[Sequence[str | Path], ReadOptions], Inputs]
    compute: Callable[[Inputs, Any, Inputs | None, Progress | None], Any]
    summarise: Callable[[Result], dict[str, Any]]
    settings: type
    write: Callable[[Result, Path], list[Path]] | None = None
    matches: tuple[str, ...] | None = None
    needs_validation: bool = False
    protocols: tuple[str, ...] = ()
    columns: dict[str, tuple[str, str]] = field(default_factory=dict)

    def analyse(self, inputs: Inputs, settings: Any = None, validation: Inputs | None = None,
                progress: Progress | None = None) -> Result:
        """The analysis of ``inputs`` (see the module docstring)."""
        settings = self.settings() if settings is None else settings
        if validation is not None:
            if self.matches is None:
                raise AnalysisError(f"{self.name} takes no validation run")
            check_validation(inputs, validation, self.matches)
        elif self.needs_validation:
            raise AnalysisError(f"{self.name} scores its models on a validation run: give one")
        return Result(self.name, self.compute(inputs, settings, validation, progress), inputs, validation, settings)

    def report(self, result: Result, out_dir: str | Path | None = None) -> tuple[list[Path], dict[str, Any]]:
        """(files written into ``out_dir``, created; none when it is None, the flat summary)."""
        files: list[Path] = []
        if out_dir is not None and self.write is not None:
            Path(out_dir).mkdir(parents=True, exist_ok=True)
            files = list(self.write(result, Path(out_dir)))
        return files, self.summarise(result)


#: every analysis: name -> (module, attribute) of its :class:`Analysis` entry, imported on first use
ANALYSES: dict[str, tuple[str, str]] = {
    "identify": ("hilbench.analysis.identification.entry", "ENTRY"),
    "compare": ("hilbench.analysis.models.entry", "ENTRY"),
    "residual": ("hilbench.analysis.residual.entry", "ENTRY"),
    "presliding": ("hilbench.analysis.presliding.entry", "ENTRY"),
    "afrf": ("hilbench.analysis.afrf.entry", "ENTRY"),
    "skeleton": ("hilbench.analysis.skeleton.entry", "ENTRY"),
    "compensation": ("hilbench.analysis.compensation.entry", "ENTRY"),
    "breakaway": ("hilbench.analysis.breakaway.entry", "ENTRY"),
}
_LOADED: dict[str, Analysis] = {}


def register(name: str, module: str, attribute: str = "ENTRY") -> None:
    """Add (or replace) the analysis ``name`` whose entry is ``module.attribute``: the one line a new analysis
    needs where it cannot edit :data:`ANALYSES`."""
    ANALYSES[name] = (module, attribute)
    _LOADED.pop(name, None)


def entry(name: str) -> Analysis:
    """The entry of analysis ``name``; a one-line AnalysisError naming the known ones."""
    if name not in ANALYSES:
        raise AnalysisError(f"unknown analysis {name!r} (available: {', '.join(ANALYSES)})")
    if name not in _LOADED:
        module, attribute = ANALYSES[name]
        found = getattr(importlib.import_module(module), attribute)
        if not isinstance(found, Analysis) or found.name != name:
            raise AnalysisError(f"{module}.{attribute} is not the entry of analysis {name!r}")
        _LOADED[name] = found
    return _LOADED[name]


def entries() -> dict[str, Analysis]:
    """Every registered entry, in the registry's order."""
    return {name: entry(name) for name in ANALYSES}
