"""``hilbench identify RUN.h5``: identify a Maxwell-slip friction model from a run file."""

from __future__ import annotations

import sys
from pathlib import Path


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "identify",
        help="identify a Maxwell-slip friction model (J, k_i, Delta_i, b) from a run file",
        description="Fit J*theta'' + sum k_i*S_Delta_i[theta] + b*theta' (+ Fc, offset) = tau to the run's "
        "position and torque channels; write the model as JSON (docs/model-file.md).",
    )
    parser.add_argument("run", help="run file (.h5) with 't', 'position' and 'torque' channels")
    parser.add_argument("--validate", metavar="RUN2.h5", help="validation run (same axis)")
    parser.add_argument(
        "--method",
        choices=("lip", "oe", "paper"),
        default="lip",
        help="lip: NNLS on filtered regressors (default, fast); oe: lip then simulation-error "
        "refinement; paper: differential evolution + Nelder-Mead, N=16 (slow)",
    )
    parser.add_argument("--json", required=True, metavar="OUT.json", help="model file to write")
    parser.add_argument("--plots", metavar="DIR", help="write PNG plots into DIR")
    parser.add_argument(
        "--thresholds", type=int, default=64, help="candidate thresholds (default 64; 0: no Maxwell-slip elements)"
    )
    parser.add_argument("--cutoff", type=float, help="zero-phase filter cutoff, Hz (default fs/20)")
    parser.add_argument("--coulomb", action="store_true", help="add a Coulomb term Fc*sign(velocity)")
    parser.add_argument("--offset", action="store_true", help="add a constant torque offset")
    parser.add_argument("--spring", action="store_true", help="add a linear spring K*position")
    parser.add_argument(
        "--torque-timing",
        choices=("auto", "hold_previous", "hold_next", "instant"),
        default="auto",
        help="what torque sample k means: auto (default) = from the file's source (device runs: "
        "hold_previous; EMPS imports: hold_next); hold_previous = mean over [t_k-1, t_k) (a measured "
        "current); hold_next = held over [t_k, t_k+1) (a command); instant = value at t_k",
    )
    parser.add_argument("--refine", action="store_true", help="refine the thresholds (variable projection)")
    parser.set_defaults(func=run)


def _arrays(path: str):
    import numpy as np

    from hilbench.analysis.identification.identify import RunArrays
    from hilbench.bench.errors import BenchError
    from hilbench.bench.runfile import open_run

    run = open_run(path)
    missing = [c for c in ("t", "position", "torque") if c not in run.channels]
    if missing:
        raise BenchError(
            f"{path}: missing channel(s) {', '.join(missing)}; identification needs the "
            "position and the torque (or force)"
        )
    return RunArrays(
        t=np.asarray(run.channel("t"), float),
        torque=np.asarray(run.channel("torque"), float),
        position=np.asarray(run.channel("position"), float),
        axis=run.axis,
        name=Path(path).name,
    )


def run(args) -> int:
    from hilbench.analysis.identification.identify import identify
    from hilbench.analysis.identification.maxwell_fit import LipSettings
    from hilbench.analysis.models.model_file import model_document, write_model
    from hilbench.analysis.run_file import torque_timing_for
    from hilbench.bench.runfile import open_run

    train = _arrays(args.run)
    val = _arrays(args.validate) if args.validate else None
    with open_run(args.run) as r:
        timing = torque_timing_for(str(r.meta.get("source", "device")), args.torque_timing)
        for event in r.events:  # a host-clocked run says how its cycle went (docs/drives.md)
            text = str(event["message"])
            if event["kind"] == "info" and text.startswith("host-clocked timing"):
                print(f"{args.run}: {text}", file=sys.stderr if "UNFIT" in text else sys.stdout)
    settings = LipSettings(
        n_thresholds=args.thresholds,
        cutoff=args.cutoff,
        coulomb=args.coulomb,
        offset=args.offset,
        spring=args.spring,
        timing=timing,
        refine=args.refine,
    )
    res = identify(train, method=args.method, validate=val, settings=settings)
    data = {
        "train": {
            "file": str(Path(args.run).resolve()),
            "samples": int(train.t.size),
            "sample_rate_hz": train.fs,
            "axis": train.axis,
        }
    }
    if val is not None:
        data["validation"] = {
            "file": str(Path(args.validate).resolve()),
            "samples": int(val.t.size),
            "sample_rate_hz": val.fs,
        }
    doc = model_document(res.model, method=res.method, settings=res.settings, figures=res.figures, data=data)
    write_model(args.json, doc)
    f = res.figures
    line = (
        f"{res.method}: J = {res.model.inertia:.6g}, {res.model.ms_stiffness.size} elements, "
        f"break-away {res.model.breakaway:.4g}, b = {res.model.viscous:.4g}; "
        f"train NRMSE torque {f['train_torque_nrmse']:.4f} position {f['train_position_nrmse']:.4f}"
    )
    if val is not None:
        line += (
            f"; validation NRMSE torque {f['validation_torque_nrmse']:.4f} "
            f"position {f['validation_position_nrmse']:.4f} "
            f"(segmented {f['validation_position_nrmse_segmented']:.4f})"
        )
    print(line + f" ({res.wall_time:.2f} s) -> {args.json}")
    if args.plots:
        from hilbench.analysis.identification.plots import write_plots

        for p in write_plots(res, args.plots):
            print(f"plot: {p}")
    return 0
