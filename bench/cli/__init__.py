"""The command line: ``main`` (the ``hilbench`` entry point), the subcommands in ``commands/``, one module each,
and the demo job. ``python -m hilbench.bench.cli`` runs the same command as ``hilbench``."""

from hilbench.bench.cli.main import build_parser, main, split_global_flags

__all__ = ["build_parser", "main", "split_global_flags"]
