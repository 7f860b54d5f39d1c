"""``hilbench afrf``: AFRF (1st-3rd harmonic) of a measured stepped-sine run, or of a simulated model."""

from __future__ import annotations

import sys

MODELS = ("paper", "coulomb", "equivalent")
MAX_FREQUENCIES = 1000  # simulated grid points per amplitude: each is a separate simulation


def register(subparsers) -> None:
    from hilbench.bench.analysis_input import add_memory_option, add_record_options

    parser = subparsers.add_parser(
        "afrf",
        help="absolute frequency response of the 1st-3rd harmonic (stepped-sine run or simulated model)",
        description="Magnitude of the displacement at f, 2f and 3f over whole periods of each step's "
        "steady state (docs/science.md §5). Give a stepped-sine RUN.h5 (hilbench run stepped_sine), or --model "
        "to simulate the paper's Maxwell-slip system, a Coulomb system or the closed-form equivalent.",
    )
    parser.add_argument("run", nargs="?", help="stepped-sine run file (.h5)")
    parser.add_argument("--model", choices=MODELS,
                        help="simulate instead: paper = Maxwell-slip N=16 (m=1, h=1.64, d=0.656), coulomb = "
                        "m=1 with Fc=--coulomb, equivalent = closed-form F_k, F_d tables of the paper system")
    parser.add_argument("--amplitudes", type=float, nargs="+", default=[0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0],
                        metavar="G", help="drive amplitudes, N (simulation; default the paper's range)")
    parser.add_argument("--frequencies", type=float, nargs="+", default=None, metavar="F",
                        help="frequencies, Hz (simulation; a list, as in `hilbench run stepped_sine`; default 20 "
                        "log-spaced from 0.1 to 10 Hz, see --log-frequencies)")
    parser.add_argument("--log-frequencies", type=float, nargs=3, default=None, metavar=("F_MIN", "F_MAX", "N"),
                        help="instead of --frequencies: N log-spaced frequencies from F_MIN to F_MAX, Hz")
    parser.add_argument("--spring", type=float, default=0.0, help="linear spring k, N/m (default 0, as Fig 13)")
    parser.add_argument("--coulomb", type=float, default=1.5, help="Coulomb level Fc, N (default 1.5)")
    parser.add_argument("--samples-per-period", type=int, default=400, help="simulation (default 400)")
    parser.add_argument("--settle-periods", type=int, default=40, help="minimum settle periods (default 40)")
    parser.add_argument("--settle-time", type=float, default=60.0,
                        help="minimum settle time, s, for slow modes (default 60)")
    parser.add_argument("--measure-periods", type=int, default=10, help="measured periods (default 10)")
    parser.add_argument("--workers", type=int, help="processes (default: all cores)")
    parser.add_argument("--json", metavar="OUT.json", help="write the AFRF as JSON ('-': stdout)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --json or --plot file")
    parser.add_argument("--plot", metavar="OUT.png", help="write the paper-style figure")
    add_record_options(parser)
    add_memory_option(parser)
    parser.set_defaults(func=run)


def _simulate(args):
    import numpy as np

    from hilbench.analysis.afrf.frf import closed_form_equivalent, coulomb_system, settle_schedule, simulate_afrf
    from hilbench.firmware_sim.engine.friction_models import PAPER_D, PAPER_H, paper_system

    if args.frequencies is not None and args.log_frequencies is not None:
        raise ValueError("give --frequencies or --log-frequencies, not both")
    if args.frequencies is not None:
        freqs = np.asarray(args.frequencies, float)
        if not np.all(np.isfinite(freqs) & (freqs > 0)):
            raise ValueError("--frequencies must all be positive, finite Hz")
    else:
        f_min, f_max, n = args.log_frequencies or (0.1, 10.0, 20)
        if not (0 < f_min <= f_max < float("inf")) or not (1 <= n <= MAX_FREQUENCIES) or n != int(n):
            raise ValueError(f"--log-frequencies needs 0 < F_MIN <= F_MAX and a whole N in [1, {MAX_FREQUENCIES}]")
        freqs = np.geomspace(f_min, f_max, int(n))
    if freqs.size > MAX_FREQUENCIES:
        raise ValueError(f"{freqs.size} frequencies: at most {MAX_FREQUENCIES}")
    params = {
        "paper": lambda: paper_system(spring=args.spring),
        "coulomb": lambda: coulomb_system(args.coulomb, 1.0, args.spring),
        "equivalent": lambda: closed_form_equivalent(PAPER_H, PAPER_D, 1.0, args.spring),
    }[args.model]()
    return simulate_afrf(params, args.amplitudes, freqs, samples_per_period=args.samples_per_period,
                         settle_periods=settle_schedule(freqs, args.settle_periods, args.settle_time),
                         measure_periods=args.measure_periods, workers=args.workers, label=args.model,
                         axis="linear")


def _summary(result) -> str:
    import numpy as np

    m = result.magnitudes
    lines = [f"AFRF {result.label}: {result.amplitudes.size} amplitudes x {result.frequencies.size} frequencies "
             f"({result.frequencies.min():.4g}-{result.frequencies.max():.4g} Hz), |X| in "
             f"{result.displacement_unit}",
             f"{'G (' + result.amplitude_unit + ')':>10} {'max |X(f)|':>12} {'at f (Hz)':>10} "
             f"{'max 2f/1f':>10} {'max 3f/1f':>10} {'worst conv':>10}"]
    with np.errstate(divide="ignore", invalid="ignore"):
        for i, amp in enumerate(result.amplitudes):
            h1 = m[i, :, 0]
            if not np.any(np.isfinite(h1)):
                lines.append(f"{amp:>10.4g}  (no complete step)")
                continue
            j = int(np.nanargmax(h1))
            r2 = np.nanmax(m[i, :, 1] / h1) if m.shape[-1] > 1 else np.nan
            r3 = np.nanmax(m[i, :, 2] / h1) if m.shape[-1] > 2 else np.nan
            lines.append(f"{amp:>10.4g} {h1[j]:>12.4g} {result.frequencies[j]:>10.4g} {r2:>10.2e} {r3:>10.2e} "
                         f"{np.nanmax(result.convergence[i]):>10.1e}")
    n_bad = int(np.sum(result.convergence > 1e-3))
    if n_bad:
        lines.append(f"note: {n_bad} step(s) change by more than 1e-3 of |X(f)| from one period to the next "
                     "(not in steady state: settle longer)")
    return "\n".join(lines)


def _measured(args):
    """The AFRF of ``args.run`` through the registry's entry: read whole when it fits ``--memory``, else one step
    window at a time (the same result); a one-line error, before reading the samples, when neither fits."""
    from hilbench.bench.analysis_input import memory_budget, read_runs
    from hilbench.bench.analysis_progress import progress_bar

    entry, inputs, _ = read_runs("afrf", args, [args.run], [], memory_budget(args.memory), warn=False)
    with progress_bar("afrf") as progress:
        return entry.analyse(inputs, progress=progress).value


def run(args) -> int:
    from hilbench.analysis.afrf.frf import plot_afrf
    from hilbench.bench.storage import outputs

    if (args.run is None) == (args.model is None):
        raise ValueError("give either a stepped-sine RUN.h5 or --model (not both)")
    outputs.refuse_inputs({"--json": args.json, "--plot": args.plot}, [args.run])
    for option, target in (("--json", args.json), ("--plot", args.plot)):
        outputs.refuse_existing(option, target, args.overwrite)
    if args.run:
        result = _measured(args)
        if result.settings.get("incomplete"):
            print(f"warning: INCOMPLETE RECORD {args.run}: {result.settings['incomplete']} "
                  "(analysed with --allow-incomplete)", file=sys.stderr)
        for line in result.warnings:
            print(f"hilbench afrf: warning: {line}", file=sys.stderr)
    else:
        result = _simulate(args)
    outputs.say(_summary(result), args.json)
    if args.json:
        outputs.write_json(args.json, result.to_dict())
        if args.json != outputs.STDOUT:
            outputs.say(f"wrote {args.json}", args.json)
    if args.plot:
        fig = plot_afrf(result, title=f"AFRF {result.label}", measured=args.run is not None)
        outputs.save_figure(fig, args.plot, dpi=120)
        outputs.say(f"wrote {args.plot}", args.json)
    return 0
