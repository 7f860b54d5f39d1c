"""``hilbench demo``: the main job end to end on the simulated bench."""

from __future__ import annotations

import argparse
import math
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="run the main job end to end on the simulated bench",
        description="Start the simulated amplifier (with an effect the demo does not declare), run an "
                    "identification, a validation and a stepped-sine run, list the files, then analyse them.",
    )
    p.add_argument("-o", "--output", dest="out", type=Path, default=Path("demo-out"),
                   help="output folder (default: demo-out)")
    p.add_argument("--overwrite", action="store_true", help="replace the files of an earlier demo in the folder")
    p.add_argument("--duration", type=float, default=20.0, help="identification run length in s (default 20)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hilbench.bench.cli.demo import run_demo

    if not (math.isfinite(args.duration) and 1.0 <= args.duration <= 600.0):
        raise ValueError(f"--duration must be within [1, 600] s, got {args.duration}")
    return run_demo(args.out, args.duration, overwrite=args.overwrite)
