"""``hilbench sim``: run the simulated amplifier (it execs ``python -m hilbench.firmware_sim``)."""

from __future__ import annotations

import os
import sys


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "sim", help="run the simulated amplifier on a pseudo-terminal or a CAN bus",
        description="Run the simulated amplifier as its own process. With --serial the first line printed "
                    "is the pty path to connect to (serial://PATH).")
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--serial", action="store_true", help="serve on a new pseudo-terminal")
    where.add_argument("--can", metavar="CHANNEL", help="serve on this python-can channel (e.g. vcan0)")
    parser.add_argument("--interface", default="socketcan", help="python-can interface for --can")
    parser.add_argument("--node", type=int, default=1, help="CAN node id, 1..15")
    parser.add_argument("--fd", action="store_true", help="use CAN FD frames")
    parser.add_argument("--config", help="simulator TOML (plant and injected effects)")
    parser.add_argument("--seed", type=int, help="override the plant's random seed")
    parser.add_argument("--pacing", choices=("realtime", "lockstep"), default="realtime",
                        help="realtime (default) or lockstep (as fast as flow control allows)")
    parser.add_argument("--tick", type=float, default=0.004, help="realtime loop period, s")
    parser.add_argument("--core", choices=("c", "python"), default=None,
                        help="device implementation: c (the firmware core, default) or python")
    parser.set_defaults(func=run)


def firmware_argv(args) -> list[str]:
    """The ``python -m hilbench.firmware_sim`` command line equivalent to ``args``."""
    argv = [sys.executable, "-m", "hilbench.firmware_sim"]
    argv += ["--serial"] if args.serial else ["--can", args.can, "--interface", args.interface,
                                              "--node", str(args.node)]
    if args.fd:
        argv.append("--fd")
    for name in ("config", "seed", "core"):
        if getattr(args, name) is not None:
            argv += [f"--{name}", str(getattr(args, name))]
    return argv + ["--pacing", args.pacing, "--tick", str(args.tick)]


def run(args) -> int:
    if args.config is not None and not os.path.isfile(args.config):
        raise ValueError(f"simulator config {args.config} does not exist")
    sys.stdout.flush()
    os.execv(sys.executable, firmware_argv(args))
    return 0  # not reached
