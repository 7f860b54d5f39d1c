"""``hilbench residual RUN.h5 [--validate RUN2.h5] [--start TERMS] --json OUT.json --report DIR``: what does the
model get wrong? Fits the starting model, diagnoses its residual, adds the candidate effects that validate,
and reports the error before and after (docs/residual-report.md)."""

from __future__ import annotations

import argparse
import math


def register(subparsers: argparse._SubParsersAction) -> None:
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
    parser.add_argument("--start", default="inertia,maxwell_slip", metavar="TERMS",
                        help="comma-separated starting terms (default inertia,maxwell_slip; "
                             "EMPS reference: inertia,coulomb,viscous,offset)")
    parser.add_argument("--json", required=True, metavar="OUT.json", help="write the JSON report here")
    parser.add_argument("--report", metavar="DIR", help="write diagnostics PNGs and summary.md into DIR")
    parser.add_argument("--torque-channel", default=None, metavar="NAME",
                        help="torque channel (default: torque_cmd if present, else torque)")
    parser.add_argument("--timing", choices=("auto", "hold_next", "hold_previous", "instant"), default="auto",
                        help="torque sample timing: auto (default: from the file's source; device runs are "
                             "hold_previous, EMPS imports hold_next), hold_next (sample k held over "
                             "[t_k, t_k+1), a command), hold_previous (mean over the previous interval), instant")
    parser.add_argument("--cutoff", type=float, default=None, metavar="HZ",
                        help="regression low-pass cutoff in Hz (default fs/20)")
    parser.add_argument("--inertia", type=float, default=None, metavar="J",
                        help="known inertia (kg*m^2, or kg on a linear axis): fixes J and makes a torque-gain "
                             "error identifiable; 0 allowed (force against displacement). Default: estimated, "
                             "or 0 for a displacement-driven record (run-file attribute record)")
    parser.add_argument("--candidates", default=None, metavar="TERMS",
                        help="comma-separated candidate terms to try (default: all registered)")
    parser.set_defaults(func=run)


def _load(path: str, channel: str | None, timing: str | None, cutoff: float | None):
    import numpy as np

    from hilbench.analysis.residual import prepare_run
    from hilbench.analysis.run_file import record_kind, torque_timing_for
    from hilbench.bench.errors import BenchError
    from hilbench.bench.runfile import open_run

    with open_run(path) as r:
        name = channel or ("torque_cmd" if "torque_cmd" in r.channels else "torque")
        if name not in r.channels and not (r.axis == "linear" and name in ("force", "force_cmd")):
            raise BenchError(f"{path}: no torque channel {name!r} (has: {', '.join(r.channels)})")
        position = np.asarray(r.channel("position"), float)
        torque = np.asarray(r.channel(name), float)
        fs, axis = r.sample_rate, r.axis
        timing = torque_timing_for(str(r.meta.get("source", "device")), timing or "auto", name)
        record = record_kind(r.meta.get("record"), path)
        source = str(r.meta.get("source", "device"))
    run = prepare_run(position, torque, fs, axis=axis, name=path, cutoff=cutoff, timing=timing)
    return run, name, timing, record, source


def run(args: argparse.Namespace) -> int:
    from hilbench.analysis.residual import LoopOptions, residual_loop
    from hilbench.analysis.residual.published import published_metric
    from hilbench.analysis.residual.report import write_json, write_report

    start = tuple(t.strip() for t in args.start.split(",") if t.strip())
    cands = None if args.candidates is None else tuple(t.strip() for t in args.candidates.split(",") if t.strip())
    from hilbench.bench.errors import BenchError

    if args.inertia is not None and not (math.isfinite(args.inertia) and args.inertia >= 0):
        raise BenchError(f"--inertia must be finite and >= 0, got {args.inertia}")
    train, channel, timing, record, source = _load(args.run, args.torque_channel, args.timing, args.cutoff)
    loaded = [_load(p, args.torque_channel, args.timing, args.cutoff) for p in args.validate]
    if any(v[3] != record for v in loaded):
        raise BenchError(f"{args.run} is {record}; every --validate run must be too")
    validation = [v[0] for v in loaded]
    opts = LoopOptions(fixed_inertia=args.inertia, candidates=cands, record=record)
    result = residual_loop(train, validation or None, start=start, options=opts)
    result.published_metric = published_metric(source, result.fit_before, result.fit_after, [train], validation)
    inputs = {"run": args.run, "validate": list(args.validate), "start": list(start), "torque_channel": channel,
              "timing": timing, "cutoff_hz": train.data.cutoff, "decimation": train.data.decimation,
              "fixed_inertia": args.inertia if record == "torque-driven" or args.inertia is not None else 0.0,
              "record": record}
    write_json(result, args.json, inputs)
    if args.report:
        write_report(result, args.report, title=f"Residual loop on {args.run}")
    before = result.error_before["validation"]["torque_rel_pct"]
    after = result.error_after["validation"]["torque_rel_pct"]
    what = "force simulated from the measured displacement" if record == "displacement-driven" else "torque"
    print(f"{result.verdict}; validation {what} error {before:.3g} % -> {after:.3g} %")
    pm = result.published_metric
    if pm:
        print(f"  {pm['metric']}: train {pm['before']['train']:.3g} % -> {pm['after']['train']:.3g} % "
              f"(published {pm['published']['train']:.3g} %)" + (
                  f", validation {pm['before']['validation']:.3g} % -> {pm['after']['validation']:.3g} % "
                  f"(published {pm['published']['validation']:.3g} %)" if pm["before"]["validation"] is not None
                  else ""))
    for u in result.unexplained:
        print(f"  unexplained: {u['description']}")
    return 0
