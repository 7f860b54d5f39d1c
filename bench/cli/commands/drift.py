"""``hilbench drift RESULTS``: parameters over a campaign's runs, control charts, change points, campaign pages."""

from __future__ import annotations

import argparse
import math
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "drift", help="drift of identified parameters over runs (EWMA, CUSUM, change points) and campaign pages",
        description="Read the results of hilbench analyse; fit each parameter's dependence on temperature and load "
        "over a baseline of runs; chart the residuals (EWMA, CUSUM) and find change points (PELT). Writes "
        "drift.json, PNG figures and one self-contained HTML page per campaign. See docs/campaign-analysis.md.")
    p.add_argument("results", type=Path, help="results folder of hilbench analyse (or its results.parquet)")
    p.add_argument("-o", "--output", type=Path, default=None, help="output folder (default: RESULTS/drift)")
    p.add_argument("--parameters", default="breakaway,viscous",
                   help="comma-separated parameters to follow (default breakaway,viscous; also inertia, coulomb)")
    p.add_argument("--baseline", type=int, default=None, metavar="N",
                   help="baseline: the first N runs of each series (default: half the runs, at most 50, at least "
                   "two more than the coefficients fitted; the line printed says which)")
    p.add_argument("--baseline-runs", default=None, metavar="KEY,...",
                   help="baseline: these runs instead (run keys, or campaign/key)")
    p.add_argument("--false-alarm", type=float, default=5.0, metavar="PCT",
                   help="chance that a stationary campaign raises any alarm, in %% (default 5); the limits are "
                   "calibrated for it on simulated campaigns of the same design")
    p.add_argument("--penalty", type=float, default=None, help="change-point penalty on the clipped scores "
                   "(default: calibrated for --false-alarm)")
    p.add_argument("--no-page", action="store_true", help="do not write the campaign pages")
    p.add_argument("--overwrite", action="store_true", help="replace an earlier drift report in the output folder")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import pyarrow.parquet as pq

    from hilbench.analysis.drift.monitor import DriftSettings, monitor
    from hilbench.analysis.drift.plots import write_figures
    from hilbench.bench.campaign_analysis.table import TABLE_NAME
    from hilbench.bench.errors import BenchError
    from hilbench.bench.storage import outputs
    from hilbench.common.units import AXES, schema_units

    table = args.results / TABLE_NAME if args.results.is_dir() else args.results
    if not table.is_file():
        raise BenchError(f"{args.results}: no {TABLE_NAME} (run hilbench analyse first)")
    out = args.output or table.parent / "drift"
    outputs.refuse_existing("-o", out / "drift.json", args.overwrite)
    outputs.refuse_inputs({"-o": out}, [table])
    try:
        t = pq.read_table(table)
    except (OSError, ValueError) as exc:  # pyarrow: ArrowIOError, ArrowInvalid
        raise BenchError(f"{table}: not a readable Parquet table ({' '.join(str(exc).split())})") from None
    units = {axis: schema_units(t.schema, axis) for axis in AXES}  # a column's unit follows the row's axis
    params = tuple(p.strip() for p in args.parameters.split(",") if p.strip())
    unknown = [p for p in params if p not in units["rotary"] or f"{p}_se" not in units["rotary"]]
    if unknown or not params:
        raise BenchError(f"--parameters: {unknown[0] if unknown else '(none)'!r} is not an identified parameter "
                         f"with a standard error in {table}")
    if not 0 < args.false_alarm < 100:
        raise BenchError(f"--false-alarm {args.false_alarm:g}: must lie in (0, 100) %")
    if args.penalty is not None and not (math.isfinite(args.penalty) and args.penalty > 0):
        raise BenchError(f"--penalty {args.penalty:g}: must be finite and > 0")
    every_row = t.to_pylist()  # the page shows every step's rows; drift follows identify's
    rows = [r for r in every_row if r.get("step") == "identify"]
    settings = DriftSettings(parameters=params, baseline=args.baseline, penalty=args.penalty,
                             false_alarm=args.false_alarm / 100.0,
                             baseline_runs=tuple(k.strip() for k in args.baseline_runs.split(","))
                             if args.baseline_runs else ())
    result = monitor(rows, settings)
    for g in result.groups:
        outputs.say(f"{g.group + ': ' if len(result.groups) > 1 else ''}{g.baseline_line()}")
    out.mkdir(parents=True, exist_ok=True)
    figures = write_figures(result, units, out, outputs.save_figure)
    summary = result.summary()
    summary["figures"] = [p.name for p in figures]
    outputs.write_json(out / "drift.json", summary, indent=1, allow_nan=False)
    axes = {g["group"]: g["axis"] for g in summary["groups"]}
    for name, p in summary["parameters"].items():
        unit = units[axes[p["group"]]][p["parameter"]]
        c = p["covariates"].get("temperature_mean", {})
        dep = (f"temperature {c['coefficient']:.3g} +- {c['se']:.2g} {unit}/K"
               f"{' (found)' if c['found'] else ' (not significant)'}" if "coefficient" in c else
               "no temperature dependence fitted")
        cps = ", ".join(f"{cp['run']} ({cp['shift']:+.3g} {unit})" for cp in p["change_points"]) or "none"
        outliers = ", ".join(f"{o['run']} (z {o['z']:+.2g})" for o in p["outliers"]) or "none"
        extra = f"; {len(p['extrapolated'])} run(s) beyond the baseline's covariate range" if p["extrapolated"] else ""
        outputs.say(f"{name}: {dep}; change points: {cps}; EWMA alarms {len(p['ewma_alarms'])}, "
                    f"CUSUM alarms {len(p['cusum_alarms'])}; outliers: {outliers}{extra}")
    if not args.no_page:
        from hilbench.bench.campaign_analysis.page import write_pages

        for page in write_pages(every_row, units, figures, summary, out):
            outputs.say(f"page: {page}")
    outputs.say(f"{len(summary['alarms'])} alarm(s) over {summary['runs']} runs -> {out / 'drift.json'}")
    return 0
