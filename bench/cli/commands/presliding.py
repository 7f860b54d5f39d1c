"""``hilbench presliding RUN.h5 -o DIR``: presliding analysis of a displacement-driven record (docs/presliding.md):
reversal-point table, Masing and wiping-out checks, the Maxwell-slip force model, x_p, sum(k), F_b with
uncertainties, what the resolution no longer resolves, and the figures."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

OUTPUT_FILES = ("presliding.json", "summary.md", "reversals.csv", "loops.png", "virgin.png")


def register(subparsers: argparse._SubParsersAction) -> None:
    from hilbench.bench.analysis_input import add_memory_option, add_record_options, whole_number

    parser = subparsers.add_parser(
        "presliding",
        help="presliding analysis of a displacement-driven record (force against imposed displacement)",
        description="Reversal points, the Masing and wiping-out checks on the measured data, force-from-"
        "displacement identification (Maxwell-slip by NNLS), presliding distance, initial stiffness and "
        "break-away force with bootstrap uncertainties, and which of them the encoder resolution no longer "
        "resolves. Writes " + ", ".join(OUTPUT_FILES) + " into DIR (docs/presliding.md).",
    )
    parser.add_argument("run", metavar="RUN.h5", help="a displacement-driven run file (root attribute record)")
    parser.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the outputs")
    parser.add_argument("--overwrite", action="store_true", help="replace outputs that exist in DIR")
    parser.add_argument("--fraction", type=float, default=0.9,
                        help="presliding distance: where the virgin curve reaches this fraction of its sliding "
                             "level (default 0.9)")
    parser.add_argument("--inertia", type=float, default=None, metavar="J",
                        help="known inertia (kg*m^2, or kg on a linear axis) whose J*x'' is subtracted (default: the "
                             "presliding protocol's inertia parameter in the run file, else 0)")
    parser.add_argument("--coulomb", action="store_true", help="add a Coulomb term Fc*sign(x')")
    parser.add_argument("--no-viscous", action="store_true", help="no viscous term b*x'")
    parser.add_argument("--thresholds", type=whole_number, default=48,
                        help="candidate Maxwell-slip thresholds (default 48, 1 to 400)")
    parser.add_argument("--hysteresis", type=float, default=None, metavar="X",
                        help="smallest travel counted as a reversal, m or rad (default 1.5 position steps)")
    parser.add_argument("--replicates", type=whole_number, default=20,
                        help="bootstrap replicates for the uncertainties (default 20, 2 to 1000)")
    parser.add_argument("--counts-per-rev", type=float, default=None, metavar="N",
                        help="encoder counts per revolution (default: the run file's calibration, else the "
                             "step measured from the data)")
    parser.add_argument("--torque-channel", default=None, metavar="NAME", help="force channel (default torque)")
    add_record_options(parser)
    add_memory_option(parser)
    parser.set_defaults(func=run)


def _check(args) -> None:
    from hilbench.bench.analysis_input import check_count
    from hilbench.bench.errors import BenchError

    if not (math.isfinite(args.fraction) and 0 < args.fraction < 1):
        raise BenchError(f"--fraction must be in (0, 1), got {args.fraction}")
    if args.inertia is not None and not (math.isfinite(args.inertia) and args.inertia >= 0):
        raise BenchError(f"--inertia must be finite and >= 0, got {args.inertia}")
    if args.hysteresis is not None and not (math.isfinite(args.hysteresis) and args.hysteresis >= 0):
        raise BenchError(f"--hysteresis must be finite and >= 0, got {args.hysteresis}")
    if args.counts_per_rev is not None and not (math.isfinite(args.counts_per_rev) and args.counts_per_rev > 0):
        raise BenchError(f"--counts-per-rev must be finite and > 0, got {args.counts_per_rev}")
    check_count(args.thresholds, "--thresholds", 1, 400, "each threshold is one stop-operator column")
    check_count(args.replicates, "--replicates", 2, 1000, "each replicate is one refit")


def run(args: argparse.Namespace) -> int:
    from hilbench.analysis.presliding.entry import PreslidingAnalysis, document
    from hilbench.analysis.presliding.identify import PreslidingSettings
    from hilbench.analysis.presliding.report import summary_lines
    from hilbench.bench.analysis_input import memory_budget, read_runs
    from hilbench.bench.analysis_progress import progress_bar
    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs

    _check(args)
    out = Path(args.output)
    targets = {name: out / name for name in OUTPUT_FILES}
    outputs.refuse_inputs({f"-o {p}": p for p in targets.values()}, [args.run])
    present = [p.name for p in targets.values() if p.exists()]
    if present and not args.overwrite:
        raise BenchError(f"{out} holds {', '.join(present)} already; use --overwrite or another folder")
    settings = PreslidingAnalysis(PreslidingSettings(viscous=not args.no_viscous, coulomb=args.coulomb,
                                                     n_thresholds=args.thresholds),
                                  inertia=args.inertia, counts_per_rev=args.counts_per_rev,
                                  hysteresis=args.hysteresis, fraction=args.fraction, replicates=args.replicates)
    entry, inputs, _ = read_runs("presliding", args, [args.run], [], memory_budget(args.memory))
    with progress_bar("presliding") as progress:
        result = entry.analyse(inputs, settings, progress=progress)
    res, doc = result.value, document(result)
    entry.report(result, out)
    for line in summary_lines(doc):
        outputs.say(line)
    for line in res.warnings:
        print(f"hilbench presliding: warning: {line}", file=sys.stderr)
    outputs.say(f"-> {out}/ ({', '.join(OUTPUT_FILES)})")
    return 0
