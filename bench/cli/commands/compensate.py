"""``hilbench compensate MODEL.json``: position tracking with a model feed-forward, one run or the matrix."""

from __future__ import annotations

import argparse
import uuid
from pathlib import Path

REFERENCE_OPTIONS = {
    # name: (type, nargs, unit, help)
    "amplitudes": (float, "+", "rad", "sine: amplitudes, presliding to gross sliding (peak-to-peak 2A)"),
    "amplitude": (float, None, "rad", "triangle: amplitude"),
    "frequency": (float, None, "Hz", "sine and triangle: frequency"),
    "cycles": (int, None, "periods", "sine (per amplitude) and triangle: periods"),
    "corner": (float, None, "s", "triangle: corner blend time"),
    "targets": (float, "+", "rad", "point_to_point: targets in turn"),
    "move_time": (float, None, "s", "point_to_point: time of each minimum-jerk move"),
    "rest": (float, None, "s", "rest at 0 (sine, triangle) or after each move"),
}

def register(subparsers) -> None:
    from hilbench.analysis.compensation.references import KINDS
    from hilbench.bench.acquisition.device_options import add_device_options

    p = subparsers.add_parser(
        "compensate", help="position tracking with a friction-model feed-forward; one run or the matrix",
        description="The device's position loop tracks a reference while the host streams the model's "
        "feed-forward current J*q''_ref + F(q_ref) + c0 (converted with the calibration, clipped to the current "
        "limit). MODEL.json is a model file (hilbench identify: none, coulomb, maxwell_slip) or a comparison "
        "(hilbench compare's compare.json: also every family). A single run also plays the same reference "
        "without feed-forward (the baseline; --no-baseline skips it) and writes a figure of both tracking errors "
        "and a summary with the reduction factors. --matrix plays every feed-forward against every "
        "reference and writes compensation.md/.json and error plots around reversals (docs/compensation.md).")
    p.add_argument("model", help="model file (.json) of hilbench identify or hilbench compare")
    p.add_argument("--reference", choices=KINDS, default="sine", help="reference of a single run (default sine)")
    p.add_argument("--references", default=None,
                   help=f"--matrix: comma-separated references (default all: {','.join(KINDS)})")
    p.add_argument("--feedforward", default="maxwell_slip",
                   help="feed-forward of a single run: none, coulomb, maxwell_slip or a family of the "
                   "comparison (default maxwell_slip)")
    p.add_argument("--feedforwards", default=None, help="--matrix: comma-separated subset (default all)")
    p.add_argument("--matrix", action="store_true", help="every feed-forward against every reference")
    p.add_argument("--no-baseline", action="store_true",
                   help="single run: do not also play the reference without feed-forward (the baseline run "
                   "<stem>-baseline.h5 the figure and summary compare against)")
    p.add_argument("--predict", action="store_true",
                   help="no device: simulate the position loop on the model's own Maxwell-slip plant (a "
                   "prediction, not a measurement)")
    p.add_argument("-o", "--output", dest="out", type=Path, default=None,
                   help="single run: run file (.h5; default runs/compensated-<uid>.h5), with <stem>-baseline.h5, "
                   "<stem>-tracking.png and <stem>-tracking.json beside it (--predict: no run file, only the "
                   "figure and the summary); --matrix: folder for the runs and the report (required)")
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    p.add_argument("--sample-rate", type=int, default=10000, help="device sample rate, Hz (default 10000)")
    p.add_argument("--window", type=float, default=0.05, help="glitch window after each reversal, s (default "
                   "0.05)")
    p.add_argument("--tolerance", type=float, default=1e-4, help="settling band of point-to-point moves, rad "
                   "(default 1e-4)")
    for name, (kind, nargs, unit, text) in REFERENCE_OPTIONS.items():
        p.add_argument("--" + name.replace("_", "-"), dest=name, type=kind, nargs=nargs, default=None,
                       help=f"{text} ({unit})")
    add_device_options(p)
    p.set_defaults(func=run)


def _references(args) -> dict[str, dict]:
    from hilbench.bench.acquisition.compensation_matrix import DEFAULT_REFERENCES
    from hilbench.bench.errors import BenchError

    kinds = [args.reference] if not args.matrix else (
        [k.strip() for k in args.references.split(",") if k.strip()] if args.references else list(DEFAULT_REFERENCES))
    bad = [k for k in kinds if k not in DEFAULT_REFERENCES]
    if bad or not kinds:
        raise BenchError(f"unknown reference {', '.join(bad) or '(none)'}; choose from {', '.join(DEFAULT_REFERENCES)}")
    out = {}
    for kind in kinds:
        params = dict(DEFAULT_REFERENCES[kind])
        for name in REFERENCE_OPTIONS:
            value = getattr(args, name)
            if value is not None and name in params:
                params[name] = tuple(value) if isinstance(value, list) else value
        out[kind] = params
    return out


def run(args: argparse.Namespace) -> int:
    from hilbench.analysis.compensation.closed_loop import PositionGains
    from hilbench.analysis.compensation.feedforward import load_compensators
    from hilbench.analysis.compensation.run_report import summary_line
    from hilbench.bench.acquisition.compensation_matrix import (
        MatrixSettings,
        case_file,
        cases,
        check_calibration,
        named_runs,
        predict_case,
        run_cases,
        single_outputs,
        write_report,
        write_single_report,
    )
    from hilbench.bench.acquisition.device_options import settings_from_args
    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs

    # everything is checked before anything moves: the model, its axis and units, the calibration, the
    # references and every case's feed-forward
    if not (args.window > 0 and args.tolerance > 0):
        raise BenchError(f"--window ({args.window} s) and --tolerance ({args.tolerance} rad) must be > 0")
    settings = settings_from_args(args)  # limits, calibration and the position loop's gains
    comps, doc = load_compensators(args.model)
    inputs = [args.model, *named_runs(doc)]  # the model and the runs it names (its training run) are inputs
    note = check_calibration(doc, settings.torque_constant, settings.ratio)
    matrix = MatrixSettings(window=args.window, tolerance=args.tolerance, current_limit=settings.current_limit,
                            torque_constant=settings.torque_constant, ratio=settings.ratio)
    if args.matrix:
        if args.out is None:
            raise BenchError("--matrix needs -o/--output DIR (the runs and the report go there)")
        names = [n.strip() for n in args.feedforwards.split(",") if n.strip()] if args.feedforwards else None
        reports = ("compensation.md", "compensation.json", *(f"compensation_{k}.png" for k in _references(args)))
        outputs.refuse_inputs({"--output": args.out, **{f"--output {args.out / n}": args.out / n for n in reports}},
                              inputs)
        if not args.overwrite and (args.out / "compensation.md").exists():
            raise BenchError(f"{args.out / 'compensation.md'} exists; use --overwrite or another folder")
    else:
        baseline = not args.no_baseline and args.feedforward != "none"  # a run without feed-forward is its own
        names = [args.feedforward, "none"] if baseline else [args.feedforward]
        stem = args.out or Path("runs") / f"{'predicted' if args.predict else 'compensated'}-{uuid.uuid4().hex[:8]}.h5"
        single = single_outputs(stem, baseline)
        if args.predict:  # no device, no run file: -o names the figure and the summary
            del single["run"]
            single.pop("baseline", None)
        outputs.refuse_inputs({f"--output {p}": p for p in single.values()}, inputs)
        for path in single.values():
            outputs.refuse_existing("--output", path, args.overwrite)
    protocols = cases(args.model, _references(args), names, matrix, args.sample_rate)
    if args.matrix and not args.predict:  # every run file of the matrix is an output too
        outputs.refuse_inputs({f"--output {f}": f for f in (args.out / case_file(c) for c in protocols)}, inputs)
    outputs.say(note)
    source = "prediction on the model's Maxwell-slip plant (--predict)" if args.predict else \
        f"device {args.device or 'default'}"
    if args.predict:
        ms = predicted_plant(comps, args.model)
        plant = ms.replace(torque_constant=settings.torque_constant * settings.ratio)
        gains = PositionGains(settings.position_kp, settings.position_ki, settings.position_kd,
                              settings.position_i_limit, settings.position_d_cutoff)
        results = run_cases(protocols, lambda p, i: predict_case(p, plant, gains, matrix,
                                                                 settings.counts_per_rev), say=outputs.say)
    else:
        files = [args.out / case_file(c) for c in protocols] if args.matrix else \
            [single["run"], single.get("baseline")][:len(protocols)]
        results = _on_device(args, protocols, settings, matrix, files)
    meta = {"source": source, "model": str(Path(args.model).resolve()), "window_s": args.window,
            "tolerance_rad": args.tolerance, "current_limit_a": settings.current_limit,
            "torque_constant_nm_per_a": settings.torque_constant, "ratio": settings.ratio,
            "sample_rate_hz": args.sample_rate, "calibration_check": note}
    if args.matrix:
        for path in write_report(results, args.out, meta):
            outputs.say(f"-> {path}")
        return 0
    run, base = results[0], (results[1] if len(results) > 1 else None)
    what = f"prediction (--predict) for {stem.name}" if args.predict else Path(run.run_file).name
    title = f"{what}: {run.reference.kind} reference, feed-forward {run.compensator}" + \
        (" against none (baseline)" if base else "")
    for path in write_single_report(run, base, single, meta, title):
        outputs.say(f"-> {path}")
    outputs.say(summary_line(run, base))
    return 0


def predicted_plant(comps: list, model: str):
    """The plant --predict simulates: the model's Maxwell-slip plant, or the one family a family file holds."""
    from hilbench.bench.errors import BenchError

    found = {c.name: c.params for c in comps if c.params is not None and c.name != "coulomb"}
    if "maxwell_slip" in found:
        return found["maxwell_slip"]
    if len(found) == 1:
        return next(iter(found.values()))
    raise BenchError(f"--predict simulates one model's plant; {model} offers {', '.join(found) or 'none'}")


def _on_device(args, protocols, settings, matrix, files: list[Path]) -> list:
    """Play every case on the device, case i into run file ``files[i]``."""
    from hilbench.bench.acquisition.compensation import CompensatedReference
    from hilbench.bench.acquisition.compensation_matrix import measured_case, run_cases
    from hilbench.bench.acquisition.protocols import ProtocolError
    from hilbench.bench.errors import BenchError

    try:  # every protocol is built (and checked) before the device is opened
        played = [CompensatedReference.of(case, matrix.window, matrix.tolerance) for case in protocols]
    except ProtocolError as exc:
        raise BenchError(str(exc)) from None
    from hilbench.bench.acquisition.runner import Bench, signals_as_interrupt
    from hilbench.bench.storage import outputs

    with signals_as_interrupt(), Bench.open(args.device, settings) as bench:
        def play(case, i):
            p = played[i]
            files[i].parent.mkdir(parents=True, exist_ok=True)
            result = bench.run(p, files[i], overwrite=args.overwrite,
                               notes=f"hilbench compensate {p.reference}/{p.compensation}")
            if result.status != "completed":
                raise BenchError(f"{result.path}: run {result.status}: {result.message}")
            outputs.say(f"run file: {result.path} ({result.samples} samples)")
            return measured_case(case, result.path, matrix)

        return run_cases(protocols, play, say=outputs.say)
