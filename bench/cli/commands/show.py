"""``hilbench show RUN.h5``: status, metadata, channel summary and events of a run file; ``--repair`` marks a
crashed run ``crashed`` in the file."""

from __future__ import annotations

import argparse
import json


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "show",
        help="inspect a run file (status, metadata, channels, events); --repair marks a crashed run",
        description=(
            "Print a run file's status, metadata, per-channel summary (unit, min, max, mean) and events. "
            "A file still marked 'running' whose writer is gone is reported as crashed; with --repair the "
            "file itself is marked 'crashed' and made readable by any HDF5 tool again."
        ),
    )
    parser.add_argument("run", metavar="RUN.h5", help="run file (HDF5, schema v1)")
    parser.add_argument("--repair", action="store_true", help="mark a crashed run 'crashed' in the file")
    parser.add_argument(
        "--events", type=int, default=20, metavar="N", help="show at most N events (default 20)"
    )
    parser.add_argument("--json", metavar="PATH", help="also write the summary as JSON to PATH ('-': stdout)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    parser.set_defaults(func=run)


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.6g}"


def run(args: argparse.Namespace) -> int:
    from hilbench.bench.storage import outputs
    from hilbench.common.runfile import SAMPLE_INDEX, channel_summary, open_run, repair

    outputs.refuse_inputs({"--json": args.json}, [args.run])
    outputs.refuse_existing("--json", args.json, args.overwrite)
    repaired = None
    if args.repair:
        repaired = repair(args.run)
    with open_run(args.run) as r:
        status = r.status
        note = ""
        if status == "crashed" and r.stored_status == "running":
            note = " (writer died; file still says 'running': use --repair to mark it)"
        elif repaired == "crashed":
            note = " (marked in the file)"
        channels = channel_summary(r)
        events = r.events
        summary = {
            **r.meta_json,
            "n_samples": r.n_samples,
            "duration_s": r.duration,
            "channels": channels,
            "protocol_arrays": {name: list(r.protocol_array(name).shape) for name in r.protocol_array_names},
            "events": [
                {SAMPLE_INDEX: int(e[SAMPLE_INDEX]), "t": float(e["t"]), "kind": str(e["kind"]),
                 "message": str(e["message"])}
                for e in events
            ],
        }
        lines = [
            r.path,
            f"  status     {status}{note}",
            f"  uid        {r.uid}",
            f"  schema     {r.meta['schema']} v{r.meta['schema_version']}",
            f"  source     {r.meta.get('source', '') or '-'}",
            f"  axis       {r.axis}",
            f"  start      {r.start_time}",
            f"  end        {r.end_time or '-'}",
            f"  samples    {r.n_samples} at {r.sample_rate:g} Hz ({r.duration:.6g} s)",
            f"  operator   {r.meta.get('operator', '') or '-'}",
            f"  notes      {r.meta.get('notes', '') or '-'}",
            "  software   " + ", ".join(f"{k} {v}" for k, v in sorted(r.software.items())),
            f"  device     {json.dumps(r.device, sort_keys=True)}",
            f"  protocol   {r.protocol_name or '-'} {json.dumps(r.protocol_params, sort_keys=True)[:300]}",
        ]
        for name, shape in summary["protocol_arrays"].items():
            lines.append(f"             /protocol/{name} shape {tuple(shape)}")
        lines.append("channels:")
        lines.append(f"  {'name':<14}{'unit':<9}{'n':>10}{'min':>14}{'max':>14}{'mean':>14}")
        for c in channels:
            lines.append(
                f"  {c['name']:<14}{c['unit']:<9}{c['n']:>10}{_fmt(c['min']):>14}{_fmt(c['max']):>14}"
                f"{_fmt(c['mean']):>14}" + (f"  ({c['non_finite']} non-finite)" if c["non_finite"] else "")
                + (f"  (not numeric: {c['not_numeric']})" if "not_numeric" in c else "")
            )
        lines.append(f"events: {len(events)}")
        for e in events[: max(args.events, 0)]:
            lines.append(f"  t={e['t']:<12.6g} #{e[SAMPLE_INDEX]:<10} {e['kind']:<8} {e['message']}")
        if len(events) > args.events:
            lines.append(f"  ... {len(events) - args.events} more")
    outputs.say("\n".join(lines), args.json, level=0)
    if args.json:
        outputs.write_json(args.json, summary, indent=2, sort_keys=True)
    return 0
