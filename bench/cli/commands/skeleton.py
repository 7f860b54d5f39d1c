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
    """The skeleton of ``args.runs``: read whole when they fit ``--memory``, else chunk by chunk into decimated
    copies (docs/long-runs.md); a one-line error before the samples are read when neither fits."""
    from hilbench.analysis import skeleton
    from hilbench.analysis.record import stream_record
    from hilbench.bench.analysis_input import load, memory_budget
    from hilbench.bench.analysis_progress import progress_bar

    budget = memory_budget(args.memory)
    opts = {"torque_channel": args.torque_channel, "allow_incomplete": args.allow_incomplete}
    heads = [stream_record(p, **opts) for p in args.runs]
    samples = sum(h[0].n_samples for h in heads)
    with progress_bar("skeleton") as progress:
        if skeleton.array_cost(samples) <= budget or any(src is None for _, src in heads):
            return skeleton.analyse([load(p, args) for p in args.runs], settings, progress=progress)
        return skeleton.analyse_stream(args.runs, settings, budget=budget, progress=progress, **opts)


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


def skeleton_figure(curves, names: list[str], pos: str, trq: str):
    """Restoring force against displacement amplitude and damping force against velocity amplitude: each run's
    instantaneous points (small dots, one colour per run) under the composed curve (black), broken where bins are
    missing (a gap between the runs' amplitude ranges is not bridged). Small values in mrad, mN*m; the legend
    below the axes; a log amplitude axis labelled at 1-2-5 only (no minor labels running into each other)."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    from hilbench.analysis.figure_style import engineering, plain_numbers, with_gaps

    fa, au = engineering(pos, curves.points_amplitude)
    fv, vu = engineering(f"{pos}/s", curves.points_velocity)
    fk, ku = engineering(trq, np.r_[curves.points_restoring_force, curves.points_damping_force])
    fig = Figure(figsize=(11, 5.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots(1, 2)
    handles = []
    for i in np.unique(curves.points_run):
        m = curves.points_run == i
        dots = ax[0].plot(fa * curves.points_amplitude[m], fk * curves.points_restoring_force[m], ".", ms=1.5,
                          alpha=0.5, rasterized=True)
        ax[1].plot(fv * curves.points_velocity[m], fk * curves.points_damping_force[m], ".", ms=1.5, alpha=0.5,
                   color=dots[0].get_color(), rasterized=True)
        handles.append(Line2D([], [], ls="none", marker="o", ms=5, color=dots[0].get_color(), label=names[i]))
    a, f = with_gaps(curves.amplitude, curves.restoring_force)
    ax[0].plot(fa * a, fk * f, "ko-", ms=3, lw=1)
    v, d = with_gaps(curves.velocity, curves.damping_force)
    ax[1].plot(fv * v, fk * d, "ko-", ms=3, lw=1)
    handles.append(Line2D([], [], color="k", marker="o", ms=4, lw=1, label="composed (bin medians; gaps: no data)"))
    span = fa * curves.points_amplitude[curves.points_amplitude > 0]
    if span.size and span.max() > 3 * span.min():  # a log axis only over a range worth one
        ax[0].set_xscale("log")
        ax[0].xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax[0].xaxis.set_major_formatter(FuncFormatter(lambda value, _pos: f"{value:g}"))
        ax[0].xaxis.set_minor_formatter(NullFormatter())
    ax[0].set_xlabel(f"displacement amplitude A ({au})")
    ax[0].set_ylabel(f"restoring force k_eq*A ({ku})")
    ax[1].set_xlabel(f"velocity amplitude V ({vu})")
    ax[1].set_ylabel(f"damping force c_eq*V ({ku})")
    ax[0].set_title("restoring force skeleton", fontsize=10)
    ax[1].set_title("damping force skeleton", fontsize=10)
    for a in ax:
        a.grid(alpha=0.3, which="both")
        a.tick_params(labelsize=9)
        plain_numbers(a)
    fig.legend(handles=handles, fontsize=8, loc="outside lower center", ncol=min(4, len(handles)), frameon=False)
    shown = ", ".join(names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")
    fig.suptitle(f"ForceVib skeleton curves of {len(names)} run{'s' if len(names) != 1 else ''}: {shown}")
    return fig
