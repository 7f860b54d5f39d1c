"""``hilbench residual RUN.h5 [--validate RUN2.h5] [--start TERMS] --json OUT.json --report DIR``: what does the
model get wrong? Fits the starting model, diagnoses its residual, adds the candidate effects that validate,
and reports the error before and after (docs/residual-report.md)."""

from __future__ import annotations

import argparse
import math


def register(subparsers: argparse._SubParsersAction) -> None:
    from hilbench.bench.analysis_input import add_record_options

    parser = subparsers.add_parser(
        "residual",
        help="residual loop: find the physical effects a friction model lacks, validated on held-out data",
        description=(
            "Fit the starting model to RUN.h5, diagnose the torque residual (against time, position, velocity, "
            "acceleration, command; angle- and time-domain spectra; direction; lag), then add candidate effects "
            "(viscous, stribeck, asymmetric_friction, position_periodic, position_dependent_friction, delay, "
            "torque_gain, offset_drift, ...) one at a time, keeping each only if it lowers the error on held-out "
            "data (--validate run, else blocked cross-validation) significantly. See docs/residual-report.md."
        ),
    )
    parser.add_argument("run", metavar="RUN.h5", help="training run file (position and torque channels)")
    parser.add_argument("--validate", metavar="RUN2.h5", action="append", default=[],
                        help="validation run never fitted (repeatable); default: 5-fold blocked cross-validation")
    parser.add_argument("--start", default="inertia,maxwell_slip", metavar="TERMS|FAMILY",
                        help="comma-separated starting terms (default inertia,maxwell_slip; "
                             "EMPS reference: inertia,coulomb,viscous,offset), or one friction family to identify "
                             "first and start from: coulomb_viscous, stribeck, dahl, lugre, maxwell_slip, gms, "
                             "continuous (docs/residual-report.md)")
    parser.add_argument("--json", required=True, metavar="OUT.json", help="write the JSON report here")
    parser.add_argument("--report", metavar="DIR", help="write diagnostics PNGs and summary.md into DIR")
    parser.add_argument("--torque-channel", default=None, metavar="NAME",
                        help="torque channel (default: torque if present, else torque_cmd; as identify)")
    parser.add_argument("--torque-timing", "--timing", dest="timing",
                        choices=("auto", "hold_next", "hold_previous", "instant"), default="auto",
                        help="torque sample timing: auto (default: from the file's source; device runs are "
                             "hold_previous, EMPS imports and *_cmd channels hold_next), hold_next (sample k held "
                             "over [t_k, t_k+1), a command), hold_previous (mean over the previous interval), "
                             "instant")
    parser.add_argument("--cutoff", type=float, default=None, metavar="HZ",
                        help="regression low-pass cutoff in Hz (default fs/20)")
    parser.add_argument("--inertia", type=float, default=None, metavar="J",
                        help="known inertia (kg*m^2, or kg on a linear axis): fixes J and makes a torque-gain "
                             "error identifiable; 0 allowed (force against displacement). Default: estimated, "
                             "or 0 for a displacement-driven record (run-file attribute record)")
    parser.add_argument("--candidates", default=None, metavar="TERMS",
                        help="comma-separated candidate terms to try (default: all registered)")
    add_record_options(parser)
    parser.set_defaults(func=run)


def _load(path: str, args: argparse.Namespace):
    """The run through the one loader, prepared for the loop: (RunData, channel, timing, record kind, source)."""
    from hilbench.analysis.residual import prepare_run
    from hilbench.bench.analysis_input import check_cutoff, load
    from hilbench.bench.storage import outputs

    rec = load(path, args, timing=args.timing or "auto")
    check_cutoff(args.cutoff, rec.sample_rate)
    outputs.say(f"{path}: torque timing of {rec.torque_channel}: {rec.timing} ({rec.timing_origin})", args.json,
                level=2)
    run = prepare_run(rec.position, rec.torque, rec.sample_rate, axis=rec.axis, name=path, cutoff=args.cutoff,
                      timing=rec.timing)
    return run, rec.torque_channel, rec.timing, rec.kind, rec.source, rec.incomplete


def _inertia(model: dict, fixed: float | None) -> float:
    term = model.get("inertia")
    if term is not None:
        return float(term["parameters"]["inertia"])
    return float(fixed or 0.0)


def write_hysteresis(result, directory, title: str, fixed_inertia: float | None):
    """Friction against displacement on the first training run: measured (torque - J*acceleration, J of the
    final model) against the starting and the final model (measured minus each one's residual)."""
    from pathlib import Path

    from hilbench.analysis.identification.plots import hysteresis_figure
    from hilbench.analysis.models.friction_model import AXES

    before, after = result.signals_before, result.signals_after
    i0, i1 = after.run_rows[0]
    j_after = _inertia(result.model_after, fixed_inertia)
    j_before = _inertia(result.model_before, fixed_inertia)
    measured = (after.command - j_after * after.acceleration)[i0:i1]
    model_after = measured - after.residual[i0:i1]
    model_before = (before.command - j_before * before.acceleration - before.residual)[i0:i1]
    added = ", ".join(result.names_added) or "nothing added"
    return hysteresis_figure(after.position[i0:i1], measured,
                             [(f"final model (+ {added})", model_after),
                              (f"starting model ({', '.join(result.start)})", model_before)],
                             AXES[after.axis], title, Path(directory) / "hysteresis.png", t=after.time[i0:i1])


def run(args: argparse.Namespace) -> int:
    from hilbench.analysis.models.families import FAMILIES
    from hilbench.analysis.residual import LoopOptions, family_start, residual_loop
    from hilbench.analysis.residual.published import published_metric
    from hilbench.analysis.residual.report import report_dict, write_report
    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs
    from hilbench.bench.verdict import judge

    outputs.refuse_inputs({"--json": args.json, "--report": args.report}, [args.run, *args.validate])
    start = tuple(t.strip() for t in args.start.split(",") if t.strip())
    cands = None if args.candidates is None else tuple(t.strip() for t in args.candidates.split(",") if t.strip())
    if args.inertia is not None and not (math.isfinite(args.inertia) and args.inertia >= 0):
        raise BenchError(f"--inertia must be finite and >= 0, got {args.inertia}")
    train, channel, timing, record, source, incomplete = _load(args.run, args)
    if args.inertia == 0 and record == "torque-driven":  # J = 0 left the loop nothing to fit (a numpy error)
        raise BenchError(f"--inertia 0 is for a displacement-driven record; {args.run} is torque-driven: give "
                         "J > 0 or leave --inertia out to estimate it")
    loaded = [_load(p, args) for p in args.validate]
    if any(v[3] != record for v in loaded):
        raise BenchError(f"{args.run} is {record}; every --validate run must be too")
    validation = [v[0] for v in loaded]
    opts = LoopOptions(fixed_inertia=args.inertia, candidates=cands, record=record)
    if len(start) == 1 and start[0] not in FAMILIES and start[0] != "inertia":
        raise BenchError(f"--start {start[0]!r} is neither a friction family ({', '.join(FAMILIES)}) nor a "
                         "comma-separated list of terms with inertia")
    if len(start) == 1 and start[0] in FAMILIES:
        if record == "displacement-driven" or args.inertia is not None:
            raise BenchError("--start FAMILY identifies J with the family; it takes neither --inertia nor a "
                             "displacement-driven record (start from terms instead)")
        outputs.say(f"identifying the {start[0]} family on {args.run} (start of the residual loop)", args.json)
        start = tuple(family_start(start[0], [train]))
    result = residual_loop(train, validation or None, start=start, options=opts)
    result.published_metric = published_metric(source, result.fit_before, result.fit_after, [train], validation)
    inputs = {"run": args.run, "validate": list(args.validate), "start": list(result.start),
              "start_option": args.start, "torque_channel": channel,
              "timing": timing, "cutoff_hz": train.data.cutoff, "decimation": train.data.decimation,
              "fixed_inertia": args.inertia if record == "torque-driven" or args.inertia is not None else 0.0,
              "record": record,
              "incomplete": {p: v for p, v in zip([args.run, *args.validate], [incomplete, *(v[5] for v in loaded)],
                                                  strict=True) if v is not None}}
    outputs.write_json(args.json, report_dict(result, inputs), indent=2, allow_nan=False)
    say = lambda text: outputs.say(text, args.json)  # noqa: E731
    if args.report:
        write_report(result, args.report, title=f"Residual loop on {args.run}")
        path = write_hysteresis(result, args.report, f"Residual loop on {args.run}: friction against displacement",
                                inputs["fixed_inertia"])
        extra = "force.png, " if record == "displacement-driven" else ""
        say(f"report: {args.report} (summary.md, diagnostics_before.png, diagnostics_after.png, {extra}{path.name})")
    before, after = result.error_before["validation"], result.error_after["validation"]
    pct = lambda v: None if v is None else 100.0 * v  # noqa: E731
    if record == "displacement-driven":
        say(f"{result.verdict}; validation force simulated from the measured displacement: NRMSE "
            f"{pct(before['torque_nrmse']):.3g} % -> {pct(after['torque_nrmse']):.3g} % "
            f"(relative error |e|/|y| {before['torque_rel_pct']:.3g} % -> {after['torque_rel_pct']:.3g} %)")
    else:
        say(f"{result.verdict}; on {channel} ({timing}): validation torque NRMSE "
            f"{pct(before['torque_nrmse']):.3g} % -> {pct(after['torque_nrmse']):.3g} % "
            f"(relative error |e|/|y| {before['torque_rel_pct']:.3g} % -> {after['torque_rel_pct']:.3g} %)")
    pm = result.published_metric
    if pm:
        line = (f"  {pm['metric']}: train {pm['before']['train']:.3g} % -> {pm['after']['train']:.3g} % "
                f"(published {pm['published']['train']:.3g} %)")
        if pm["before"]["validation"] is not None:
            line += (f", validation {pm['before']['validation']:.3g} % -> {pm['after']['validation']:.3g} % "
                     f"(published {pm['published']['validation']:.3g} %)")
        say(line)
    for u in result.unexplained:
        say(f"  unexplained: {u['description']}")
    where = "validation" if args.validate else "cross-validation"
    say(judge(pct(after["torque_nrmse"]), pct(after.get("position_nrmse")), None, where, residual_hint=False))
    return 0
