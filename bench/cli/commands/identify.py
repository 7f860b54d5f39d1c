"""``hilbench identify RUN.h5``: identify a Maxwell-slip friction model from a run file."""

from __future__ import annotations

import math
import sys

#: what each --method is, in the summary line (the internal names stay in the model file's "method")
METHOD_NAMES = {"lip": "Maxwell-slip (NNLS)", "oe": "Maxwell-slip (NNLS + output error)",
                "paper": "Maxwell-slip (paper: DE + Nelder-Mead)"}


def register(subparsers) -> None:
    from hilbench.bench.analysis_input import (
        MAX_THRESHOLDS,
        add_hold_out_option,
        add_memory_option,
        add_record_options,
        whole_number,
    )

    parser = subparsers.add_parser(
        "identify",
        help="identify a Maxwell-slip friction model (J, k_i, Delta_i, b) from a run file",
        description="Fit J*theta'' + sum k_i*S_Delta_i[theta] + b*theta' (+ Fc, offset) = tau to the run's "
        "position and torque channels; write the model as JSON (docs/model-file.md).",
    )
    parser.add_argument("run", help="run file (.h5) with 't', 'position' and 'torque' channels")
    parser.add_argument("--validate", metavar="RUN2.h5", help="validation run (same axis)")
    parser.add_argument(
        "--method",
        choices=("lip", "oe", "paper"),
        default="lip",
        help="lip: NNLS on filtered regressors (default, fast); oe: lip then simulation-error "
        "refinement; paper: differential evolution + Nelder-Mead, N=16 (slow)",
    )
    parser.add_argument("--json", required=True, metavar="OUT.json", help="model file to write ('-': stdout)")
    parser.add_argument("--plots", metavar="DIR", help="write PNG plots into DIR")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace existing outputs (the --json file, the --plots files)")
    parser.add_argument(
        "--thresholds", type=whole_number, default=64,
        help=f"candidate thresholds (default 64, at most {MAX_THRESHOLDS}; 0: no Maxwell-slip elements)"
    )
    parser.add_argument("--cutoff", type=float, help="zero-phase filter cutoff, Hz (default fs/20)")
    parser.add_argument("--coulomb", action="store_true", help="add a Coulomb term Fc*sign(velocity)")
    parser.add_argument("--offset", action="store_true", help="add a constant torque offset")
    parser.add_argument("--spring", action="store_true", help="add a linear spring K*position")
    parser.add_argument("--torque-channel", default=None, metavar="NAME",
                        help="torque channel (default: torque if present, else torque_cmd; as residual)")
    parser.add_argument(
        "--torque-timing",
        choices=("auto", "hold_previous", "hold_next", "instant"),
        default="auto",
        help="what torque sample k means: auto (default) = from the file's source (device runs: "
        "hold_previous; EMPS imports: hold_next; a *_cmd channel: hold_next); hold_previous = mean over "
        "[t_k-1, t_k) (a measured current); hold_next = held over [t_k, t_k+1) (a command); instant = value at t_k",
    )
    parser.add_argument("--refine", action="store_true", help="refine the thresholds (variable projection)")
    parser.add_argument(
        "--inertia", type=float, metavar="VALUE",
        help="known inertia (kg*m^2, or kg on a linear axis), not estimated; 0 allowed: force against displacement. "
        "Default: estimated, or 0 for a displacement-driven record (run-file attribute record)",
    )
    add_record_options(parser)
    add_memory_option(parser)
    add_hold_out_option(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    from hilbench.analysis.identification import report
    from hilbench.analysis.identification.entry import IdentifySettings, document
    from hilbench.analysis.identification.maxwell_fit import LipSettings
    from hilbench.analysis.identification.plots import plot_files
    from hilbench.bench.analysis_input import MAX_THRESHOLDS, check_count, check_cutoff, memory_budget, read_runs
    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs
    from hilbench.bench.verdict import judge
    from hilbench.common.units import AXIS_UNITS as AXES
    from hilbench.common.units import EFFORT, mib

    validated = bool(args.validate) or args.hold_out is not None
    plots = plot_files(args.plots, ["train", "validation"] if validated else ["train"]) if args.plots else []
    outputs.refuse_inputs({"--json": args.json, "--plots": args.plots, **{f"--plots {p}": p for p in plots}},
                          [args.run, args.validate])
    for option, path in (("--json", args.json), *(("--plots", p) for p in plots)):
        outputs.refuse_existing(option, path, args.overwrite)
    check_count(args.thresholds, "--thresholds", 0, MAX_THRESHOLDS,
                "candidate thresholds; a model must fit the plant's element limit")
    if args.inertia is not None and not (math.isfinite(args.inertia) and args.inertia >= 0):
        raise BenchError(f"--inertia must be finite and >= 0, got {args.inertia}")
    budget = memory_budget(args.memory)
    settings = IdentifySettings(LipSettings(
        n_thresholds=args.thresholds,
        cutoff=args.cutoff,
        coulomb=args.coulomb,
        offset=args.offset,
        spring=args.spring,
        refine=args.refine,
        fixed_inertia=args.inertia,
    ), method=args.method)
    entry, inputs, val_inputs = read_runs("identify", args, [args.run], [args.validate], budget)
    rec = inputs.record
    if inputs.streamed and args.plots:
        raise BenchError(f"--plots draws the whole record, which does not fit --memory {mib(budget)}: leave "
                         "--plots out, or raise --memory")
    channel, timing, record = rec.torque_channel, rec.timing, rec.kind
    outputs.say(f"torque timing: {timing} ({rec.timing_origin})", args.json, level=2)
    check_cutoff(args.cutoff, rec.sample_rate)
    for text in [n for n in rec.notes if n.startswith("host-clocked timing")]:
        if "UNFIT" in text:
            print(f"{args.run}: {text}", file=sys.stderr)
        else:
            outputs.say(f"{args.run}: {text}", args.json)
    result = entry.analyse(inputs, settings, val_inputs)
    res, val_rec = result.value, (val_inputs.record if val_inputs is not None else None)
    doc = document(result)
    outputs.write_json(args.json, doc, indent=2, allow_nan=False)
    f, u = res.figures, AXES[res.model.axis]
    say = lambda text: outputs.say(text, args.json)  # noqa: E731
    if "train_force_nrmse" in f:
        m, trq = res.model, u["torque"]
        name = METHOD_NAMES.get(res.method, res.method)
        line = (f"{name} on {channel} ({record}, J fixed at {m.inertia:.6g} {u['inertia']}): "
                f"{m.ms_stiffness.size} elements, break-away {EFFORT[m.axis]} {m.breakaway:.4g} {trq}, "
                f"b = {m.viscous:.4g} {u['viscous']}; force simulated from the measured displacement: "
                f"train force NRMSE {100 * f['train_force_nrmse']:.3g} % ({f['train_force_rel_pct']:.3g} % relative)")
        if val_rec is not None:
            line += (f"; validation force NRMSE {100 * f['validation_force_nrmse']:.3g} % "
                     f"({f['validation_force_rel_pct']:.3g} % relative)")
        say(line + f" ({res.wall_time:.2f} s) -> {args.json}")
        if args.plots:
            say("plots: not drawn for a displacement-driven record (use hilbench residual --report for its figures)")
        return 0
    say(summary_line(res, u, channel, timing) + f" ({res.wall_time:.2f} s) -> {args.json}")
    where = "validation" if val_rec is not None else "train"
    say(judge(100 * f[f"{where}_torque_nrmse"], 100 * f[f"{where}_position_nrmse"],
              100 * f[f"{where}_position_nrmse_segmented"], where))
    if args.plots:
        names = {"train": args.run, "validation": args.validate or f"{args.run} (held-out tail)"}
        for p in report(res, args.plots, runs=names):
            say(f"plot: {p}")
    return 0


def summary_line(res, u: dict, channel: str, timing: str) -> str:
    """The identification in one line, every number with its unit."""
    from hilbench.common.metrics import POSITION_NRMSE, label, percent
    from hilbench.common.units import EFFORT

    m, f = res.model, res.figures
    pos, trq = u["position"], u["torque"]
    line = (
        f"{METHOD_NAMES.get(res.method, res.method)} on {channel} ({timing}):"
        f" J = {m.inertia:.6g} {u['inertia']}, {m.ms_stiffness.size} elements, "
        f"break-away {EFFORT[m.axis]} {m.breakaway:.4g} {trq}, b = {m.viscous:.4g} {u['viscous']}"
    )
    if m.coulomb:
        line += f", Fc = {m.coulomb:.4g} {trq}"
    if m.spring:
        line += f", K = {m.spring:.4g} {trq}/{pos}"
    if m.offset:
        line += f", offset {m.offset:.4g} {trq}"
    line += (f"; {label('train')} {percent(f['train_torque_nrmse']):.3g} %, "
             f"{POSITION_NRMSE} {percent(f['train_position_nrmse']):.3g} %")
    if "validation_torque_nrmse" in f:
        line += (
            f"; {label('validation')} {percent(f['validation_torque_nrmse']):.3g} %, "
            f"{POSITION_NRMSE} {percent(f['validation_position_nrmse']):.3g} % "
            f"(segmented {percent(f['validation_position_nrmse_segmented']):.3g} %)"
        )
    return line
