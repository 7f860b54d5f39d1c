"""Run every benchmark: ``python -m benchmarks [--quick] [--only NAME] [--json OUT]``.

Each module ``benchmarks/bench_<topic>.py`` defines ``run(quick=False) -> list[dict]`` whose results
are ratios against a baseline measured in the same run (see docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
import sys
import time
from pathlib import Path


def discover(only: str | None = None) -> list[str]:
    here = Path(__file__).resolve().parent
    names = sorted(m.name for m in pkgutil.iter_modules([str(here)]) if m.name.startswith("bench_"))
    return [n for n in names if only is None or only in n]


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (a smoke run of a few seconds each)")
    ap.add_argument("--only", help="run only modules whose name contains this")
    ap.add_argument("--json", type=Path, help="also write all results as JSON")
    args = ap.parse_args(argv)
    results = []
    failed = 0
    for name in discover(args.only):
        module = importlib.import_module(f"benchmarks.{name}")
        t0 = time.perf_counter()
        rows = module.run(quick=args.quick)
        print(f"== {name} ({time.perf_counter() - t0:.1f} s)")
        for r in rows:
            ok = r.get("ok")
            mark = {True: "ok", False: "MISS", None: ""}[ok]
            failed += ok is False
            print(f"  {r['name']:<48} {_fmt(r['value']):>12} {r['unit']:<10} "
                  f"vs {r.get('baseline_name') or '-':<22} {_fmt(r.get('baseline_value')):>10} "
                  f"ratio {_fmt(r.get('ratio')):>8}  target {r.get('target') or '-'} {mark}")
            results.append({"module": name, **r})
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    print(f"{len(results)} results, {failed} below target")
    return 0


if __name__ == "__main__":
    sys.exit(main())
