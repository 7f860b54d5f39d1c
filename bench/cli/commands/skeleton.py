"""``hilbench skeleton RUN.h5 [RUN2.h5 ...]``: ForceVib skeleton curves of logged chirp runs, composed."""

from __future__ import annotations

import argparse
import math
import sys


def register(subparsers: argparse._SubParsersAction) -> None:
    from hilbench.bench.analysis_input import add_record_options, whole_number

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
        type=float,
        help="inertia J (kg*m^2) or mass (kg); default: the run's declared calibration 'inertia' if present",
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
    parser.add_argument("--plot", metavar="OUT.png", help="write the skeleton plot")
    parser.add_argument("--torque-channel", default=None, metavar="NAME",
                        help="force channel (default: torque if present, else torque_cmd; as identify)")
    add_record_options(parser)
    parser.set_defaults(func=run)


def _mass(args, runs) -> float:
    from hilbench.bench.errors import BenchError

    if args.mass is not None:
        mass = args.mass
    else:
        declared = [r.calibration.get("inertia") for r in runs]
        if any(m is None for m in declared):
            raise BenchError("no --mass given and a run declares no inertia in its calibration")
        mass = float(declared[0])
    if not (math.isfinite(mass) and mass > 0):
        raise BenchError(f"--mass must be positive, got {mass}")
    return mass


def centred_force(torque, timing: str):
    """Torque at the sample instants t_k from a logged channel: a value averaged over [t_k-1, t_k)
    (``hold_previous``) or held over [t_k, t_k+1) (``hold_next``) is centred half a sample off, which biases
    ForceVib's damping by ~5 %; the mean of two neighbours is centred on t_k (ends repeated)."""
    import numpy as np

    f = np.asarray(torque, float)
    if timing == "hold_previous":
        return 0.5 * (f + np.append(f[1:], f[-1]))
    if timing == "hold_next":
        return 0.5 * (f + np.insert(f[:-1], 0, f[0]))
    return f


def run(args: argparse.Namespace) -> int:
    from hilbench.analysis.skeleton.forcevib import compose, forcevib
    from hilbench.bench.analysis_input import MAX_BINS, check_count, load
    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs

    outputs.refuse_inputs({"--json": args.json, "--plot": args.plot}, args.runs)
    check_count(args.bins, "--bins", 1, MAX_BINS, "log-spaced bins per skeleton curve")
    runs = [load(p, args) for p in args.runs]
    if len({r.axis for r in runs}) > 1:
        raise BenchError("runs mix rotary and linear axes")
    if not (math.isfinite(args.spring) and args.spring >= 0):
        raise BenchError(f"--spring must be >= 0, got {args.spring}")
    mass = _mass(args, runs)
    options = {"fb": args.fb, "fc": args.fc} if args.method == "cwt" else {}
    if args.band:
        options["freq_range"] = tuple(args.band)
    results = []
    for r in runs:
        force = centred_force(r.torque, r.timing)
        outputs.say(f"{r.name}: torque timing of {r.torque_channel}: {r.timing} ({r.timing_origin})", level=2)
        results.append(forcevib(r.position, force, r.sample_rate, mass, args.method, spring=args.spring, **options))
    pos, trq = ("rad", "N*m") if runs[0].axis == "rotary" else ("m", "N")
    for r, res in zip(runs, results, strict=True):
        v = res.valid
        outputs.say(f"{r.path.name}: {v.sum()} valid samples, A {res.amplitude[v].min():.4g} .. "
                    f"{res.amplitude[v].max():.4g} {pos}", args.json)
    curves = compose(results, n_bins=args.bins, method=args.compose)
    warnings = _stiffness_warnings(curves, pos, trq, args.spring, mass)
    doc = {
        "runs": [str(p) for p in args.runs],
        "incomplete": {str(r.path): r.incomplete for r in runs if r.incomplete is not None},
        "mass": mass,
        "spring": args.spring,
        "method": args.method,
        "compose": args.compose,
        "units": {
            "amplitude": pos,
            "stiffness": f"{trq}/{pos}",
            "restoring_force": trq,
            "energy": f"{trq}*{pos}",
            "velocity": f"{pos}/s",
            "damping": f"{trq}*s/{pos}",
            "damping_force": trq,
        },
        **{
            k: getattr(curves, k).tolist()
            for k in (
                "amplitude",
                "stiffness",
                "restoring_force",
                "energy",
                "amplitude_count",
                "velocity",
                "damping",
                "damping_force",
                "velocity_count",
            )
        },
    }
    doc["warnings"] = warnings
    outputs.say(
        f"composed {len(results)} runs: {curves.amplitude.size} amplitude bins "
        f"({curves.amplitude.min():.4g} .. {curves.amplitude.max():.4g} {pos}), k_eq "
        f"{curves.stiffness.max():.4g} .. {curves.stiffness.min():.4g} {trq}/{pos}", args.json
    )
    for w in warnings:
        print(f"hilbench skeleton: warning: {w}", file=sys.stderr)
    if args.json:
        outputs.write_json(args.json, doc)
    if args.plot:
        outputs.save_figure(skeleton_figure(curves, [r.name for r in runs], pos, trq), args.plot, dpi=110,
                            bbox_inches="tight")
    return 0


def _stiffness_warnings(curves, pos: str, trq: str, spring: float, mass: float) -> list[str]:
    """A negative k_eq is no stiffness: say so, and refuse when no bin is positive."""
    import numpy as np

    from hilbench.bench.errors import BenchError

    k = np.asarray(curves.stiffness, float)
    neg = np.isfinite(k) & (k < 0)
    if not neg.any():
        return []
    a = np.asarray(curves.amplitude, float)[neg]
    mass_unit = "kg*m^2" if pos == "rad" else "kg"
    why = (f"the restoring force is negative: --spring {spring:g} {trq}/{pos} is larger than the system's spring, "
           f"--mass {mass:g} {mass_unit} is too large, or the system has no restoring force at these amplitudes "
           "(no spring, free sliding), where the skeleton method does not apply")
    if neg.all():
        raise BenchError(f"k_eq < 0 in every amplitude bin: {why}")
    return [f"k_eq < 0 in {int(neg.sum())} of {k.size} amplitude bins (A {a.min():.3g} .. {a.max():.3g} {pos}): "
            f"{why}"]


def skeleton_figure(curves, names: list[str], pos: str, trq: str):
    """Restoring force against displacement amplitude and damping force against velocity amplitude: each run's
    instantaneous points (small dots, one colour per run) under the composed curve (black)."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.ticker import LogLocator

    fig = Figure(figsize=(11, 4.4))
    FigureCanvasAgg(fig)
    ax = fig.subplots(1, 2)
    handles = []
    for i in np.unique(curves.points_run):
        m = curves.points_run == i
        dots = ax[0].plot(curves.points_amplitude[m], curves.points_restoring_force[m], ".", ms=1.5,
                          alpha=0.5, rasterized=True)
        ax[1].plot(curves.points_velocity[m], curves.points_damping_force[m], ".", ms=1.5, alpha=0.5,
                   color=dots[0].get_color(), rasterized=True)
        handles.append(Line2D([], [], ls="none", marker="o", ms=5, color=dots[0].get_color(), label=names[i]))
    ax[0].plot(curves.amplitude, curves.restoring_force, "ko-", ms=3, lw=1)
    ax[1].plot(curves.velocity, curves.damping_force, "ko-", ms=3, lw=1)
    handles.append(Line2D([], [], color="k", marker="o", ms=4, lw=1, label="composed"))
    ax[0].set_xscale("log")
    ax[0].xaxis.set_major_locator(LogLocator(base=10))
    ax[0].set_xlabel(f"displacement amplitude A ({pos})")
    ax[0].set_ylabel(f"restoring force k_eq*A ({trq})")
    ax[1].set_xlabel(f"velocity amplitude V ({pos}/s)")
    ax[1].set_ylabel(f"damping force c_eq*V ({trq})")
    ax[0].legend(handles=handles, fontsize=8, loc="upper left")
    for a in ax:
        a.grid(alpha=0.3, which="both")
        a.tick_params(labelsize=9)
    fig.tight_layout()
    return fig
