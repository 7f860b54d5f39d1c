"""The ``hilbench`` command line: discovers subcommands in :mod:`hilbench.bench.cli.commands`."""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import re
import sys

import hilbench.bench.cli.commands as commands
from hilbench.analysis import execution, output_files
from hilbench.bench import __version__
from hilbench.bench.errors import BenchError
from hilbench.bench.storage import outputs

# Options of the whole command that are accepted anywhere on the line (before a "--"), e.g.
# ``hilbench show RUN.h5 --traceback`` as well as ``hilbench --traceback show RUN.h5``.
GLOBAL_FLAGS = {"-v": "verbose", "--verbose": "verbose", "-q": "quiet", "--quiet": "quiet",
                "--traceback": "traceback"}


def _user_errors() -> tuple[type[BaseException], ...]:
    errors: list[type[BaseException]] = [BenchError, ValueError, OSError, LookupError]
    try:
        from hilbench.drivers.errors import DriverError

        errors.append(DriverError)
    except ImportError:  # drivers is part of the same distribution; this only guards partial checkouts
        pass
    return tuple(errors)


def command_modules() -> list[str]:
    """The modules of :mod:`hilbench.bench.cli.commands` that register a subcommand, sorted by name."""
    return sorted(m.name for m in pkgutil.iter_modules(commands.__path__) if not m.name.startswith("_"))


def command_module(command: str) -> str | None:
    """The module that registers ``command``: its name, or its name + "_" where the name is a Python keyword
    (``import_`` registers ``import``); None for a name no module bears."""
    names = command_modules()
    return next((name for name in (command, command + "_") if name in names), None)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``hilbench`` parser. With ``command``, only that command's module registers (its imports are all a
    command line pays for, e.g. ``hilbench docs`` imports no numpy); with None or a name no module registers,
    every module does, so that the help lists every command and an unknown one is named with the choices."""
    parser = argparse.ArgumentParser(
        prog="hilbench",
        description="hilbench: hardware-in-the-loop friction test bench (device, runs, analysis).",
        epilog="-v/--verbose, -q/--quiet and --traceback are accepted anywhere on the line. The default device "
        "is $HILBENCH_DEVICE, else 'device' in the config file ($HILBENCH_CONFIG, else "
        "$XDG_CONFIG_HOME/hilbench/config.toml, else ~/.config/hilbench/config.toml), else sim://.",
    )
    parser.add_argument("--version", action="version", version=f"hilbench {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="print more (every file written)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary lines")
    parser.add_argument(
        "--traceback", action="store_true", help="show the full traceback on errors (for bug reports)"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    only = command_module(command) if command else None
    for name in [only] if only else command_modules():
        importlib.import_module(f"hilbench.bench.cli.commands.{name}").register(sub)
    if only and command not in sub.choices:  # a module's other spelling (``import_``): the full parser says so
        return build_parser()
    _plain_texts(parser)
    return parser


def named_command(argv: list[str]) -> str | None:
    """The command ``argv`` (without the global flags) names: its first argument unless that is an option
    (``-h``, ``--version``, an abbreviation or a mistake: the full parser answers those)."""
    return argv[0] if argv and not argv[0].startswith("-") else None


# Docstrings (protocol classes, analyses) feed help texts; a terminal shows them as plain text, not reST.
_RST = re.compile(r"``([^`]+)``|:(?:func|class|mod|meth|data|attr):`~?([^`]+)`")


def plain_text(text: str | None) -> str | None:
    """``text`` with reST markup taken out: double backquotes and Sphinx roles keep their content."""
    if not text:
        return text
    return _RST.sub(lambda m: m.group(1) or m.group(2), text)


def _plain_texts(parser: argparse.ArgumentParser) -> None:
    """Every description, epilog and option help of ``parser`` and its subcommands, as plain text."""
    parser.description, parser.epilog = plain_text(parser.description), plain_text(parser.epilog)
    for action in parser._actions:
        action.help = plain_text(action.help)
        if isinstance(action, argparse._SubParsersAction):
            for choice in action._choices_actions:
                choice.help = plain_text(choice.help)
            for sub in set(action.choices.values()):
                _plain_texts(sub)


def split_global_flags(argv: list[str]) -> tuple[list[str], set[str]]:
    """Take the global flags out of ``argv`` wherever they stand (not after ``--``); returns the rest and the
    names of the flags found (``verbose``, ``quiet``, ``traceback``)."""
    rest: list[str] = []
    found: set[str] = set()
    for i, arg in enumerate(argv):
        if arg == "--":
            rest += argv[i:]
            break
        if arg in GLOBAL_FLAGS:
            found.add(GLOBAL_FLAGS[arg])
        else:
            rest.append(arg)
    return rest, found


def _run(args: argparse.Namespace, show_tb: bool) -> int:
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("hilbench: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        raise
    except _user_errors() as exc:
        if show_tb:
            raise
        msg = " ".join(str(exc).split()) or type(exc).__name__
        print(f"hilbench {args.command}: error: {msg}", file=sys.stderr)
        return 2


def main(argv: list[str] | None = None) -> int:
    argv, flags = split_global_flags(list(sys.argv[1:] if argv is None else argv))
    execution.limit_process()  # one BLAS thread, here and in what the command starts (analysis.execution)
    if argv[:1] == ["analyse"]:  # its cluster's fork server starts before the parser is built
        from hilbench.bench.cli.commands.analyse import start_early

        start_early(argv[1:])
    parser = build_parser(named_command(argv))
    args = parser.parse_args(argv)
    args.traceback = "traceback" in flags
    previous, outputs.verbosity = outputs.verbosity, 0 if "quiet" in flags else 2 if "verbose" in flags else 1
    output_files.verbosity = outputs.verbosity  # the analyses' writes say "wrote" at -v too
    outputs.begin_command()
    if "quiet" in flags and hasattr(args, "quiet"):
        args.quiet = True
    show_tb = args.traceback or bool(os.environ.get("HILBENCH_TRACEBACK"))
    try:
        if hasattr(args, "device") and args.device is None:
            from hilbench.bench.acquisition.user_config import default_device

            args.device = default_device()
        rc = _run(args, show_tb)
        sys.stdout.flush()
        return rc
    except BrokenPipeError:
        # The reader went away (``hilbench show RUN.h5 | head``): stop quietly, as a Unix filter does. Point
        # stdout at /dev/null so that the interpreter's final flush does not complain either.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return 141
    except _user_errors() as exc:  # from the default-device look-up
        if show_tb:
            raise
        print(f"hilbench {args.command}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    finally:
        outputs.verbosity = output_files.verbosity = previous


if __name__ == "__main__":
    sys.exit(main())
