"""``hilbench residual RUN.h5 [--validate RUN2.h5] [--start TERMS] --json OUT.json --report DIR``: what does the
model get wrong? Fits the starting model, diagnoses its residual, adds the candidate effects that validate,
and reports the error before and after (docs/residual-report.md)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    from hilbench.bench.analysis_input import add_hold_out_option, add_memory_option, add_record_options

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
    parser.add_argument("--start", default="inertia,maxwell_slip", metavar="TERMS|FAMILY|MODEL.json",
                        help="comma-separated starting terms (default inertia,maxwell_slip; "
                             "EMPS reference: inertia,coulomb,viscous,offset), or one friction family to identify "
                             "first and start from: coulomb_viscous, stribeck, dahl, lugre, maxwell_slip (identify's "
                             "own fit), gms, continuous, or a Maxwell-slip model file of hilbench identify to start "
                             "from unrefitted (docs/residual-report.md)")
    parser.add_argument("--json", required=True, metavar="OUT.json", help="write the JSON report here")
    parser.add_argument("--report", metavar="DIR", help="write diagnostics PNGs and summary.md into DIR")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --json file or --report summary")
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
    add_memory_option(parser)
    add_hold_out_option(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hilbench.analysis.models.families import FAMILIES
    from hilbench.analysis.models.model_file import read_model
    from hilbench.analysis.record import span_note
    from hilbench.analysis.residual import record_analysis
    from hilbench.analysis.residual.report import report_dict
    from hilbench.bench.analysis_input import check_cutoff, memory_budget, read_runs
    from hilbench.bench.analysis_progress import progress_bar
    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs
    from hilbench.bench.verdict import judge
    from hilbench.common.units import mib

    model_file = args.start if args.start.strip().lower().endswith(".json") else None
    outputs.refuse_inputs({"--json": args.json, "--report": args.report}, [args.run, *args.validate, model_file])
    outputs.refuse_existing("--json", args.json, args.overwrite)
    if args.report:
        outputs.refuse_existing("--report", Path(args.report) / "summary.md", args.overwrite)
    start_model = read_model(model_file) if model_file else (None, None)
    start = tuple(t.strip() for t in args.start.split(",") if t.strip()) if model_file is None else ()
    cands = None if args.candidates is None else tuple(t.strip() for t in args.candidates.split(",") if t.strip())
    if args.inertia is not None and not (math.isfinite(args.inertia) and args.inertia >= 0):
        raise BenchError(f"--inertia must be finite and >= 0, got {args.inertia}")
    budget = memory_budget(args.memory)
    with progress_bar("read") as progress:
        entry, inputs, val_inputs = read_runs("residual", args, [args.run], args.validate, budget, progress)
    recs = inputs.records + (val_inputs.records if val_inputs is not None else [])
    names = [args.run, *args.validate] if args.hold_out is None else [args.run, f"{args.run} (held-out tail)"]
    if any(span_note(r) for r in recs):
        outputs.say(f"over --memory {mib(budget)}: the loop analyses the first {recs[0].n_samples} samples of each "
                    "run at its rate (a bounded span, docs/long-runs.md)", args.json)
    for h in recs:  # the loop's cutoff applies at the rate it analyses (at most 2 kHz)
        check_cutoff(args.cutoff, h.sample_rate)
    for p, rec in zip(names, recs, strict=True):
        outputs.say(f"{p}: torque timing of {rec.torque_channel}: {rec.timing} ({rec.timing_origin})", args.json,
                    level=2)
    if len(start) == 1 and start[0] in FAMILIES:
        outputs.say(f"identifying the {start[0]} family on {args.run} (start of the residual loop)", args.json)
    settings = record_analysis.ResidualSettings(start=start, cutoff=args.cutoff, fixed_inertia=args.inertia,
                                                candidates=cands, start_model=start_model[0],
                                                start_model_document=start_model[1])
    res = entry.analyse(inputs, settings, val_inputs).value
    result, train, rec = res.loop, res.train, recs[0]
    record = rec.kind
    inputs = {"run": args.run, "validate": list(args.validate), "hold_out": args.hold_out, "start": list(result.start),
              "start_option": args.start, "torque_channel": rec.torque_channel,
              "timing": rec.timing, "cutoff_hz": train.data.cutoff, "decimation": train.data.decimation,
              "sample_rate_hz": rec.sample_rate,
              "fixed_inertia": args.inertia if record == "torque-driven" or args.inertia is not None else 0.0,
              "record": record, "start_model": res.start_model,
              "span": {p: span_note(r) for p, r in zip(names, recs, strict=True) if span_note(r)},
              "incomplete": {p: r.incomplete for p, r in zip(names, recs, strict=True)
                             if r.incomplete is not None}}
    outputs.write_json(args.json, report_dict(result, inputs), indent=2, allow_nan=False)
    say = lambda text: outputs.say(text, args.json)  # noqa: E731
    if args.report:
        paths = record_analysis.report(res, args.report, title=f"Residual loop on {args.run}")
        say(f"report: {args.report} ({', '.join(p.name for p in paths)})")
    channel, timing = rec.torque_channel, rec.timing
    before, after = result.error_before["validation"], result.error_after["validation"]
    from hilbench.common.metrics import percent as pct

    if (figure := res.start_figure()) is not None:  # the start model's own figure, as identify reports it
        where, value = figure
        say(f"start model ({res.start_model['source']}): {where} torque NRMSE {pct(value):.3g} %")
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
    where = "validation" if args.validate or args.hold_out is not None else "cross-validation"
    say(judge(pct(after["torque_nrmse"]), pct(after.get("position_nrmse")), None, where, residual_hint=False))
    return 0
