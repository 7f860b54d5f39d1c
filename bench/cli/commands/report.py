"""``hilbench report NAME RUN``: any analysis of the registry on a run, by its entry alone (read, analyse, report).

The door of an analysis that has no command of its own (the compensation metrics of a recorded compensated run,
the break-away probe of a probe run, an analysis a lab registered) and the same door for those that have one: the
entry's defaults as settings, its files in ``-o``, its summary as JSON (``--json``), the figures the campaign rows
and the GUI show.
"""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    from hilbench.analysis.protocol import ANALYSES
    from hilbench.bench.analysis_input import add_hold_out_option, add_memory_option, add_record_options

    p = sub.add_parser(
        "report", help="any registered analysis of a run, with its defaults: files and a JSON summary",
        description="Read RUN through the analysis's registry entry (within --memory), analyse it with the "
        "entry's default settings (validated on --validate or on the run's last --hold-out fraction when the "
        "analysis takes a validation run), write its files into -o and its summary (the figures a campaign row "
        "and the GUI show; SI units, NRMSE as fractions) as JSON. Analyses: " + ", ".join(ANALYSES) + ".")
    p.add_argument("analysis", metavar="NAME", help=f"registered analysis ({', '.join(ANALYSES)})")
    p.add_argument("run", help="run file (.h5)")
    p.add_argument("--validate", default=None, metavar="RUN.h5", help="validation run (analyses that take one)")
    add_hold_out_option(p)
    p.add_argument("-o", "--output", type=str, default=None, metavar="DIR", help="folder for the analysis's files")
    p.add_argument("--json", default=None, metavar="OUT.json", help="the summary as JSON ('-': stdout)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    add_record_options(p)
    add_memory_option(p)
    p.set_defaults(func=run)


def summary_lines(title: str, summary: dict) -> list[str]:
    """The summary as text, one figure a line; an NRMSE (a fraction in the JSON) in percent (docs/metrics.md)."""
    from hilbench.common.metrics import UNIT, is_fraction, percent

    lines = [title]
    for key, value in summary.items():
        if isinstance(value, float) and is_fraction(key):
            lines.append(f"  {key.replace('nrmse', 'NRMSE').replace('_', ' ')}: {percent(value):.4g} {UNIT}")
        elif isinstance(value, int | float | str) and not isinstance(value, bool):
            lines.append(f"  {key}: {value:.6g}" if isinstance(value, float) else f"  {key}: {value}")
    return lines


def run(args: argparse.Namespace) -> int:
    from hilbench.analysis.protocol import ANALYSES
    from hilbench.bench.analysis_input import memory_budget, read_runs
    from hilbench.bench.analysis_progress import progress_bar
    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs

    if args.analysis not in ANALYSES:
        raise BenchError(f"unknown analysis {args.analysis!r} (available: {', '.join(ANALYSES)})")
    outputs.refuse_inputs({"--json": args.json, "-o": args.output}, [args.run, args.validate])
    outputs.refuse_existing("--json", args.json, args.overwrite)
    entry, inputs, validation = read_runs(args.analysis, args, [args.run], [args.validate],
                                          memory_budget(args.memory))
    if validation is None and entry.needs_validation:
        raise BenchError(f"{args.analysis} scores its models on a validation run: give --validate or --hold-out")
    with progress_bar(args.analysis) as progress:
        result = entry.analyse(inputs, None, validation, progress)
    files, summary = entry.report(result, args.output)
    outputs.say("\n".join(summary_lines(f"{entry.title} ({args.analysis}) of {args.run}", summary)), args.json)
    for path in files:
        outputs.say(f"-> {path}", args.json)
    if args.json:
        outputs.write_json(args.json, {"analysis": args.analysis, "run": str(args.run), "summary": summary})
    return 0
