"""``hilbench campaign FILE.toml``: play a campaign of runs into a folder, resumable."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("campaign", help="run a campaign TOML (runs x repeats) into a folder, resumable",
                       description="Validate the whole campaign first (file:line: reason), then play every "
                                   "run into OUT/<name>-<repeat>.h5 with OUT/index.json.")
    p.add_argument("file", type=Path, help="campaign TOML (see docs/campaign.md)")
    p.add_argument("-o", "--output", dest="out", type=Path, default=None,
                   help="output folder (default: the file's stem)")
    p.add_argument("--resume", action="store_true", help="skip completed runs, redo crashed or aborted ones")
    p.add_argument("--check", action="store_true", help="only validate the file and list the runs")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hilbench.bench.acquisition.campaign import load_campaign, run_campaign
    from hilbench.bench.acquisition.progress import ProgressBar
    from hilbench.bench.acquisition.runner import signals_as_interrupt
    from hilbench.bench.storage import outputs

    campaign = load_campaign(args.file)  # checks every run's memory against what is available now
    if args.check:
        for r in campaign.runs:
            print(f"{r.key}: {r.protocol.name} {r.protocol.duration:.1f} s ({r.protocol.n_samples} samples, "
                  f"{r.protocol.memory_bytes / 2**20:.1f} MiB peak) on {r.device}")
        peak = max(r.protocol.memory_bytes for r in campaign.runs)
        print(f"{len(campaign.runs)} runs, {sum(r.protocol.duration for r in campaign.runs):.1f} s of device time, "
              f"peak memory {peak / 2**20:.1f} MiB")
        return 0
    out = args.out or args.file.with_suffix("")
    bars: dict[str, ProgressBar] = {}

    def show(ev) -> None:
        if ev.state == "running" and ev.run is not None:
            bar = bars.setdefault(ev.key, ProgressBar(disable=args.quiet, desc=f"[{ev.index + 1}/{ev.total}] "
                                                                             f"{ev.key}"))
            bar.update(ev.run)
        elif ev.state != "running":
            if ev.key in bars:
                bars.pop(ev.key).close()
            outputs.say(f"[{ev.index + 1}/{ev.total}] {ev.key}: {ev.state}")

    try:
        with signals_as_interrupt():
            entries = run_campaign(campaign, out, resume=args.resume, progress=show, say=outputs.say)
    except KeyboardInterrupt as exc:
        for bar in bars.values():
            bar.close()
        print(f"hilbench campaign: interrupted ({exc or 'Ctrl-C'}); device disarmed. Continue with --resume.")
        return 130
    done = sum(entries[r.key]["status"] == "completed" for r in campaign.runs if r.key in entries)  # planned only
    outputs.say(f"{done}/{len(campaign.runs)} runs completed; index: {out / 'index.json'}")
    return 0 if done == len(campaign.runs) else 1
