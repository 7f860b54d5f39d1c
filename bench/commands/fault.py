"""``hilbench fault {show,clear} --device URL``: read or clear the faults a device has latched."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "fault", help="show or clear a device's latched faults",
        description="Faults (watchdog, limits, e-stop, buffer underrun) stay latched in the device until "
                    "cleared; a latched fault refuses ARM. 'clear' clears them and prints what was cleared.")
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, text in (("show", "print the latched faults"), ("clear", "clear every latched fault")):
        q = actions.add_parser(name, help=text, description=text)
        q.add_argument("--device", required=True,
                       help="device URL: serial:///dev/ttyUSB0, can://socketcan/can0?node=1, sim://")
        q.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hilbench.drivers import protocol as p
    from hilbench.drivers.device_url import open_device

    with open_device(args.device) as amp:
        status = amp.status()
        where = f" (first at sample {status.fault_index})" if status.faults else ""
        print(f"faults: {p.describe_faults(status.faults)}{where}")
        if args.action == "clear":
            amp.clear_faults()
            print(f"cleared; faults now: {p.describe_faults(amp.status().faults)}")
    return 0
