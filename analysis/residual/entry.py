"""The residual loop's entry in the analysis registry (hilbench.analysis.protocol): read each run reduced to the
loop's rate chunk by chunk (record_analysis.read; a bounded span over the memory budget), analyse
(record_analysis.analyse), report (residual.json, summary.md and the figures)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from hilbench.analysis.protocol import WHOLE, Analysis, Inputs, ReadOptions, Result, whole, write_json
from hilbench.analysis.residual.record_analysis import ResidualSettings

#: bytes per sample of a run held whole at its recorded rate (t, position, torque and the loader's copies)
WHOLE_BYTES_PER_SAMPLE = 48


def read(paths: Sequence[str | Path], options: ReadOptions) -> Inputs:
    """Every run whole when it fits ``options.memory`` at its recorded rate (the loop reduces it to at most
    2 kHz), else reduced to 2 kHz while read chunk by chunk (the same bit for bit as reducing the whole record),
    cut to the first samples of each run that fit ``options.memory`` (record_analysis.span_for); a
    one-line refusal before any sample is read when not even a short span fits."""
    from hilbench.analysis.record import span_note, stream_record
    from hilbench.analysis.residual import record_analysis

    read_heads = [stream_record(p, **options.loader()) for p in paths]
    heads = [h for h, _ in read_heads]
    span = record_analysis.span_for(heads, options.memory) if options.memory is not None else None
    loaded = sum(record_analysis.analysed_samples(h.n_samples, h.sample_rate) for h in heads)
    if options.memory is None or (span is None and record_analysis.cost(loaded) + WHOLE_BYTES_PER_SAMPLE * sum(
            h.n_samples for h in heads) <= options.memory):
        # whole at the recorded rate (analyse reduces it, the same bit for bit): a held-out tail is then cut at
        # the recorded rate, as the same run written as two files reads
        return whole(paths, options, read_heads)
    records, done = [], 0
    total = sum(h.n_samples for h in heads)
    for p, h in zip(paths, heads, strict=True):
        tick = (lambda n, base=done: options.progress(base + n, total)) if options.progress else None
        records.append(record_analysis.read(p, max_samples=span, progress=tick, **options.loader()))
        done += h.n_samples
    reads = [span_note(r) or next((n for n in r.notes if n.startswith("decimated")), WHOLE) for r in records]
    return Inputs(records, reads=reads, budget=options.memory)


def compute(inputs: Inputs, settings: ResidualSettings, validation: Inputs | None, progress=None):
    from hilbench.analysis.residual.record_analysis import analyse

    return analyse(inputs.record, settings, validation=validation.records if validation is not None else ())


def summarise(result: Result) -> dict[str, Any]:
    """The final model's terms, the validation torque NRMSE of the start and the final model (fractions; blocked
    cross-validation without a validation run), the validation position NRMSE, the verdict, and the start model's
    own figure as identify defines it."""
    res = result.value
    loop = res.loop
    before, after = loop.error_before["validation"], loop.error_after["validation"]
    out = {"model": ",".join([*loop.start, *loop.names_added]),
           "validation_torque_nrmse_start": before["torque_nrmse"],
           "validation_torque_nrmse": after["torque_nrmse"],
           "validation_position_nrmse": after.get("position_nrmse"), "verdict": loop.verdict}
    if (figure := res.start_figure()) is not None:
        out[f"start_model_{figure[0]}_torque_nrmse"] = figure[1]
    return out


def write(result: Result, out: Path) -> list[Path]:
    from hilbench.analysis.protocol import provenance
    from hilbench.analysis.residual.record_analysis import report
    from hilbench.analysis.residual.report import report_dict

    path = write_json(out / "residual.json", report_dict(result.value.loop, provenance(result.inputs,
                                                                                       result.validation)))
    return [path, *report(result.value, out)]


COLUMNS = {
    "model": ("string", ""), "validation_torque_nrmse_start": ("float64", "1"),
    "validation_torque_nrmse": ("float64", "1"), "validation_position_nrmse": ("float64", "1"),
    "verdict": ("string", ""),
}

ENTRY = Analysis("residual", "Residual loop", read, compute, summarise, ResidualSettings, write=write,
                 matches=("axis", "kind", "timing"), protocols=("identification", "chirp"), columns=COLUMNS)
