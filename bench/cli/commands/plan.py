"""``hilbench plan``: a break-away probe on the device, then a campaign sized from it (acquisition/planning.py)."""

from __future__ import annotations

import argparse
from pathlib import Path

from hilbench.bench.acquisition.device_options import DEVICE_OPTIONS, add_device_options, settings_from_args
from hilbench.bench.cli.option_errors import options_named


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plan", help="probe the motor's break-away, then write a campaign sized from it",
        description="Play slow current ramps both ways (a few seconds, within --current-limit; the run files go "
                    "to the probe folder), find the break-away and sliding current, J, b and the presliding "
                    "distance, and write a campaign TOML whose identification, stepped sine, chirp and presliding "
                    "runs are sized from them (docs/cli.md, 'hilbench plan'). Play it with hilbench campaign.")
    p.add_argument("-o", "--output", dest="out", type=Path, default=Path("plan.toml"),
                   help="campaign file to write (default plan.toml)")
    p.add_argument("--probe-dir", type=Path, default=None,
                   help="folder of the probe's run files (default: the output's name with -probe, e.g. plan-probe)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing campaign file and probe runs")
    p.add_argument("--sample-rate", type=int, default=10000, help="sample rate of the probe and every run (Hz; "
                   "default 10000)")
    p.add_argument("--duration", type=float, default=20.0,
                   help="length of the identification and the chirp (s; default 20)")
    p.add_argument("--seed", type=int, default=0, help="seed of the identification input (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_device_options(p)
    p.set_defaults(func=run)


def check_outputs(out: Path, probe_dir: Path, overwrite: bool) -> None:
    """Refuse, before anything moves, a campaign file or probe folder that could not be written at the end:
    an existing file without --overwrite, a missing or read-only folder, a folder where a file goes."""
    import os

    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs

    outputs.refuse_existing("--output", out, overwrite)
    if out.is_dir():
        raise BenchError(f"--output {out} is a folder; give the campaign file's path, e.g. {out / 'plan.toml'}")
    if probe_dir.exists() and not probe_dir.is_dir():
        raise BenchError(f"--probe-dir {probe_dir} is a file; give a folder for the probe's run files")
    if not overwrite and probe_dir.is_dir() and any(probe_dir.glob("probe-*.h5")):
        raise BenchError(f"--probe-dir {probe_dir} holds probe runs of an earlier plan; use --overwrite to "
                         f"replace them, or another --probe-dir")
    folder = out.parent if str(out.parent) else Path(".")
    if not folder.is_dir():
        raise BenchError(f"--output {out}: the folder {folder} does not exist")
    probe_parent = probe_dir
    while not probe_parent.exists() and probe_parent != probe_parent.parent:  # created with its parents
        probe_parent = probe_parent.parent
    for option, where in (("--output", folder), ("--probe-dir", probe_parent)):
        if not os.access(where, os.W_OK | os.X_OK):
            raise BenchError(f"{option}: cannot write in {where} (permission denied)")


def run(args: argparse.Namespace) -> int:
    from hilbench.bench.acquisition.planning import plan_experiments
    from hilbench.bench.acquisition.progress import ProgressBar
    from hilbench.bench.acquisition.protocols import SAMPLE_RATES
    from hilbench.bench.acquisition.runner import signals_as_interrupt
    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs

    if args.sample_rate not in SAMPLE_RATES:
        raise BenchError(f"--sample-rate {args.sample_rate} Hz is not one of {', '.join(map(str, SAMPLE_RATES))} Hz")
    if not 0.1 <= args.duration <= 3600:
        raise BenchError(f"--duration {args.duration:g} s is outside [0.1, 3600] s")
    probe_dir = args.probe_dir or args.out.with_name(args.out.stem + "-probe")
    check_outputs(args.out, probe_dir, args.overwrite)  # before the probe moves the motor
    with options_named(DEVICE_OPTIONS):
        settings = settings_from_args(args)
    bars: list[ProgressBar] = []
    last = [0]  # samples done in the probe run under way: a smaller count starts the next probe's bar

    def progress(p) -> None:
        if not bars or p.done < last[0]:
            bars.append(ProgressBar(disable=args.quiet, desc=f"probe {len(bars) + 1}"))
        last[0] = p.done
        bars[-1].update(p)

    def probed(found) -> None:
        if bars:
            bars[-1].close()
        slid = ", ".join(f"{b:+.3g} A" if b is not None else "no slide" for b in found.breakaway)
        outputs.say(f"probe {found.path} (peak {found.peak:.3g} A): break-away per ramp {slid}", level=2)

    try:
        with signals_as_interrupt():
            plan = plan_experiments(args.device, settings, probe_dir=probe_dir, sample_rate=args.sample_rate,
                                    duration=args.duration, seed=args.seed, overwrite=args.overwrite,
                                    progress=progress, on_probe=probed)
    except KeyboardInterrupt as exc:
        for bar in bars:
            bar.close()
        print(f"hilbench plan: interrupted ({exc or 'Ctrl-C'}); device disarmed, no plan written")
        return 130
    plan.write(args.out)
    for line in plan.lines():
        outputs.say(line)
    outputs.say(f"campaign: {args.out} (play it with: hilbench campaign {args.out})")
    return 0
