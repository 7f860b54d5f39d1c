"""``hilbench run {identify,chirp,afrf,presliding}``: run one measurement protocol on a device and log it."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from hilbench.bench.protocols import PROTOCOLS, Protocol

RUNNABLE: dict[str, type[Protocol]] = dict(PROTOCOLS)  # every protocol of the table (campaign names)
# Old spellings of `run`'s protocol names, kept as argparse aliases (they map onto the one name; docs/cli.md).
ALIASES = {"identification": ["identify"], "stepped_sine": ["afrf"]}
DEVICE_OPTIONS = {
    "current_limit": ("A", "device current limit"),
    "velocity_limit": ("rad/s", "device velocity limit"),
    "position_min": ("rad", "lower end of the position window"),
    "position_max": ("rad", "upper end of the position window"),
    "watchdog_timeout": ("s", "device watchdog timeout (0 = off)"),
    "torque_constant": ("N*m/A", "calibration: torque constant"),
    "counts_per_rev": ("counts", "calibration: encoder counts per motor revolution"),
    "ratio": ("1", "calibration: motor revolutions per load revolution"),
    "position_kp": ("A/rad", "position loop: proportional gain (position mode)"),
    "position_ki": ("A/(rad*s)", "position loop: integral gain (0 = off)"),
    "position_kd": ("A*s/rad", "position loop: derivative gain (0 = off)"),
    "position_i_limit": ("A", "position loop: bound of the integral term"),
    "position_d_cutoff": ("Hz", "position loop: low-pass of the derivative (0 = unfiltered)"),
}


def add_protocol_options(parser: argparse.ArgumentParser, cls: type[Protocol]) -> None:
    """One option per protocol parameter, with unit, range and default from the protocol's SPECS."""
    defaults = cls()
    for name, spec in cls.specs().items():
        default = getattr(defaults, name)
        unit = spec.unit if spec.unit != "setpoint" else "A or rad/s"
        rng = f" [{spec.minimum:g}, {spec.maximum:g}]" if spec.minimum is not None else ""
        help_ = f"{spec.help} ({unit}{rng}; default {default})" if unit else f"{spec.help} (default {default})"
        flag = "--" + name.replace("_", "-")
        if spec.kind == "floats":
            parser.add_argument(flag, dest=name, type=float, nargs="+", default=None, help=help_)
        elif spec.kind == "choice":
            parser.add_argument(flag, dest=name, choices=spec.choices, default=None, help=help_)
        elif spec.kind == "str":
            parser.add_argument(flag, dest=name, default=None, help=help_)
        else:
            parser.add_argument(flag, dest=name, type=int if spec.kind == "int" else float, default=None,
                                help=help_)


def add_device_options(parser: argparse.ArgumentParser) -> None:
    from hilbench.bench.runner import DeviceSettings
    from hilbench.drivers.device_url import describe_schemes

    parser.add_argument("--device", default=None, help=f"device URL: {describe_schemes()} (default "
                        "$HILBENCH_DEVICE, the config file's 'device', else sim://: the simulated bench; docs/cli.md)")
    defaults = DeviceSettings()
    for name, (unit, text) in DEVICE_OPTIONS.items():
        parser.add_argument("--" + name.replace("_", "-"), dest=name, default=None,
                            type=int if name == "counts_per_rev" else float,
                            help=f"{text} ({unit}; default {getattr(defaults, name)})")


def protocol_from_args(cls: type[Protocol], args: argparse.Namespace) -> Protocol:
    values = {name: getattr(args, name) for name in cls.specs() if getattr(args, name, None) is not None}
    return cls.from_dict(values)


def settings_from_args(args: argparse.Namespace):
    """Device settings: the options given, over the config file's ``[settings]``, over the protocol's
    ``RECOMMENDED_SETTINGS``, over the defaults."""
    from hilbench.bench.runner import DeviceSettings
    from hilbench.bench.user_config import default_settings

    values = {name: getattr(args, name) for name in DEVICE_OPTIONS if getattr(args, name, None) is not None}
    for name, value in values.items():
        if isinstance(value, float) and math.isnan(value):
            raise ValueError(f"--{name.replace('_', '-')} is NaN")
    protocol = getattr(args, "protocol_class", None)
    recommended = protocol.RECOMMENDED_SETTINGS if protocol else {}
    return DeviceSettings(**{**recommended, **default_settings(), **values})


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run a measurement protocol on a device and log it to an HDF5 run file",
                       description="Run a protocol: startup (configure, arm), execute (stream, log), "
                                   "shutdown (always: zero current, disarm). Ctrl-C stops safely.")
    kinds = p.add_subparsers(dest="protocol", metavar="PROTOCOL", required=True)
    for cmd, cls in RUNNABLE.items():
        q = kinds.add_parser(cmd, aliases=ALIASES.get(cmd, []), help=(cls.__doc__ or "").split("\n")[0],
                             description=" ".join((cls.__doc__ or "").split()))
        q.add_argument("-o", "--output", dest="out", type=Path, default=None,
                       help="run file to write (default runs/<protocol>-<uid>.h5)")
        q.add_argument("--overwrite", action="store_true", help="replace an existing run file")
        q.add_argument("--operator", default="", help="operator name, stored in the run file")
        q.add_argument("--notes", default="", help="free-text notes, stored in the run file")
        q.add_argument("--quiet", action="store_true", help="no progress bar")
        add_protocol_options(q, cls)
        add_device_options(q)
        q.set_defaults(func=run, protocol_class=cls)


def run(args: argparse.Namespace) -> int:
    from hilbench.bench.progress import ProgressBar
    from hilbench.bench.runner import Bench, RunControl, signals_as_interrupt

    protocol = protocol_from_args(args.protocol_class, args)
    settings = settings_from_args(args)
    control = RunControl()
    with signals_as_interrupt(control=control), Bench.open(args.device, settings) as bench, \
            ProgressBar(disable=args.quiet) as bar:
        try:
            result = bench.run(protocol, args.out, operator=args.operator, notes=args.notes,
                               progress=bar.update, overwrite=args.overwrite, control=control)
        except KeyboardInterrupt as exc:
            bar.close()
            print(f"hilbench run: interrupted ({exc or 'Ctrl-C'}); device disarmed, run file marked aborted")
            return 130
    print(f"{result.status}: {result.path} ({result.samples} samples, uid {result.uid})")
    return 0 if result.status == "completed" else 1
