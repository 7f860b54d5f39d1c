"""The comparison's entry in the analysis registry (hilbench.analysis.protocol): read the training and the
validation run within a memory budget (whole, else decimated to at least 5 kHz, else a bounded span:
compare.reading_plan), analyse (compare.analyse), report (compare.md, compare.json, the plots and one model file
per fitted family)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from hilbench.analysis.models.compare import CompareSettings
from hilbench.analysis.protocol import WHOLE, Analysis, Inputs, ReadOptions, Result, whole, write_json


def read(paths: Sequence[str | Path], options: ReadOptions) -> Inputs:
    """The runs whole when the comparison fits ``options.memory`` at the recorded rate, else reduced by the
    largest whole factor that keeps at least 5 kHz, read chunk by chunk, and cut to the first samples of each run
    that fit when even that does not; a one-line refusal before any sample is read when nothing fits."""
    from hilbench.analysis.models.compare import reading_plan
    from hilbench.analysis.record import decimated_record, span_note, stream_record

    read_heads = [stream_record(p, **options.loader()) for p in paths]
    heads = [h for h, _ in read_heads]
    plan = reading_plan(heads, options.memory) if options.memory is not None else None
    if plan is None:
        return whole(paths, options, read_heads)
    qs, span = plan
    records, done = [], 0
    total = sum(h.n_samples for h in heads)
    for p, h, q in zip(paths, heads, qs, strict=True):
        tick = (lambda n, base=done: options.progress(base + n, total)) if options.progress else None
        records.append(decimated_record(p, h.sample_rate / q, max_samples=span, progress=tick, **options.loader()))
        done += h.n_samples
    reads = ["; ".join(n for n in r.notes if n.startswith("decimated") or n == span_note(r)) or WHOLE
             for r in records]
    return Inputs(records, reads=reads, budget=options.memory)


def compute(inputs: Inputs, settings: CompareSettings, validation: Inputs, progress=None):
    from hilbench.analysis.models.compare import analyse

    n = len(settings.families)
    done = iter(range(1, n + 1))
    tick = (lambda _family: progress(next(done), n)) if progress is not None else None
    return analyse(inputs.record, validation.record, settings, progress=tick)


def summarise(result: Result) -> dict[str, Any]:
    """The family with the lowest validation torque NRMSE (``model`` and its figures), and every family's figures
    as ``<family>.<figure>`` (fractions; failed families: ``<family>.error``)."""
    import math

    from hilbench.analysis.errors import AnalysisError

    rows = result.value.rows
    out: dict[str, Any] = {}
    for r in rows:
        if r.error is not None:
            out[f"{r.name}.error"] = r.error
            continue
        out.update({f"{r.name}.train_{k}": v for k, v in r.train.items()})
        out.update({f"{r.name}.validation_{k}": v for k, v in r.validation.items()})
    scored = [r for r in rows if r.error is None and math.isfinite(r.validation["torque_nrmse"])]
    if not scored:
        raise AnalysisError("compare: no family could be fitted (" + "; ".join(
            f"{r.name}: {r.error}" for r in rows) + ")")
    best = min(scored, key=lambda r: r.validation["torque_nrmse"])
    return {"model": best.name, "train_torque_nrmse": best.train["torque_nrmse"],
            "validation_torque_nrmse": best.validation["torque_nrmse"],
            "validation_position_nrmse_segmented": best.validation["position_nrmse_segmented"], **out}


def family_documents(result: Result) -> dict[str, dict]:
    """One model file per fitted family (schema hilbench.friction-model/2), with the runs' provenance."""
    from hilbench.analysis.models.model_file import family_document
    from hilbench.analysis.protocol import provenance

    data = provenance(result.inputs, result.validation)
    s = result.settings
    docs = {}
    for row in result.value.rows:
        if row.fit is not None:
            figures = {f"train_{k}": v for k, v in row.train.items()} | {
                f"validation_{k}": v for k, v in row.validation.items()} | {"fit_time_s": row.fit_time_s}
            docs[row.name] = family_document(row.fit, method="compare", data=data, figures=figures,
                                             settings={"segment_s": s.segment, "max_evaluations": s.max_nfev})
    return docs


def write(result: Result, out: Path) -> list[Path]:
    """compare.md, the plots, models/FAMILY.json, then compare.json last: its presence says the folder holds a
    whole comparison."""
    from hilbench.analysis.models.compare import document, markdown_table
    from hilbench.analysis.models.compare_plots import report
    from hilbench.analysis.output_files import atomic_path
    from hilbench.analysis.protocol import provenance

    md = out / "compare.md"
    with atomic_path(md) as tmp:
        tmp.write_text(markdown_table(result.value))
    files = [md]
    (out / "models").mkdir(exist_ok=True)
    files += [write_json(out / "models" / f"{name}.json", doc) for name, doc in family_documents(result).items()]
    files += list(report(result.value, out))
    files.append(write_json(out / "compare.json", document(result.value, provenance(result.inputs,
                                                                                         result.validation))))
    return files


COLUMNS = {
    "model": ("string", ""),
    "train_torque_nrmse": ("float64", "1"), "validation_torque_nrmse": ("float64", "1"),
    "validation_position_nrmse_segmented": ("float64", "1"),
}

ENTRY = Analysis("compare", "Model comparison (every friction family)", read, compute, summarise,
                 CompareSettings, write=write, matches=("axis", "kind", "timing"), needs_validation=True,
                 protocols=("identification", "chirp"), columns=COLUMNS)
