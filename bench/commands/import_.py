"""``hilbench import {emps,hsm150,mnich,csv} FILE [-o RUN.h5]``: convert measured data into a run file (schema v1)."""

from __future__ import annotations

import argparse
import os


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "import",
        help="import real data (EMPS, HSM150, Mnich rig, CSV) into a run file",
        description="Convert measured data from another bench into a hilbench run file (HDF5 schema v1).",
    )
    formats = parser.add_subparsers(dest="format", metavar="FORMAT", required=True)

    def common(p: argparse.ArgumentParser) -> None:
        p.add_argument("-o", "--output", metavar="RUN.h5", help="run file to write (default: ./<name>.h5)")
        p.add_argument("--force", action="store_true", help="overwrite the output file if it exists")
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
        help="CSV with a header row (t, position, torque or current, optional velocity)",
        description=(
            "Import a CSV file whose header names the columns: t (s), position (rad; m with --linear), "
            "torque (N*m; N with --linear) or current (A) with --torque-constant, optional velocity "
            "(rad/s; m/s with --linear). Columns with other names are mapped with --map CHANNEL=COLUMN. "
            "Values must all be finite and t strictly increasing."
        ),
    )
    csv.add_argument("file", metavar="FILE.csv")
    csv.add_argument(
        "--torque-constant", type=float, metavar="K",
        help="torque constant in N*m/A (N/A with --linear) to turn a current column into torque",
    )
    csv.add_argument(
        "--map", action="append", default=[], metavar="CHANNEL=COLUMN",
        help="read run-file channel CHANNEL from CSV column COLUMN (repeatable), e.g. --map torque=Tq_Nm",
    )
    csv.add_argument("--linear", action="store_true", help="linear axis: position in m, force in N")
    csv.add_argument("--delimiter", help="field separator (default: guessed from the header: , ; or tab)")
    csv.add_argument(
        "--record", choices=("torque-driven", "displacement-driven"), default="torque-driven",
        help="torque-driven (default: the torque drives the motion) or displacement-driven (force measured "
        "against an imposed displacement, e.g. a tribometer); the analysis picks its mode from it",
    )
    common(csv)


def _parse_map(items: list[str]) -> dict[str, str]:
    from hilbench.bench.importers import ImportDataError

    mapping = {}
    for item in items:
        channel, sep, column = item.partition("=")
        if not sep or not channel.strip() or not column.strip():
            raise ImportDataError(f"--map {item!r}: expected CHANNEL=COLUMN")
        mapping[channel.strip()] = column.strip()
    return mapping


def run(args: argparse.Namespace) -> int:
    from hilbench.bench import importers

    if args.format == "csv":
        imported = importers.load_csv(
            args.file, torque_constant=args.torque_constant, mapping=_parse_map(args.map), linear=args.linear,
            delimiter=args.delimiter, record=args.record,
        )
    elif args.format == "mnich":
        from hilbench.bench.import_mnich import load_mnich

        shift = {} if args.ni_shift is None else {"shift": args.ni_shift}
        imported = load_mnich(args.file, args.ni, **shift)
    else:
        imported = importers.LOADERS[args.format](args.file)
    out = args.output or os.path.splitext(os.path.basename(args.file))[0] + ".h5"
    importers.write_run(imported, out, overwrite=args.force, operator=args.operator, notes=args.notes)
    units = {name: imported.custom_units.get(name) or _unit(name, imported.axis) for name in imported.samples}
    channels = ", ".join(f"{name} [{unit}]" for name, unit in units.items())
    print(
        f"wrote {out}: {imported.n_samples} samples at {imported.sample_rate:g} Hz, {imported.axis} axis; "
        f"channels {channels}"
    )
    ignored = imported.protocol_params.get("ignored_columns")
    if ignored:
        print(f"ignored columns: {', '.join(ignored)}")
    return 0


def _unit(name: str, axis: str) -> str:
    from hilbench.bench.runfile import CHANNELS

    return CHANNELS[name].unit(axis)
