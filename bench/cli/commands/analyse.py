"""``hilbench analyse CAMPAIGN_DIR...``: analyse every run of one or more campaigns into one Parquet table."""

from __future__ import annotations

import argparse
import math
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    from hilbench.analysis.protocol import ANALYSES
    from hilbench.bench.analysis_input import MAX_THRESHOLDS, whole_number
    from hilbench.bench.campaign_analysis.fork_server import MAX_WORKERS

    p = sub.add_parser(
        "analyse", help="analyse every run of campaign folders (identify, compare, residual, ...) into one Parquet "
        "table, in parallel",
        description="Run the chosen steps on every run of the campaign folders (their index.json) on a Dask "
        "cluster: one row per run and step in OUT/results.parquet, keyed by the run file's content hash, the "
        "settings and the hilbench version; rows already there are skipped (--resume, the default). See "
        "docs/campaign-analysis.md.")
    p.add_argument("campaigns", nargs="+", type=Path, metavar="CAMPAIGN_DIR", help="campaign folder(s)")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="results folder (default: CAMPAIGN_DIR/analysis with one campaign; required with several)")
    p.add_argument("--steps", default="identify",
                   help="comma-separated steps, each run gets those its protocol supports (default identify; "
                   f"available: the analysis registry's {', '.join(ANALYSES)})")
    engine = p.add_mutually_exclusive_group()
    engine.add_argument("--serial", action="store_true", help="run in this process (no cluster; no --workers)")
    engine.add_argument("--scheduler", metavar="tcp://HOST:8786",
                        help="use a running Dask scheduler (it must answer within 10 s; its workers must see the "
                        "run files and the results folder at the same paths)")
    engine.add_argument("--scheduler-file", metavar="FILE", help="use the Dask scheduler this file names")
    p.add_argument("--workers", type=whole_number, default=None,
                   help=f"worker processes of the local cluster, 1..{MAX_WORKERS} (default: one per core)")
    resume = p.add_mutually_exclusive_group()
    resume.add_argument("--resume", dest="resume", action="store_true", default=True,
                        help="skip rows already in the table (default)")
    resume.add_argument("--no-resume", dest="resume", action="store_false", help="analyse every run again")
    p.add_argument("--thresholds", type=whole_number, default=32,
                   help=f"identify: candidate thresholds, 0..{MAX_THRESHOLDS} (default 32)")
    p.add_argument("--method", choices=("lip", "oe"), default="lip", help="identify: method (default lip)")
    p.add_argument("--coulomb", action="store_true", help="identify: add a Coulomb term")
    p.add_argument("--offset", action="store_true", help="identify: add a torque offset")
    p.add_argument("--validation-fraction", type=float, default=0.3,
                   help="identify: tail of each run held out for validation (default 0.3; 0: none)")
    p.add_argument("--skeleton-mass", type=float, default=None, metavar="J",
                   help="skeleton: inertia J (kg*m^2) or mass (kg); default: each run's declared calibration inertia")
    p.add_argument("--allow-incomplete", action="store_true",
                   help="also analyse runs that did not complete (aborted, short), as the single-run commands do")
    p.add_argument("--no-dashboard", action="store_true", help="do not start the Dask dashboard (it costs seconds)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def start_early(argv: list[str]) -> None:
    """Start the local cluster's host process if this command line will use one (hilbench.bench.cli.main calls this
    before it builds its parser): its fork server's imports (1-2 s on one core) are the local cluster's critical
    path, and the command's own imports, parsing and planning then run beside them. Only for a line that names a
    campaign folder and no other engine; a line that is bad for another reason costs a process that exits with the
    command."""
    if any(a in ("-h", "--help") or a.startswith(("--serial", "--scheduler")) for a in argv):
        return
    from hilbench.bench.campaign_index import INDEX_NAME

    if not any(not a.startswith("-") and (Path(a) / INDEX_NAME).is_file() for a in argv):
        return
    workers = None
    for i, a in enumerate(argv):  # the count the command will check; a bad one: no early start
        if a == "--workers" or a.startswith("--workers="):
            value = a.partition("=")[2] if "=" in a else (argv[i + 1] if i + 1 < len(argv) else "")
            workers = int(value) if value.isdigit() else -1
    from hilbench.bench.campaign_analysis import cluster_host
    from hilbench.bench.campaign_analysis.fork_server import MAX_WORKERS

    if workers is None or 1 <= workers <= MAX_WORKERS:
        dashboard = cluster_host.dashboard_address("--no-dashboard" not in argv)
        cluster_host.start_early(cluster_host.local_workers(workers), dashboard)


def run(args: argparse.Namespace) -> int:
    from hilbench.bench.campaign_analysis import cluster_host

    try:
        return _run(args)
    finally:
        cluster_host.discard()  # a cluster host start_early started for a command line refused here


def _run(args: argparse.Namespace) -> int:
    from hilbench.bench.analysis_input import MAX_THRESHOLDS, check_count
    from hilbench.bench.campaign_analysis.fork_server import MAX_WORKERS
    from hilbench.bench.campaign_analysis.steps import STEPS, StepSettings
    from hilbench.bench.campaign_index import INDEX_NAME
    from hilbench.bench.errors import AnalyseError, BenchError
    from hilbench.bench.storage import outputs

    steps = tuple(s.strip() for s in args.steps.split(",") if s.strip())
    bad = [s for s in steps if s not in STEPS]
    if bad or not steps:
        raise AnalyseError(f"--steps: unknown step {bad[0] if bad else '(none)'!r} (available: {', '.join(STEPS)})")
    if not 0 <= args.validation_fraction < 0.9:
        raise AnalyseError(f"--validation-fraction must be in [0, 0.9), got {args.validation_fraction}")
    if args.workers is not None and not 1 <= args.workers <= MAX_WORKERS:
        raise AnalyseError(f"--workers must be in 1..{MAX_WORKERS}, got {args.workers}")
    if args.serial and args.workers is not None:
        raise AnalyseError("--serial runs in this process: it takes no --workers")
    try:
        check_count(args.thresholds, "--thresholds", 0, MAX_THRESHOLDS, "candidate thresholds, as identify takes")
    except BenchError as exc:
        raise AnalyseError(str(exc)) from None
    if args.skeleton_mass is not None and not (math.isfinite(args.skeleton_mass) and args.skeleton_mass > 0):
        raise AnalyseError(f"--skeleton-mass must be finite and > 0 (kg*m^2 or kg), got {args.skeleton_mass}")
    for folder in args.campaigns:
        if not (folder / INDEX_NAME).is_file():
            raise AnalyseError(f"{folder}: no {INDEX_NAME}; not a campaign folder (hilbench campaign writes one)")
    if args.output is None:
        if len(args.campaigns) > 1:
            raise AnalyseError("several campaigns: give the results folder with -o")
        args.output = args.campaigns[0] / "analysis"
    if (args.output / INDEX_NAME).exists():
        raise AnalyseError(f"{args.output}: is a campaign folder; the results go into a folder of their own")
    outputs.refuse_inputs({"-o": args.output}, args.campaigns)
    from hilbench.bench.campaign_analysis.engine import analyse

    settings = StepSettings(thresholds=args.thresholds, method=args.method, coulomb=args.coulomb,
                            offset=args.offset, validation_fraction=args.validation_fraction,
                            skeleton_mass=args.skeleton_mass, allow_incomplete=args.allow_incomplete)
    summary = analyse(list(args.campaigns), args.output, steps, settings, serial=args.serial, workers=args.workers,
                      scheduler=args.scheduler, scheduler_file=args.scheduler_file, resume=args.resume,
                      progress=not args.quiet and outputs.verbosity > 0, say=outputs.say,
                      verbose=outputs.verbosity > 1, dashboard=not args.no_dashboard)
    for line in summary.failures:
        outputs.say(f"failed: {line}")
    per_run = summary.scheduler_cpu_per_run
    scheduler = "" if per_run is None else f", scheduler {1e3 * per_run:.2f} ms per run"
    outputs.say(f"{summary.analysed} analysed ({summary.failed} failed), {summary.skipped} already there, "
                f"{summary.total} rows in all ({summary.wall_time:.2f} s, {summary.startup_time:.2f} s of it start-up; "
                f"client CPU {1e3 * summary.client_cpu_per_run:.2f} ms per run{scheduler}) "
                f"-> {summary.table}")
    return 0
