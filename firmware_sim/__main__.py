"""``python -m hilbench.firmware_sim``: run the simulated amplifier on a new pseudo-terminal or a python-can bus.

With ``--serial`` the first line on stdout is the pty path to open (nothing else is printed there).
"""

from __future__ import annotations

import argparse
import math
import sys

from hilbench.common.can import enlarge_receive_buffer

PACINGS = ("realtime", "lockstep")
#: Node ids each kind of simulated device can take: the hilbench protocol's 4-bit node; CiA 402 1..126 (127 is
#: the host's own heartbeat id, which the drive would otherwise hear as the host); ODrive's 6-bit node (its
#: 11-bit ids are node << 5 | command); a moteus controller id 1..126 (127 is its broadcast id).
NODE_RANGES = {"can": (1, 15), "canopen": (1, 126), "odrive": (0, 63), "moteus": (1, 126)}


def check_bus_args(kind: str, interface: str, channel: str, node: int) -> None:
    """Raise ValueError (one line) for a bus, channel or node the simulated device of ``kind`` (can, canopen,
    odrive, moteus) cannot serve on, before any bus is opened."""
    import ipaddress

    import can

    if interface not in can.VALID_INTERFACES:
        raise ValueError(f"--interface {interface!r} is not a python-can interface (known: "
                         f"{', '.join(sorted(can.VALID_INTERFACES))})")
    low, high = NODE_RANGES[kind]
    if not low <= node <= high:
        raise ValueError(f"--node must be {low}..{high} for --{kind}, got {node}")
    if interface == "udp_multicast":
        try:
            multicast = ipaddress.ip_address(channel).is_multicast
        except ValueError:
            multicast = False
        if not multicast:
            raise ValueError(f"udp_multicast needs a multicast group address as its channel (e.g. 239.74.163.2), "
                             f"got {channel!r}")


def check_pid_position(gains: list[float] | None, kind: str) -> None:
    """Refuse --pid-position (ValueError, one line) but on a moteus, or with a gain negative or not finite."""
    if gains is None:
        return
    if kind != "moteus":
        raise ValueError("--pid-position is the simulated moteus controller's (--moteus)")
    if not all(0.0 <= g < math.inf for g in gains):
        raise ValueError(f"--pid-position gains must be finite and >= 0, got {' '.join(f'{g:g}' for g in gains)}")


def build_parser(prog: str = "python -m hilbench.firmware_sim") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog,
                                     description="Simulated hilbench amplifier (a real protocol peer).")
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--serial", action="store_true",
                       help="serve on a new pseudo-terminal; its path is the first line printed")
    where.add_argument("--can", metavar="CHANNEL", help="serve on this python-can channel (e.g. vcan0)")
    where.add_argument("--canopen", metavar="CHANNEL",
                       help="be a simulated CiA 402 drive on this python-can channel (e.g. 239.74.163.2 with "
                            "--interface udp_multicast); prints its canopen:// URL")
    where.add_argument("--odrive", metavar="CHANNEL",
                       help="be a simulated ODrive axis (CAN Simple) on this python-can channel; prints its "
                            "odrive:// URL")
    where.add_argument("--moteus", metavar="CHANNEL",
                       help="be a simulated moteus controller (its register protocol over CAN-FD) on this "
                            "python-can channel; prints its moteus:// URL")
    parser.add_argument("--clock", choices=("real", "sync"), default="real",
                        help="--canopen, --moteus: plant time follows real time between SYNCs or commands "
                             "(default) or their count")
    parser.add_argument("--order", choices=("apply-then-sample", "sample-then-apply"), default="apply-then-sample",
                        help="--canopen: whether a SYNC's TPDO reports the state after (default) or before the "
                             "controlword received with that SYNC")
    parser.add_argument("--enable-latency", type=int, choices=range(4), default=0, metavar="{0..3}",
                        help="--canopen: SYNCs between an enable received by RPDO and operation enabled")
    parser.add_argument("--pid-position", nargs=4, type=float, metavar=("KP", "KI", "KD", "ILIMIT"),
                        help="--moteus: the controller's servo.pid_position kp (N*m/rev), ki (N*m/(rev*s)), kd "
                             "(N*m*s/rev) and ilimit (N*m), closed inside it at every plant step; default 4 0 0.1 0")
    parser.add_argument("--udp-port", type=int, default=None,
                        help="--canopen, --odrive, --moteus on udp_multicast: UDP port (default 43113; buses on one "
                             "port hear each other)")
    parser.add_argument("--interface", default="socketcan",
                        help="python-can interface for --can (socketcan, udp_multicast, pcan...; "
                             "default socketcan)")
    parser.add_argument("--node", type=int, default=1,
                        help="CAN node id (default 1): 1..15 with --can, 1..126 with --canopen, 0..63 with --odrive, "
                             "the controller id 1..126 with --moteus")
    parser.add_argument("--fd", action="store_true", help="use CAN FD frames")
    parser.add_argument("--config",
                        help="simulator TOML (plant and injected effects); default: the packaged one")
    parser.add_argument("--seed", type=int, help="override the plant's random seed")
    parser.add_argument("--pacing", choices=PACINGS, default="realtime",
                        help="realtime (default) or lockstep (as fast as flow control allows, for tests)")
    parser.add_argument("--tick", type=float, default=0.004, help="realtime loop period, s (default 0.004)")
    parser.add_argument("--parent-pid", type=int, default=None,
                        help="exit once this process is gone (sim:// passes the host's pid); the watchdog has "
                             "zeroed the current and latched its fault by then")
    return parser


def watch_parent(pid: int, stop, grace: float = 2.0, period: float = 0.25) -> None:
    """Set ``stop`` once process ``pid`` no longer exists (or is no longer our parent), after ``grace`` s."""
    import os
    import time

    while not stop.is_set():
        try:
            os.kill(pid, 0)
            alive = os.getppid() == pid
        except ProcessLookupError:
            alive = False
        except PermissionError:
            alive = True
        if not alive:
            time.sleep(grace)
            stop.set()
            return
        time.sleep(period)


def _serve_drive(args, sim) -> int:
    import threading

    from hilbench.firmware_sim.devices import cia402_drive, moteus_sim, odrive_sim

    stop = threading.Event()
    if args.parent_pid is not None:
        threading.Thread(target=watch_parent, args=(args.parent_pid, stop), daemon=True).start()
    if args.odrive:
        return odrive_sim.serve(args.interface, args.odrive, args.node, sim, stop, port=args.udp_port)
    if args.moteus:
        gains = dict(zip(("kp", "ki", "kd", "ilimit"), args.pid_position or (), strict=False))
        return moteus_sim.serve(args.interface, args.moteus, args.node, sim, args.clock, stop=stop, port=args.udp_port,
                                **gains)
    return cia402_drive.serve(args.interface, args.canopen, args.node, sim, args.clock, stop=stop, port=args.udp_port,
                              order=args.order, enable_latency=args.enable_latency)


def main(argv: list[str] | None = None, prog: str = "python -m hilbench.firmware_sim") -> int:
    args = build_parser(prog).parse_args(argv)
    import can

    from hilbench.firmware_sim.devices.core_c import CoreDevice
    from hilbench.firmware_sim.devices.device import CanTransport, PtyTransport, serve
    from hilbench.firmware_sim.devices.sim_config import load_sim_config

    try:
        sim = load_sim_config(args.config, seed=args.seed)
        if args.canopen or args.odrive or args.moteus:
            kind = "canopen" if args.canopen else "odrive" if args.odrive else "moteus"
            check_bus_args(kind, args.interface, args.canopen or args.odrive or args.moteus, args.node)
            check_pid_position(args.pid_position, kind)
            return _serve_drive(args, sim)
        if not 0.0005 <= args.tick <= 0.1:
            raise ValueError(f"--tick must be within 0.0005..0.1 s, got {args.tick}")
        if args.serial:
            transport = PtyTransport()
        else:
            check_bus_args("can", args.interface, args.can, args.node)

            bus = can.Bus(interface=args.interface, channel=args.can, fd=args.fd)
            enlarge_receive_buffer(bus)
            transport = CanTransport(bus, args.node, args.fd)
    except (ValueError, OSError, ImportError, RuntimeError, can.CanError) as exc:
        print(f"{prog}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    link = "serial" if args.serial else "can-fd" if args.fd else "can"
    device = CoreDevice(sim, args.pacing, link, args.node, transport.max_block)
    if args.serial:
        print(transport.path, flush=True)
    else:
        print(f"{args.interface}:{args.can} node {args.node}", flush=True)
    import threading

    stop = threading.Event()
    if args.parent_pid is not None:
        threading.Thread(target=watch_parent, args=(args.parent_pid, stop), daemon=True).start()
    try:
        serve(transport, device, args.tick, stop)
    except KeyboardInterrupt:
        pass
    finally:
        transport.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
