"""``hilbench compare RUN --validate RUN2``: every friction family fitted on one run, scored on another."""

from __future__ import annotations

from pathlib import Path

#: Published models a comparison can add as a row: J (kg), Fv (N*s/m), Fc (N), offset (N). EMPS: Janot,
#: Gautier, Brunot 2019, IDIM-LS on DATA_EMPS (docs/compare.md).
OUTPUTS = ("compare.md", "compare.json", "compare_hysteresis.png", "compare_time.png", "models")
PUBLISHED = {"emps": ("EMPS published (IDIM-LS)", 95.1089, 203.5034, 20.3935, -3.1648)}


def register(subparsers) -> None:
    from hilbench.analysis.models.families import FAMILIES
    from hilbench.bench.analysis_input import add_hold_out_option, add_memory_option, add_record_options

    parser = subparsers.add_parser(
        "compare",
        help="fit every friction family on RUN and compare them on the validation run",
        description="Fit Coulomb+viscous, Stribeck, Dahl, LuGre, Maxwell-slip, GMS and the continuous hysteresis "
        "model on RUN; report on RUN2 the torque error, the segmented simulation error, the parameter count "
        "and the fit time, as a Markdown table, JSON and plots (docs/compare.md).",
    )
    parser.add_argument("run", help="training run file (.h5) with 't', 'position' and 'torque' channels")
    parser.add_argument("--validate", metavar="RUN2.h5", help="validation run (same axis); or --hold-out")
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
    add_hold_out_option(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    from hilbench.analysis.models.compare import CompareSettings, cost, markdown_table
    from hilbench.analysis.models.families import FAMILIES, published_plant
    from hilbench.analysis.protocol import WHOLE
    from hilbench.bench.analysis_input import memory_budget, read_runs
    from hilbench.bench.analysis_progress import progress_bar
    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs
    from hilbench.common.units import mib

    families = tuple(f.strip() for f in args.families.split(",") if f.strip())
    bad = [f for f in families if f not in FAMILIES]
    if bad or not families:
        raise BenchError(f"unknown famil{'y' if len(bad) == 1 else 'ies'} {', '.join(bad) or '(none)'}; "
                         f"choose from {', '.join(FAMILIES)}")
    if not args.segment > 0:
        raise BenchError(f"--segment must be > 0 s, got {args.segment}")
    if args.max_evaluations < 1:
        raise BenchError(f"--max-evaluations must be >= 1, got {args.max_evaluations}")
    if not args.validate and args.hold_out is None:
        raise BenchError("compare scores every family on held-out data: give --validate RUN2.h5 or --hold-out 0.3")
    out = Path(args.out)
    outputs.refuse_inputs({"--output": out, **{f"--output {out / name}": out / name for name in OUTPUTS}},
                          [args.run, args.validate])
    # compare.json is written last: its presence says the folder holds a whole earlier comparison
    outputs.refuse_existing("--output", out / "compare.json", args.overwrite)
    budget = memory_budget(args.memory)
    with progress_bar("read") as progress:
        entry, inputs, val_inputs = read_runs("compare", args, [args.run], [args.validate], budget, progress)
    train_rec = inputs.record
    if inputs.reads[0] != WHOLE:
        samples = train_rec.n_samples + val_inputs.record.n_samples
        outputs.say(f"over --memory {mib(budget)} read whole ({mib(cost(samples))} or more): compared at "
                    f"{train_rec.sample_rate:g} Hz, read chunk by chunk ({inputs.reads[0]})")
    for p, rec in ((args.run, train_rec), (args.validate or f"{args.run} (held-out tail)", val_inputs.record)):
        outputs.say(f"{p}: torque timing of {rec.torque_channel}: {rec.timing} ({rec.timing_origin})", level=2)
    published = {}
    for key in args.published:
        name, *values = PUBLISHED[key]
        if train_rec.axis != "linear":
            raise BenchError(f"--published {key} is a linear-axis model; {args.run} is {train_rec.axis}")
        published[name] = published_plant(*values)
    settings = CompareSettings(families=families, segment=args.segment, max_nfev=args.max_evaluations,
                               published=published)
    with progress_bar("compare", unit="family") as progress:
        result = entry.analyse(inputs, settings, val_inputs, progress=progress)
    files, _ = entry.report(result, out)
    print(markdown_table(result.value), end="")
    for p in files:
        if p.suffix == ".png":
            print(f"plot: {p}")
    written = [p.name for p in files if p.parent.name == "models"]
    print(f"-> {out / 'compare.md'}, {out / 'compare.json'}, {out / 'models'}/ ({', '.join(written) or 'no model'})")
    return 0
