"""``hilbench skeleton RUN.h5 [RUN2.h5 ...]``: ForceVib skeleton curves of logged chirp runs, composed."""

from __future__ import annotations

import argparse
import sys


def register(subparsers: argparse._SubParsersAction) -> None:
    from hilbench.bench.analysis_input import add_memory_option, add_record_options, whole_number

    parser = subparsers.add_parser(
        "skeleton",
        help="equivalent stiffness and damping (skeleton curves) from chirp runs, composed across runs",
        description="ForceVib on each run (x = position channel, force = torque channel), then composition "
        "across runs into k_eq(A), restoring force k_eq*A against displacement amplitude, and "
        "damping force c_eq*V against velocity amplitude (docs/science.md §4).",
    )
    parser.add_argument("runs", nargs="+", metavar="RUN.h5", help="chirp run files (same axis)")
    parser.add_argument(
        "--mass",
        metavar="J|MODEL.json",
        help="inertia J (kg*m^2) or mass (kg), or a model file of hilbench identify or compare whose inertia "
        "is taken; default: the run's declared calibration 'inertia' if present",
    )
    parser.add_argument(
        "--spring", type=float, default=0.0, help="linear spring to subtract, N*m/rad (default 0)"
    )
    parser.add_argument("--method", choices=("cwt", "hilbert"), default="cwt", help="instantaneous analysis")
    parser.add_argument("--fb", type=float, default=0.5, help="Morlet bandwidth f_b (default 0.5)")
    parser.add_argument("--fc", type=float, default=0.8, help="Morlet centre frequency f_c (default 0.8)")
    parser.add_argument(
        "--band",
        type=float,
        nargs=2,
        metavar=("F_MIN", "F_MAX"),
        help="analysed band in Hz (default: from the spectrum of each run)",
    )
    parser.add_argument("--bins", type=whole_number, default=30,
                        help="log-spaced bins per curve (default 30, at most 10000)")
    parser.add_argument(
        "--compose",
        choices=("rate", "updown", "median"),
        default="rate",
        help="per-bin energy estimate: rate-extrapolated fit (default), mean of growing/decaying medians, or the "
        "plain median (the paper's pooling); see hilbench.analysis.skeleton.forcevib.compose",
    )
    parser.add_argument("--json", metavar="OUT.json", help="write the composed curves as JSON ('-': stdout)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --json or --plot file")
    parser.add_argument("--plot", metavar="OUT.png", help="write the skeleton plot")
    parser.add_argument("--torque-channel", default=None, metavar="NAME",
                        help="force channel (default: torque if present, else torque_cmd; as identify)")
    add_record_options(parser)
    add_memory_option(parser)
    parser.set_defaults(func=run)


def _analyse(args, settings):
    """The skeleton of ``args.runs`` through the registry's entry: read whole when they fit ``--memory``, else
    chunk by chunk into decimated copies (docs/long-runs.md); a one-line error before the samples are read when
    neither fits."""
    from hilbench.bench.analysis_input import memory_budget, read_runs
    from hilbench.bench.analysis_progress import progress_bar

    entry, inputs, _ = read_runs("skeleton", args, list(args.runs), [], memory_budget(args.memory))
    with progress_bar("skeleton") as progress:
        return entry.analyse(inputs, settings, progress=progress).value


def _mass(text: str | None) -> float | None:
    """``--mass``: a number, or a model file whose inertia is used (a device run declares none, and the
    identification that precedes a chirp has just measured J)."""
    if text is None:
        return None
    try:
        return float(text)
    except ValueError:
        pass
    from hilbench.analysis.errors import AnalysisError
    from hilbench.analysis.models.model_file import read_family

    try:
        model, _ = read_family(text)
    except AnalysisError as exc:
        raise AnalysisError(f"--mass {text}: neither a number nor a readable model file ({exc})") from None
    return float(model.plant.inertia)


def run(args: argparse.Namespace) -> int:
    from hilbench.analysis.figure_style import engineering
    from hilbench.analysis.skeleton import SkeletonSettings
    from hilbench.analysis.skeleton.figure import skeleton_figure
    from hilbench.bench.analysis_input import MAX_BINS, check_count
    from hilbench.bench.storage import outputs

    outputs.refuse_inputs({"--json": args.json, "--plot": args.plot}, args.runs)
    for option, target in (("--json", args.json), ("--plot", args.plot)):
        outputs.refuse_existing(option, target, args.overwrite)
    check_count(args.bins, "--bins", 1, MAX_BINS, "log-spaced bins per skeleton curve")
    settings = SkeletonSettings(mass=_mass(args.mass), spring=args.spring, method=args.method, fb=args.fb, fc=args.fc,
                                band=tuple(args.band) if args.band else None, bins=args.bins, compose=args.compose)
    result = _analyse(args, settings)
    curves, u = result.curves, result.units
    pos, trq = u["amplitude"], u["restoring_force"]
    # summary lines in engineering units (mrad for a presliding chirp), like the figure; the JSON stays SI
    fa, au = engineering(pos, [r["amplitude_max"] for r in result.per_run])
    for r in result.per_run:
        outputs.say(f"{r['run']}: {r['valid_samples']} valid samples, A {fa * r['amplitude_min']:.4g} .. "
                    f"{fa * r['amplitude_max']:.4g} {au}" + ("" if r["read"] == "whole" else f" ({r['read']})"),
                    args.json)
    outputs.say(
        f"composed {len(result.runs)} runs: {curves.amplitude.size} amplitude bins "
        f"({fa * curves.amplitude.min():.4g} .. {fa * curves.amplitude.max():.4g} {au}), k_eq "
        f"{curves.stiffness.max():.4g} .. {curves.stiffness.min():.4g} {trq}/{pos}", args.json
    )
    for w in result.warnings:
        print(f"hilbench skeleton: warning: {w}", file=sys.stderr)
    if args.json:
        outputs.write_json(args.json, result.to_dict())
    if args.plot:
        outputs.save_figure(skeleton_figure(curves, result.names, pos, trq), args.plot, dpi=110,
                            bbox_inches="tight")
    return 0
