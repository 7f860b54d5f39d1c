"""``hilbench run {identify,chirp,afrf,presliding}``: run one measurement protocol on a device and log it."""

from __future__ import annotations

import argparse
from pathlib import Path

from hilbench.bench.acquisition.device_options import add_device_options, settings_from_args
from hilbench.bench.acquisition.protocols import PROTOCOLS, Protocol
from hilbench.bench.cli.option_errors import options_named

RUNNABLE: dict[str, type[Protocol]] = dict(PROTOCOLS)  # every protocol of the table (campaign names)
# Old spellings of `run`'s protocol names, kept as argparse aliases (they map onto the one name; docs/cli.md).
ALIASES = {"identification": ["identify"], "stepped_sine": ["afrf"]}


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


def protocol_from_args(cls: type[Protocol], args: argparse.Namespace) -> Protocol:
    values = {name: getattr(args, name) for name in cls.specs() if getattr(args, name, None) is not None}
    with options_named(cls.specs()):
        return cls.from_dict(values)


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
    from hilbench.bench.acquisition.device_options import DEVICE_OPTIONS
    from hilbench.bench.acquisition.progress import ProgressBar
    from hilbench.bench.acquisition.runner import Bench, RunControl, signals_as_interrupt
    from hilbench.bench.storage import outputs

    protocol = protocol_from_args(args.protocol_class, args)
    with options_named(DEVICE_OPTIONS):
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
    outputs.say(f"{result.status}: {result.path} ({result.samples} samples, uid {result.uid})")
    return 0 if result.status == "completed" else 1
