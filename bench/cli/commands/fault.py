"""``hilbench fault {show,clear} [--device URL]``: read or clear the faults a device has latched (the default
device when --device is not given, as every command that drives one)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    from hilbench.drivers.device_url import describe_schemes

    parser = subparsers.add_parser(
        "fault", help="show or clear a device's latched faults",
        description="Faults (watchdog, limits, e-stop, buffer underrun) stay latched in the device until "
                    "cleared; a latched fault refuses ARM. 'clear' clears them and prints what was cleared.")
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, text in (("show", "print the latched faults"), ("clear", "clear every latched fault")):
        q = actions.add_parser(name, help=text, description=text)
        q.add_argument("--device", default=None, help=f"device URL: {describe_schemes()} (default "
                       "$HILBENCH_DEVICE, the config file's 'device', else sim://; docs/cli.md)")
        q.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hilbench.drivers.device_url import open_device

    with open_device(args.device) as device:  # every device kind answers faults(), history(), clear_faults()
        faults = device.faults()
        print(f"faults: {'; '.join(faults) if faults else 'none'}")
        for line in device.history():
            print(line)
        if args.action == "clear":
            device.clear_faults()  # CiA 402: the fault-reset edge; ODrive: Clear_Errors; hilbench: CLEAR_FAULTS
            now = device.faults()
            print(f"cleared; faults now: {'; '.join(now) if now else 'none'}")
    return 0
