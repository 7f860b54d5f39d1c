"""The presliding analysis on long repeats of the nested path (docs/long-runs.md, "presliding"): break-away,
initial stiffness, presliding distance, the block length, the span analysed, peak RSS and wall time, read whole
and chunk by chunk, each in a fresh child process.

    python -m benchmarks.presliding_long DIR 60 600 3600 [--modes whole,stream] [--python PY]

writes ``DIR/presliding_<S>s.h5`` (20 kHz, ``long_run_paper._write_presliding``) where it is missing, then prints
one JSON line per (duration, mode). ``--python``: the interpreter of the analysis (e.g. another checkout's venv,
to measure the code before a change); the records are written by this one. A whole read is skipped past
``WHOLE_MAX_S`` (its arrays alone would be 2.3 GB at an hour).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

FS = 20_000.0
#: s: the longest record read whole
WHOLE_MAX_S = 600.0

_CHILD = r"""
import json, sys, time
path, mode = sys.argv[1], sys.argv[2]

def peak_mib():
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith("VmHWM:")) / 1024

from hilbench.analysis import presliding
from hilbench.analysis.record import load_record
base = peak_mib()  # after the imports: two venvs' numpy and scipy builds differ by ~10 MiB here
t0 = time.perf_counter()
try:
    res = (presliding.analyse(load_record(path), replicates=4) if mode == "whole"
           else presliding.analyse_stream(path, replicates=4)[0])
except Exception as exc:
    print(json.dumps({"error": f"{type(exc).__name__}: {exc}", "wall_s": time.perf_counter() - t0,
                      "peak_rss_mib": peak_mib(), "import_rss_mib": base}))
    raise SystemExit(0)
print(json.dumps({"wall_s": time.perf_counter() - t0, "peak_rss_mib": peak_mib(), "import_rss_mib": base,
                  "block": res.block,
                  "analysed_s": float(res.t[-1] - res.t[0]), "reversals": int(res.reversals.size),
                  "quantities": res.quantities, "uncertainties": res.uncertainties,
                  "parametric_initial_stiffness": (res.parametric.quantities(res.fraction)["initial_stiffness"]
                                                   if res.parametric is not None else None),
                  "warnings": res.warnings}))
"""


def measure(python: str, path: Path, mode: str) -> dict:
    done = subprocess.run([python, "-c", _CHILD, str(path), mode], capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> None:
    from benchmarks.long_run_paper import _write_presliding

    ap = argparse.ArgumentParser(prog="python -m benchmarks.presliding_long", description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("durations", nargs="+", type=float)
    ap.add_argument("--modes", default="whole,stream")
    ap.add_argument("--python", default=sys.executable)
    args = ap.parse_args(argv)
    args.dir.mkdir(parents=True, exist_ok=True)
    for duration in args.durations:
        path = args.dir / f"presliding_{duration:g}s.h5"
        if not path.exists():
            t0 = time.perf_counter()
            _write_presliding(path, duration, FS)
            print(json.dumps({"wrote": str(path), "wall_s": time.perf_counter() - t0}), flush=True)
        for mode in args.modes.split(","):
            if mode == "whole" and duration > WHOLE_MAX_S:
                continue
            print(json.dumps({"duration_s": duration, "mode": mode, **measure(args.python, path, mode)}), flush=True)


if __name__ == "__main__":
    main()
