"""``hilbench examples [-o DIR]``: list the example files that ship with hilbench, or copy them into DIR."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("examples", help="list the shipped example files, or copy them into a folder",
                       description="The docs' commands name example files as examples/NAME (a campaign TOML, a "
                                   "simulator config, scripts). From an installed wheel, 'hilbench examples -o "
                                   "examples' puts them there; without -o the files and their folder are listed.")
    p.add_argument("-o", "--output", dest="out", type=Path, default=None, help="folder to copy the examples into")
    p.add_argument("--overwrite", action="store_true", help="replace example files that exist in the folder")
    p.set_defaults(func=run)


def shipped() -> list:
    """The example files installed with hilbench (importlib.resources traversables), by name."""
    from importlib.resources import files

    return sorted((f for f in files("hilbench.examples").iterdir()
                   if f.is_file() and f.name != "__init__.py" and f.name.endswith((".toml", ".py"))),
                  key=lambda f: f.name)


def run(args: argparse.Namespace) -> int:
    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs

    examples = shipped()
    if args.out is None:
        for f in examples:
            print(f"examples/{f.name}")
        return 0
    present = [f.name for f in examples if (args.out / f.name).exists()]
    if present and not args.overwrite:
        raise BenchError(f"{args.out} holds {', '.join(present)} already; use --overwrite or another --output")
    args.out.mkdir(parents=True, exist_ok=True)
    for f in examples:
        outputs.write_text(args.out / f.name, f.read_text(encoding="utf-8"))
        outputs.say(f"wrote {args.out / f.name}", level=2)
    outputs.say(f"{len(examples)} example files in {args.out}")
    return 0
