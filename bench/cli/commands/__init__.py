"""CLI subcommands, one module each.

Every module here defines ``register(subparsers) -> None``, which adds its parser and sets
``func=<callable(args) -> int>``. ``bench.cli`` discovers the modules, so adding a subcommand never
touches a shared file. A module is named after the one command it registers (``import_`` for ``import``):
a command line builds only that module's parser (tests/bench/cli/test_parser_per_command.py). Import heavy
libraries inside the command function, not at module level, so that ``hilbench --help`` stays fast.
"""
