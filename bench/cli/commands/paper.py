"""``hilbench paper -o DIR``: regenerate the figures of Tjahjowidodo (2012) on the simulated system and motor."""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "paper",
        help="reproduce the paper's Figs 4-13 and 15-16 (PNGs + summary.md) on the simulated systems",
        description="Simulate the paper's mass-spring system with 16-element Maxwell-slip friction and "
        "the DC "
        "motor model under chirps; compose their skeleton curves (ForceVib), fit them, build the "
        "equivalent models and compare stepped-sine AFRFs. Writes one PNG per paper figure, "
        "summary.md (figure map, key numbers, inferred settings) and summary.json.",
    )
    parser.add_argument(
        "-o", "--output", dest="out", type=Path, required=True, metavar="DIR", help="output folder (created)"
    )
    parser.add_argument("--quick", action="store_true", help="smaller grid (fewer levels and frequencies)")
    parser.add_argument("--json", metavar="PATH", help="also copy summary.json to PATH")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the figures and summaries of an earlier reproduction in DIR, and --json")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hilbench.analysis.reproductions.paper import PaperSettings, reproduce
    from hilbench.analysis.reproductions.paper_figures import write_figures, write_summary
    from hilbench.bench.errors import BenchError

    out: Path = args.out
    if out.exists() and not out.is_dir():
        raise BenchError(f"{out} exists and is not a folder")
    from hilbench.bench.storage import outputs

    # the summary is written last: its presence says DIR holds a whole earlier reproduction
    outputs.refuse_existing("-o", out / "summary.json", args.overwrite)
    outputs.refuse_existing("--json", args.json, args.overwrite)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    result = reproduce(
        PaperSettings.quick() if args.quick else PaperSettings(), progress=lambda msg: print(msg, flush=True)
    )
    figures = write_figures(result, out)
    result.seconds["figures"] = time.perf_counter() - t0 - sum(result.seconds.values())
    md, js = write_summary(result, out)
    if args.json:
        outputs.write_text(args.json, js.read_text())
    print(f"wrote {len(figures)} figures, {md} and {js} in {time.perf_counter() - t0:.1f} s")
    return 0
