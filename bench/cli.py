"""The ``hilbench`` command line: discovers subcommands in :mod:`hilbench.bench.commands`."""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys

import hilbench.bench.commands as commands
from hilbench.bench import __version__
from hilbench.bench.errors import BenchError


def _user_errors() -> tuple[type[BaseException], ...]:
    errors: list[type[BaseException]] = [BenchError, ValueError, OSError, LookupError]
    try:
        from hilbench.drivers.errors import DriverError

        errors.append(DriverError)
    except ImportError:  # drivers is part of the same distribution; this only guards partial checkouts
        pass
    return tuple(errors)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hilbench",
        description="hilbench: hardware-in-the-loop friction test bench (device, runs, analysis).",
    )
    parser.add_argument("--version", action="version", version=f"hilbench {__version__}")
    parser.add_argument(
        "--traceback", action="store_true", help="show the full traceback on errors (for bug reports)"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"hilbench.bench.commands.{info.name}")
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    show_tb = args.traceback or bool(os.environ.get("HILBENCH_TRACEBACK"))
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("hilbench: interrupted", file=sys.stderr)
        return 130
    except _user_errors() as exc:
        if show_tb:
            raise
        msg = " ".join(str(exc).split()) or type(exc).__name__
        print(f"hilbench {args.command}: error: {msg}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
