"""CLI subcommands, one module each.

Every module here defines ``register(subparsers) -> None``, which adds its parser and sets
``func=<callable(args) -> int>``. ``bench.cli`` discovers the modules, so adding a subcommand never
touches a shared file. Import heavy libraries inside the command function, not at module level,
so that ``bench --help`` stays fast.
"""
