"""``hilbench compare RUN --validate RUN2``: every friction family fitted on one run, scored on another."""

from __future__ import annotations

from functools import partial
from pathlib import Path

#: Published models a comparison can add as a row: J (kg), Fv (N*s/m), Fc (N), offset (N). EMPS: Janot,
#: Gautier, Brunot 2019, IDIM-LS on DATA_EMPS (docs/compare.md).
OUTPUTS = ("compare.md", "compare.json", "compare_hysteresis.png", "compare_time.png", "models")
PUBLISHED = {"emps": ("EMPS published (IDIM-LS)", 95.1089, 203.5034, 20.3935, -3.1648)}


def register(subparsers) -> None:
    from hilbench.analysis.models.families import FAMILIES
    from hilbench.bench.analysis_input import add_memory_option, add_record_options

    parser = subparsers.add_parser(
        "compare",
        help="fit every friction family on RUN and compare them on the validation run",
        description="Fit Coulomb+viscous, Stribeck, Dahl, LuGre, Maxwell-slip, GMS and the continuous hysteresis "
        "model on RUN; report on RUN2 the torque error, the segmented simulation error, the parameter count "
        "and the fit time, as a Markdown table, JSON and plots (docs/compare.md).",
    )
    parser.add_argument("run", help="training run file (.h5) with 't', 'position' and 'torque' channels")
    parser.add_argument("--validate", required=True, metavar="RUN2.h5", help="validation run (same axis)")
    parser.add_argument("-o", "--output", dest="out", required=True, metavar="DIR",
                        help="output folder: compare.md, compare.json, compare_*.png, models/FAMILY.json")
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier comparison in the output folder")
    parser.add_argument("--families", default=",".join(FAMILIES),
                        help=f"comma-separated subset (default all: {','.join(FAMILIES)})")
    parser.add_argument("--published", choices=sorted(PUBLISHED), action="append", default=[],
                        help="add a published model as a row (emps: Janot et al. 2019)")
    parser.add_argument("--segment", type=float, default=1.0,
                        help="restart interval of the segmented simulation, s (default 1)")
    parser.add_argument("--max-evaluations", type=int, default=40,
                        help="output-error refinement budget per family (default 40)")
    parser.add_argument("--torque-channel", default=None,
                        help="channel holding the drive torque or force (default: torque if present, else "
                        "torque_cmd, as identify; a *_cmd channel is held over the next interval)")
    parser.add_argument("--torque-timing", choices=("auto", "hold_previous", "hold_next", "instant"),
                        default="auto", help="what torque sample k means (as in hilbench identify)")
    add_record_options(parser)
    add_memory_option(parser)
    parser.set_defaults(func=run)


def _records(args, budget: int) -> tuple:
    """(train, validation) records: whole when the comparison fits ``budget`` (bytes) at the recorded rate, else
    reduced by the largest whole factor that keeps at least 5 kHz while reading chunk by chunk, and cut to the
    first samples of each run that fit when even that does not (``compare.reading_plan``, docs/long-runs.md)."""
    from hilbench.analysis.models.compare import cost, reading_plan
    from hilbench.analysis.record import decimated_record, span_note, stream_record
    from hilbench.bench.analysis_input import load, read_decimated
    from hilbench.bench.storage import outputs
    from hilbench.common.units import mib

    opts = {"torque_channel": args.torque_channel, "timing": args.torque_timing or "auto",
            "allow_incomplete": args.allow_incomplete}
    heads = [stream_record(p, **opts)[0] for p in (args.run, args.validate)]
    plan = reading_plan(heads, budget)
    if plan is None:
        recs = tuple(load(p, args) for p in (args.run, args.validate))
    else:
        qs, span = plan
        recs = tuple(read_decimated(p, args, partial(decimated_record, max_rate=h.sample_rate / q, max_samples=span),
                                    h.n_samples)
                     for p, h, q in zip((args.run, args.validate), heads, qs, strict=True))
        how = [n for n in recs[0].notes if n.startswith("decimated") or n == span_note(recs[0])] or ["not reduced"]
        outputs.say(f"over --memory {mib(budget)} read whole ({mib(cost(sum(h.n_samples for h in heads)))}): "
                    f"compared at {recs[0].sample_rate:g} Hz, read chunk by chunk ({'; '.join(how)})")
    for p, rec in zip((args.run, args.validate), recs, strict=True):
        outputs.say(f"{p}: torque timing of {rec.torque_channel}: {rec.timing} ({rec.timing_origin})", level=2)
    return recs


def run(args) -> int:
    from hilbench.analysis.models.compare import CompareSettings, analyse, document, markdown_table
    from hilbench.analysis.models.compare_plots import report
    from hilbench.analysis.models.families import FAMILIES, published_plant
    from hilbench.analysis.models.model_file import family_document
    from hilbench.analysis.record import span_note
    from hilbench.bench.analysis_input import memory_budget
    from hilbench.bench.analysis_progress import progress_bar
    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs

    families = tuple(f.strip() for f in args.families.split(",") if f.strip())
    bad = [f for f in families if f not in FAMILIES]
    if bad or not families:
        raise BenchError(f"unknown famil{'y' if len(bad) == 1 else 'ies'} {', '.join(bad) or '(none)'}; "
                         f"choose from {', '.join(FAMILIES)}")
    if not args.segment > 0:
        raise BenchError(f"--segment must be > 0 s, got {args.segment}")
    if args.max_evaluations < 1:
        raise BenchError(f"--max-evaluations must be >= 1, got {args.max_evaluations}")
    out = Path(args.out)
    outputs.refuse_inputs({"--output": out, **{f"--output {out / name}": out / name for name in OUTPUTS}},
                          [args.run, args.validate])
    # compare.json is written last: its presence says the folder holds a whole earlier comparison
    outputs.refuse_existing("--output", out / "compare.json", args.overwrite)
    budget = memory_budget(args.memory)
    train_rec, val_rec = _records(args, budget)
    published = {}
    for key in args.published:
        name, *values = PUBLISHED[key]
        if train_rec.axis != "linear":
            raise BenchError(f"--published {key} is a linear-axis model; {args.run} is {train_rec.axis}")
        published[name] = published_plant(*values)
    settings = CompareSettings(families=families, segment=args.segment, max_nfev=args.max_evaluations,
                               published=published)
    done = iter(range(1, len(families) + 1))
    with progress_bar("compare", unit="family") as progress:
        result = analyse(train_rec, val_rec, settings, progress=lambda _family: progress(next(done), len(families)))
    train, val, timing = result.train, result.validation, train_rec.timing
    out.mkdir(parents=True, exist_ok=True)
    table = markdown_table(result)
    outputs.write_text(out / "compare.md", table)
    data = {"train": {"file": str(Path(args.run).resolve()), "samples": int(train.x.size),
                      "sample_rate_hz": train.fs, "torque_channel": train_rec.torque_channel, "torque_timing": timing,
                      "incomplete": train_rec.incomplete,
                      "read": next((n for n in train_rec.notes if n.startswith("decimated")), "whole"),
                      "span": span_note(train_rec)},
            "validation": {"file": str(Path(args.validate).resolve()), "samples": int(val.x.size),
                           "sample_rate_hz": val.fs, "incomplete": val_rec.incomplete, "span": span_note(val_rec)}}
    outputs.write_json(out / "compare.json", document(result, data), indent=2, allow_nan=False)
    (out / "models").mkdir(exist_ok=True)
    written = []
    for row in result.rows:  # one model file per fitted family (schema hilbench.friction-model/2)
        if row.fit is not None:
            figures = {f"train_{k}": v for k, v in row.train.items()} | {
                f"validation_{k}": v for k, v in row.validation.items()} | {"fit_time_s": row.fit_time_s}
            doc = family_document(row.fit, method="compare", data=data, figures=figures,
                                  settings={"segment_s": args.segment, "max_evaluations": args.max_evaluations})
            outputs.write_json(out / "models" / f"{row.name}.json", doc, indent=2, allow_nan=False)
            written.append(f"{row.name}.json")
    print(table, end="")
    for p in report(result, out):
        print(f"plot: {p}")
    print(f"-> {out / 'compare.md'}, {out / 'compare.json'}, {out / 'models'}/ ({', '.join(written) or 'no model'})")
    return 0
