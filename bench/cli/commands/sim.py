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
    where.add_argument("--canopen", metavar="CHANNEL",
                       help="be a simulated CiA 402 drive on this python-can channel (with --interface "
                            "udp_multicast: e.g. 239.74.163.2, this host only); prints its canopen:// URL")
    where.add_argument("--odrive", metavar="CHANNEL", help="be a simulated ODrive axis on this python-can channel")
    where.add_argument("--moteus", metavar="CHANNEL",
                       help="be a simulated moteus controller (CAN-FD) on this python-can channel; prints its "
                            "moteus:// URL")
    parser.add_argument("--clock", choices=("real", "sync"), default="real",
                        help="--canopen, --moteus: the plant follows real time between SYNCs or commands (default) "
                             "or their count")
    parser.add_argument("--udp-port", type=int, default=None,
                        help="--canopen, --odrive, --moteus on udp_multicast: UDP port")
    parser.add_argument("--pid-position", nargs=4, type=float, metavar=("KP", "KI", "KD", "ILIMIT"),
                        help="--moteus: the controller's servo.pid_position kp (N*m/rev), ki (N*m/(rev*s)), kd "
                             "(N*m*s/rev), ilimit (N*m), closed inside it at every plant step (default 4 0 0.1 0); "
                             "a host's URL gives the same kp and kd (&kp=&kd=)")
    parser.add_argument("--order", choices=("apply-then-sample", "sample-then-apply"), default="apply-then-sample",
                        help="--canopen: a SYNC's TPDO reports the state after (default) or before its controlword")
    parser.add_argument("--enable-latency", type=int, choices=range(4), default=0, metavar="{0..3}",
                        help="--canopen: SYNCs between an enable received by RPDO and operation enabled")
    parser.add_argument("--interface", default="socketcan", help="python-can interface for --can")
    parser.add_argument("--node", type=int, default=1,
                        help="CAN node id: 1..15 with --can, 1..126 with --canopen, 0..63 with --odrive, the "
                             "controller id 1..126 with --moteus")
    parser.add_argument("--fd", action="store_true", help="use CAN FD frames")
    parser.add_argument("--config", help="simulator TOML (plant and injected effects)")
    parser.add_argument("--seed", type=int, help="override the plant's random seed")
    parser.add_argument("--pacing", choices=("realtime", "lockstep"), default="realtime",
                        help="realtime (default) or lockstep (as fast as flow control allows)")
    parser.add_argument("--tick", type=float, default=0.004, help="realtime loop period, s")
    parser.set_defaults(func=run)


def firmware_argv(args) -> list[str]:
    """The ``python -m hilbench.firmware_sim`` command line equivalent to ``args``."""
    argv = [sys.executable, "-m", "hilbench.firmware_sim"]
    drive = next((k for k in ("canopen", "odrive", "moteus") if getattr(args, k, None)), None)
    if drive is not None:
        kind = [f"--{drive}", getattr(args, drive)]
        return argv + kind + ["--interface", args.interface, "--node", str(args.node), "--clock", args.clock] \
            + [f"--{k}={getattr(args, k)}" for k in ("config", "seed") if getattr(args, k) is not None] \
            + ([f"--udp-port={args.udp_port}"] if args.udp_port else []) \
            + (["--pid-position", *map(repr, args.pid_position)] if args.pid_position else []) \
            + ([f"--order={args.order}", f"--enable-latency={args.enable_latency}"] if args.canopen else [])
    argv += ["--serial"] if args.serial else ["--can", args.can, "--interface", args.interface,
                                              "--node", str(args.node)]
    if args.fd:
        argv.append("--fd")
    for name in ("config", "seed"):
        if getattr(args, name) is not None:
            argv += [f"--{name}", str(getattr(args, name))]
    return argv + ["--pacing", args.pacing, "--tick", str(args.tick)]


def run(args) -> int:
    if args.config is not None and not os.path.isfile(args.config):
        raise ValueError(f"simulator config {args.config} does not exist")
    if args.config is not None:  # a bad file is one line here, not a traceback in the simulator later
        from hilbench.firmware_sim.devices.sim_config import load_sim_config

        load_sim_config(args.config, seed=args.seed)
    if not args.serial:  # bus, channel and node refused in one line here, not as a traceback in the simulator
        from hilbench.firmware_sim.__main__ import check_bus_args, check_pid_position

        kind = next(k for k in ("can", "canopen", "odrive", "moteus") if getattr(args, k) is not None)
        check_bus_args(kind, args.interface, getattr(args, kind), args.node)
        check_pid_position(args.pid_position, kind)
    sys.stdout.flush()
    os.execv(sys.executable, firmware_argv(args))
    return 0  # not reached
