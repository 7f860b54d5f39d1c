"""``hilbench import {emps,hsm150,mnich,csv,mat} FILE [-o RUN.h5]``: measured data into a run file (schema v1)."""

from __future__ import annotations

import argparse
import os


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "import",
        help="import real data (EMPS, HSM150, Mnich rig, your own CSV or MAT) into a run file",
        description="Convert measured data from another bench into a hilbench run file (HDF5 schema v1).",
    )
    formats = parser.add_subparsers(dest="format", metavar="FORMAT", required=True)

    def common(p: argparse.ArgumentParser) -> None:
        p.add_argument("-o", "--output", metavar="RUN.h5", help="run file to write (default: ./<name>.h5)")
        p.add_argument("--overwrite", dest="force", action="store_true", help="replace the output file if it exists")
        p.add_argument("--force", dest="force", action="store_true", help=argparse.SUPPRESS)  # old name
        p.add_argument("--operator", default="", help="operator recorded in the run file")
        p.add_argument("--notes", default="", help="notes recorded in the run file")
        p.set_defaults(func=run)

    emps = formats.add_parser(
        "emps",
        help="EMPS benchmark .mat (linear axis: m, N; force = gtau*vir)",
        description="Import DATA_EMPS.mat or DATA_EMPS_PULSES.mat: linear axis in m and N, force = gtau*vir.",
    )
    emps.add_argument("file", metavar="FILE.mat")
    common(emps)

    hsm = formats.add_parser(
        "hsm150",
        help="HSM150 idf_*.mat identification run (rotary: rad, N*m)",
        description="Import an HSM150 idf_*.mat run: rotary axis in rad, rad/s, N*m and A, 1 kHz.",
    )
    hsm.add_argument("file", metavar="FILE.mat")
    common(hsm)

    mnich = formats.add_parser(
        "mnich",
        help="Mnich rack-and-pinion rig: servo CSV + load-cell CSV (linear: m, N)",
        description=(
            "Import the rack-and-pinion friction rig (servo scope export a3MR.csv and NI load-cell export "
            "a3NI.csv): linear axis, force from the load cell in N on its 2 kHz grid, speed from the servo, "
            "position integrated from it. One short motion: a sanity check for a Stribeck curve."
        ),
    )
    mnich.add_argument("file", metavar="a3MR.csv", help="servo amplifier scope export")
    mnich.add_argument("--ni", metavar="a3NI.csv", help="load-cell export (default: a3NI.csv beside FILE)")
    mnich.add_argument(
        "--ni-shift", type=float, metavar="S",
        help="load-cell clock relative to the servo clock, s (default: the author's -0.004)",
    )
    common(mnich)

    csv = formats.add_parser(
        "csv",
        help="your own CSV with a header row (t, position, torque or current; units per column)",
        description=(
            "Import a CSV file whose header names the columns. Usual names are found by themselves (t, time, "
            "Time [s], position, theta, torque, tau, current, velocity, speed, counts...; see docs/data.md); "
            "others are mapped with --map CHANNEL=COLUMN. Units: from the header (Time [ms], pos_deg) or "
            "--unit CHANNEL=UNIT; unstated means SI (s, rad or m, N*m or N, A). Time stamps must be uniform "
            "(or give --resample linear); values finite."
        ),
    )
    csv.add_argument("file", metavar="FILE.csv")
    csv.add_argument("--delimiter", help="field separator (default: guessed from the header: , ; or tab)")
    table_options(csv)
    common(csv)

    mat = formats.add_parser(
        "mat",
        help="your own MAT file of vectors (v5/v7 or v7.3; units per variable)",
        description=(
            "Import a MATLAB file (v5/v7 with scipy, v7.3 with h5py) whose vectors are named like channels "
            "(t, time, position, theta, torque, current...; see docs/data.md), or mapped with --map "
            "CHANNEL=VAR, or CHANNEL='VAR(:,K)' for column K of a matrix. MAT files carry no units: give them "
            "with --unit CHANNEL=UNIT (unstated means SI). Complex variables are refused."
        ),
    )
    mat.add_argument("file", metavar="FILE.mat")
    table_options(mat)
    common(mat)


def table_options(p: argparse.ArgumentParser) -> None:
    """Options of the table importers (csv, mat): channels, units, timing, gaps."""
    from hilbench.bench.storage.importers import RESAMPLE_METHODS, TORQUE_TIMINGS

    p.add_argument(
        "--map", action="append", default=[], metavar="CHANNEL=COLUMN",
        help="read run-file channel CHANNEL from COLUMN (repeatable), e.g. --map torque=Tq",
    )
    p.add_argument(
        "--unit", action="append", default=[], metavar="CHANNEL=UNIT",
        help="unit of a channel's source values (repeatable): t=ms, position=deg, torque=mN*m, velocity=rpm, "
        "current=mA, position=counts (with --counts-per-rev)...; docs/data.md lists them all",
    )
    p.add_argument("--counts-per-rev", type=float, metavar="N", help="encoder counts per revolution, for a "
                   "position in counts (or a counts column and no position)")
    p.add_argument(
        "--torque-constant", type=float, metavar="K",
        help="torque constant in N*m/A (N/A with --linear) to turn a current column into torque",
    )
    p.add_argument("--linear", action="store_true", help="linear axis: position in m, force in N")
    p.add_argument(
        "--torque-timing", choices=TORQUE_TIMINGS,
        help="what torque sample k means, stored in the run file: hold_next = held over [t_k, t_k+1) (a "
        "command); hold_previous = mean over [t_k-1, t_k) (a current sampled at t_k); instant = value at t_k. "
        "Not given: analyses assume instant (docs/science.md section 6)",
    )
    p.add_argument(
        "--resample", choices=RESAMPLE_METHODS,
        help="non-uniform time stamps: linear = interpolate every channel linearly onto a uniform grid of the "
        "median step (default: refuse, naming the first gap)",
    )
    p.add_argument("--sample-rate", type=float, metavar="HZ", help="sample rate for a file without a time column")
    p.add_argument(
        "--record", choices=("torque-driven", "displacement-driven"), default="torque-driven",
        help="torque-driven (default: the torque drives the motion) or displacement-driven (force measured "
        "against an imposed displacement, e.g. a tribometer); the analysis picks its mode from it",
    )


def _options(args: argparse.Namespace):
    from hilbench.bench.storage.importers import TableOptions

    return TableOptions(
        mapping=_parse_pairs(args.map, "--map", "CHANNEL=COLUMN"),
        units=_parse_pairs(args.unit, "--unit", "CHANNEL=UNIT"),
        torque_constant=args.torque_constant, counts_per_rev=args.counts_per_rev, linear=args.linear,
        torque_timing=args.torque_timing, resample=args.resample, sample_rate=args.sample_rate,
        record=args.record,
    )


def _parse_pairs(items: list[str], option: str, form: str) -> dict[str, str]:
    from hilbench.bench.storage.importers import ImportDataError

    pairs = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip() or not value.strip():
            raise ImportDataError(f"{option} {item!r}: expected {form}")
        key, value = key.strip(), value.strip()
        if key in pairs:  # the last one won silently: --unit position=deg --unit position=rad
            raise ImportDataError(f"{option} {key}= is given twice ({pairs[key]} and {value}); give it once")
        pairs[key] = value
    return pairs


def run(args: argparse.Namespace) -> int:
    from hilbench.bench.storage import importers, outputs

    out = args.output or os.path.splitext(os.path.basename(args.file))[0] + ".h5"
    ni = getattr(args, "ni", None) or (os.path.join(os.path.dirname(args.file), "a3NI.csv")
                                       if args.format == "mnich" else None)
    outputs.refuse_inputs({"-o": out}, [args.file, ni])  # `import csv x.csv -o x.csv --overwrite` replaced x.csv
    if args.format == "csv":
        imported = importers.load_csv(args.file, _options(args), delimiter=args.delimiter)
    elif args.format == "mat":
        imported = importers.load_mat(args.file, _options(args))
    elif args.format == "mnich":
        from hilbench.bench.storage.import_mnich import load_mnich

        shift = {} if args.ni_shift is None else {"shift": args.ni_shift}
        imported = load_mnich(args.file, args.ni, **shift)
    else:
        imported = importers.LOADERS[args.format](args.file)
    importers.write_run(imported, out, overwrite=args.force, operator=args.operator, notes=args.notes)
    units = {name: imported.custom_units.get(name) or _unit(name, imported.axis) for name in imported.samples}
    channels = ", ".join(f"{name} [{unit}]" for name, unit in units.items())
    outputs.say(f"wrote {out}: {imported.n_samples} samples at {imported.sample_rate:g} Hz, {imported.axis} axis; "
                f"channels {channels}")
    params = imported.protocol_params
    if params.get("ignored_columns"):
        outputs.say(f"ignored columns: {', '.join(params['ignored_columns'])}")
    if params.get("units_assumed"):
        outputs.say(f"no unit stated for {', '.join(params['units_assumed'])}: taken as SI (--unit CHANNEL=UNIT "
                    f"if not)")
    if params.get("resampled"):  # what --resample did: informational, -v
        r = params["resampled"]
        outputs.say(f"resampled: {r['method']}, step {r['step_s']:.6g} s, {r['samples_before']} -> "
                    f"{r['samples_after']} samples (largest source step {r['largest_step_s']:.6g} s)", level=2)
    if imported.torque_timing:  # the declared --torque-timing, echoed: -v
        outputs.say(f"torque timing: {imported.torque_timing} (stored in the run file)", level=2)
    elif "torque" in imported.samples:
        outputs.say("torque timing: not declared; analyses will assume instant (--torque-timing to declare it)")
    return 0


def _unit(name: str, axis: str) -> str:
    from hilbench.common.runfile import CHANNELS

    return CHANNELS[name].unit(axis)
