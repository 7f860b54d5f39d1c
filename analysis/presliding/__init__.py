"""Presliding analysis of displacement-driven records (force against an imposed displacement): reversal points,
the Masing and wiping-out checks on the measured data, force-from-displacement identification (Maxwell-slip by
NNLS), derived quantities with uncertainties and what the encoder resolution no longer resolves.
See docs/presliding.md.

The record-level front door: :func:`analyse` (a :class:`hilbench.analysis.record.Record` read whole),
:func:`analyse_stream` (the run file read chunk by chunk, :mod:`.streamed`) and :func:`report` (the output files).
``hilbench presliding``, the GUI and scripts call these; the array function is
:func:`hilbench.analysis.presliding.analyse.analyse`.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

# The submodules ``analyse`` and ``report`` share their names with the front-door functions below. Importing them
# first makes the functions, defined after, the package's attributes for good (a submodule sets its attribute on
# the package only when it is first imported); ``from hilbench.analysis.presliding.analyse import analyse`` still
# gives the array function.
from hilbench.analysis.presliding import analyse as _arrays  # noqa: F401
from hilbench.analysis.presliding import report as _document  # noqa: F401
from hilbench.common.runfile.schema import POSITION_CMD, SAMPLE_INDEX, VELOCITY_CMD

if TYPE_CHECKING:
    from hilbench.analysis.channel_windows import Progress
    from hilbench.analysis.presliding.analyse import PreslidingResult
    from hilbench.analysis.presliding.identify import PreslidingSettings
    from hilbench.analysis.record import Record

#: run-file channels that hold no force: refused as the force channel
NOT_FORCE = ("t", SAMPLE_INDEX, "position", POSITION_CMD, "velocity", VELOCITY_CMD, "counts")
#: fewer turning points than this leave the memory-rule checks and the bootstrap's blocks without a nested loop
MIN_REVERSALS = 4
#: output files of :func:`report`
OUTPUT_FILES = ("presliding.json", "summary.md", "reversals.csv", "loops.png", "virgin.png")
#: bytes per sample of the whole read (t, x, force and the raw-path copies of the step and edge searches)
ARRAY_BYTES_PER_SAMPLE = 120
ARRAY_BYTES_FIXED = 160 << 20
#: the streamed read: one chunk, the kept second differences (NOISE_SAMPLES) and the blocks
STREAM_BYTES = 240 << 20


def array_cost(samples: int) -> int:
    """Estimated peak bytes of :func:`analyse` on a record of ``samples``."""
    return ARRAY_BYTES_FIXED + ARRAY_BYTES_PER_SAMPLE * int(samples)


def stream_cost(samples: int) -> int:
    """Estimated peak bytes of :func:`analyse_stream` (bounded whatever the record's length)."""
    return STREAM_BYTES


def _checked(record: Record, settings: PreslidingSettings | None, inertia: float | None) -> PreslidingSettings:
    """The settings with the inertia resolved (given, else the protocol's), after the record checks."""
    from hilbench.analysis.errors import AnalysisError
    from hilbench.analysis.presliding.identify import PreslidingSettings
    from hilbench.analysis.presliding.report import protocol_inertia

    if record.kind != "displacement-driven":
        raise AnalysisError(f"{record.path}: a {record.kind} record; presliding needs a displacement-driven one "
                            "(hilbench import ... --record displacement-driven, or a presliding protocol run)")
    if record.torque_channel in NOT_FORCE:  # a position taken as the force overflowed the fit (issue 30 item 12)
        raise AnalysisError(f"--torque-channel {record.torque_channel}: {record.torque_channel!r} is not a force or "
                            "torque channel")
    if inertia is None:
        inertia = protocol_inertia(record.protocol_params, str(record.path))
    return replace(settings or PreslidingSettings(), inertia=inertia)


def reversal_warning(result: PreslidingResult) -> str | None:
    """One line when the record has fewer than :data:`MIN_REVERSALS` turning points."""
    k = int(result.reversals.size)
    if k >= MIN_REVERSALS:
        return None
    return (f"only {k} reversal(s): the Masing and wiping-out checks and the bootstrap need {MIN_REVERSALS} or more "
            "(a virgin ramp and nested loops); play more turning points (hilbench run presliding --amplitudes "
            "A1 A2 A3 A4 ...)")


def _finish(result: PreslidingResult) -> PreslidingResult:
    """The result with the reversal warning after the analysis's own (e.g. the span of a long record)."""
    line = reversal_warning(result)
    result.warnings = [*result.warnings, line] if line else list(result.warnings)
    return result


def analyse(record: Record, settings: PreslidingSettings | None = None, *, inertia: float | None = None,
            counts_per_rev: float | None = None, hysteresis: float | None = None, fraction: float = 0.9,
            replicates: int = 20) -> PreslidingResult:
    """The presliding analysis of a displacement-driven record read whole. ``inertia`` (kg*m^2 or kg): J*x''
    subtracted, None = the presliding protocol's parameter (else 0); ``counts_per_rev``: None = the record's
    calibration; the rest as :func:`hilbench.analysis.presliding.analyse.analyse`."""
    from hilbench.analysis.presliding.analyse import analyse as on_arrays

    settings = _checked(record, settings, inertia)
    cpr = counts_per_rev if counts_per_rev is not None else record.calibration.get("counts_per_rev")
    return _finish(on_arrays(record.t, record.position, record.torque, record.sample_rate, record.axis, settings,
                             counts_per_rev=cpr, hysteresis=hysteresis, fraction=fraction, replicates=replicates))


def analyse_stream(path: str | Path, settings: PreslidingSettings | None = None, *, inertia: float | None = None,
                   counts_per_rev: float | None = None, hysteresis: float | None = None, fraction: float = 0.9,
                   replicates: int = 20, torque_channel: str | None = None, timing: str = "auto",
                   allow_incomplete: bool = False, chunk: int | None = None, progress: Progress | None = None
                   ) -> tuple[PreslidingResult, Record]:
    """:func:`analyse` on the run file read chunk by chunk (:mod:`.streamed`, what is exact and what is not):
    (result, the record without its arrays). A host-clocked run (resampled whole) is read whole."""
    from hilbench.analysis.channel_windows import CHUNK, ChannelReader
    from hilbench.analysis.presliding.streamed import analyse_stream as on_chunks
    from hilbench.analysis.record import load_record, stream_record

    record, source = stream_record(path, torque_channel=torque_channel, timing=timing,
                                   allow_incomplete=allow_incomplete)
    if source is None:
        record = load_record(path, torque_channel=torque_channel, timing=timing, allow_incomplete=allow_incomplete)
        return analyse(record, settings, inertia=inertia, counts_per_rev=counts_per_rev, hysteresis=hysteresis,
                       fraction=fraction, replicates=replicates), record
    settings = _checked(record, settings, inertia)
    cpr = counts_per_rev if counts_per_rev is not None else record.calibration.get("counts_per_rev")
    with ChannelReader(path) as reader:
        res = on_chunks(reader, record.sample_rate, record.axis, record.torque_channel, settings,
                        counts_per_rev=cpr, hysteresis=hysteresis, fraction=fraction, replicates=replicates,
                        chunk=chunk or CHUNK, progress=progress)
    return _finish(res), record


def document(result: PreslidingResult, record: Record, read: str = "whole") -> dict:
    """The JSON document (schema hilbench-presliding 3, docs/presliding.md) with the record's completeness, how it
    was read and the warnings."""
    from hilbench.analysis.presliding.report import report as as_document

    doc = as_document(result, str(record.path), str(record.torque_channel))
    doc["incomplete"] = record.incomplete
    doc["read"] = read
    doc["warnings"] = list(result.warnings)
    return doc


def report(result: PreslidingResult, out_dir: str | Path, doc: dict) -> list[Path]:
    """:data:`OUTPUT_FILES` in ``out_dir`` (created): the document (:func:`document`), the summary, the reversal
    table and the figures. Returns the paths written."""
    from hilbench.analysis.output_files import atomic_path, dumps, save_figure
    from hilbench.analysis.presliding.analyse import figures, table_csv, table_markdown
    from hilbench.analysis.presliding.report import summary_markdown

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    texts = {"presliding.json": dumps(doc, indent=2), "reversals.csv": table_csv(result),
             "summary.md": summary_markdown(doc, table_markdown(result))}
    written = []
    for name, text in texts.items():
        with atomic_path(out / name) as tmp:
            tmp.write_text(text)
        written.append(out / name)
    for key, fig in figures(result).items():
        written.append(save_figure(fig, out / f"{key}.png", dpi=110))
    return written
