"""``hilbench gui [--device URL]``: the operator window (live plots, protocols, E-STOP, run browser)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "gui",
        help="open the operator window (connect, live plots, run protocols, E-STOP, browse runs)",
        description=(
            "The lab operator's window: connect to the amplifier, watch current, torque, position and velocity "
            "live, start identification / chirp / stepped-sine runs, E-STOP (button or Esc), browse and "
            "analyse run files, and play campaigns. Device I/O never runs in the GUI thread."
        ),
    )
    parser.add_argument("--device", default=None,
                        help="device URL shown in the connection panel (default $HILBENCH_DEVICE, the config "
                             "file's 'device', else sim://, the simulated bench)")
    parser.add_argument("--connect", action="store_true", help="connect to --device at start-up")
    parser.add_argument("--runs", default="runs", metavar="DIR",
                        help="folder for new run files and the run browser (default runs)")
    parser.add_argument("--open", metavar="RUN.h5", help="open this run file in the run browser")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if "://" not in args.device:
        raise ValueError(f"--device {args.device!r} is not a device URL (sim://, serial:///dev/ttyUSB0, "
                         f"can://socketcan/can0)")
    try:
        from hilbench.bench.gui.app import run_app
    except ImportError as exc:
        raise OSError(f"the GUI needs PySide6 and pyqtgraph: {exc}") from None
    return run_app(device=args.device, runs_dir=args.runs, autoconnect=args.connect, open_file=args.open)
