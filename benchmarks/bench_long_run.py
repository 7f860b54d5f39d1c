"""Long runs: peak memory and wall time of the identification against the run's length (issue #26).

A record of the bench's default identification protocol on the DC motor at 10 kHz (the C plant directly, as the
simulated device records it: torque from the measured current, a 2^20-count encoder) is written to a raw file.
Each measurement runs in a fresh child process. Its peak RSS is ``VmHWM`` of /proc/self/status, the high-water
mark of the child's own address space: ``resource.getrusage(RUSAGE_SELF).ru_maxrss`` of a child started by
``subprocess`` (vfork + exec) also holds the parent's high-water mark, which here is the record's generation.
Elsewhere than on Linux the benchmark falls back to ``ru_maxrss``.

- ``stream``: ``identify_chunks`` (the NNLS fit and its figures: equation error, open-loop and segmented
  simulation) reading the file chunk by chunk (the loader's path);
- ``arrays``: ``identify`` on the whole record loaded as arrays (the array API);
- ``identify``, ``residual``, ``compare``: each as its command reads and analyses a run file with ``--memory 2G``
  (:data:`BUDGET`), validated on a second run of another seed: ``identify`` whole when its arrays fit, else
  streamed (``analyse_stream``); ``residual`` reduced to 2 kHz and ``compare`` to 5 kHz while reading, each cut to
  the bounded span that fits the budget (``record_analysis.span_for``, ``compare.reading_plan``;
  docs/long-runs.md, "A bounded span");
- ``afrf``, ``skeleton``, ``presliding`` (``long_run_paper``): read chunk by chunk, on a stepped sine, a chirp and
  a presliding path of the same lengths.

The analyses run on 20 kHz runs of ``LONG_S`` s (600 s, 12 M samples; the issue's target is 3600 s, 72 M:
``python -m benchmarks.bench_long_run --analyses 3600``) against 60 s runs, each analysis in its own child.
``--files`` takes runs recorded elsewhere, e.g. by ``hilbench run identification --device
"sim://?pacing=lockstep"``. Each child reports its wall and CPU time; on a shared machine the CPU time is the
steadier cost.

Cost per sample is compared with a 1-minute run measured in the same benchmark (``quick``: 0.5 s and 1 s, which
checks the rows' shape only).
docs/long-runs.md gives the figures and the method.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

FS = 10_000.0
CHUNK = 1 << 16  # samples per read

#: the child's peak RSS, KiB: VmHWM of its own address space (module docstring)
_PEAK = r"""
import json, resource, sys, time
def peak_kib():
    try:
        with open("/proc/self/status") as fh:
            return next(int(line.split()[1]) for line in fh if line.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
"""

_CHILD = _PEAK + r"""
import numpy as np
from hilbench.analysis.identification.identify import RunArrays, identify, identify_chunks
from hilbench.analysis.identification.maxwell_fit import LipSettings

path, n, fs, mode, chunk = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4], int(sys.argv[5])
base = peak_kib()

def source():
    with open(path, "rb") as fh:  # interleaved (position, torque) float64 pairs
        while True:
            raw = np.fromfile(fh, dtype=np.float64, count=2 * chunk)
            if raw.size == 0:
                return
            yield raw[0::2].copy(), raw[1::2].copy()

settings = LipSettings(timing="hold_previous")
t0 = time.perf_counter()
if mode == "stream":
    res = identify_chunks(source, fs, settings=settings)
else:
    raw = np.fromfile(path, dtype=np.float64)
    x, tau = raw[0::2].copy(), raw[1::2].copy()
    del raw
    res = identify(RunArrays(np.arange(x.size) / fs, tau, x), settings=settings)
wall = time.perf_counter() - t0
peak = peak_kib()
print(json.dumps({"wall_s": wall, "peak_rss_mib": peak / 1024, "import_rss_mib": base / 1024,
                  "inertia": res.model.inertia, "elements": int(res.model.ms_stiffness.size),
                  "position_nrmse": res.figures["train_position_nrmse"]}))
"""


def record(path: Path, duration: float, fs: float = FS, seed: int = 0) -> int:
    """Write the default identification run of ``duration`` s to ``path`` (float64 position, torque pairs),
    generated in blocks of 10 s (the plant continues from its state); returns the sample count."""
    import numpy as np

    from hilbench.bench.acquisition.protocols import Identification
    from hilbench.firmware_sim.engine.friction_models import dc_motor
    from hilbench.firmware_sim.engine.plant import Plant

    u = Identification(duration=duration, sample_rate=int(fs), seed=seed).setpoints()
    p = dc_motor().replace(counts_per_rev=2**20, seed=seed)
    plant = Plant(p, 1.0 / fs)
    with open(path, "wb") as fh:
        for k0 in range(0, u.size, int(10 * fs)):
            out = plant.run(u[k0 : k0 + int(10 * fs)])
            np.column_stack([out.position_meas, p.torque_constant * out.current_meas]).tofile(fh)
    return int(u.size)


_ANALYSIS_CHILD = _PEAK + r"""
from functools import partial
from hilbench.analysis.record import decimated_record, load_record, span_note, stream_record
path, val, mode, budget = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
base = peak_kib()
t0, cpu0 = time.perf_counter(), time.process_time()  # CPU of the analysis, not of the imports above
heads = [stream_record(p)[0] for p in (path, val)]
if mode == "identify":  # as hilbench identify RUN --validate VAL --memory BUDGET
    from hilbench.analysis.identification import analyse, analyse_stream, array_cost
    if array_cost(sum(h.n_samples for h in heads)) <= budget:
        train = load_record(path)
        res = analyse(train, validation=load_record(val))
    else:
        (train, source), valid = stream_record(path), stream_record(val)
        res = analyse_stream(train, source, validation=valid)
    figure = res.figures["validation_torque_nrmse"]
    n = heads[0].n_samples
    extra = {"elements": int(res.model.ms_stiffness.size), "inertia": res.model.inertia,
             "validation_position_nrmse": res.figures.get("validation_position_nrmse")}
elif mode == "residual":  # as hilbench residual RUN --validate VAL --memory BUDGET reads and analyses
    from hilbench.analysis.residual import record_analysis
    span = record_analysis.span_for(heads, budget)
    train, valid = (record_analysis.read(p, max_samples=span) for p in (path, val))
    res = record_analysis.analyse(train, validation=[valid])
    figure = res.loop.error_after["validation"]["torque_nrmse"]
    n = res.record.n_samples
    extra = {"added": list(res.loop.names_added)}
elif mode == "compare":  # as hilbench compare RUN --validate VAL --memory BUDGET
    from hilbench.analysis.models.compare import analyse, reading_plan
    plan = reading_plan(heads, budget)
    if plan is None:
        train, valid = load_record(path), load_record(val)
    else:
        qs, span = plan
        train, valid = (decimated_record(p, h.sample_rate / q, max_samples=span)
                        for p, h, q in zip((path, val), heads, qs))
    res = analyse(train, valid)
    rows = {r.name: r for r in res.rows}
    figure = rows["maxwell_slip"].validation["torque_nrmse"] if rows["maxwell_slip"].error is None else None
    n = res.train.x.size
    extra = {"families": {r.name: (r.error or r.validation["torque_nrmse"]) for r in res.rows}}
else:
    raise SystemExit(f"unknown mode {mode}")
wall = time.perf_counter() - t0
print(json.dumps({"wall_s": wall, "cpu_s": time.process_time() - cpu0, "peak_rss_mib": peak_kib() / 1024,
                  "import_rss_mib": base / 1024, "analysed_samples": int(n), "analysed_rate_hz": train.sample_rate,
                  "span": span_note(train), "figure": figure, **extra}))
"""

LONG_S = 600.0
LONG_FS = 20_000.0
#: the memory budget every analysis is given (bytes): the issue's target, ``--memory 2G``
BUDGET = 2 << 30
#: the analyses of the identification protocol, each as its command reads and analyses the runs within BUDGET
MODES = ("identify", "residual", "compare")


def write_run_file(path: Path, duration: float, fs: float, seed: int = 0) -> int:
    """The default identification run of ``duration`` s at ``fs`` Hz as a bench run file (RunWriter; torque from
    the measured current, hold_previous), generated and written in blocks of 10 s; returns the sample count."""
    import numpy as np

    from hilbench.bench.acquisition.protocols import Identification
    from hilbench.common.runfile import RunWriter
    from hilbench.firmware_sim.engine.friction_models import dc_motor
    from hilbench.firmware_sim.engine.plant import Plant

    u = Identification(duration=duration, sample_rate=int(fs), seed=seed).setpoints()
    p = dc_motor().replace(counts_per_rev=2**20, seed=seed)
    plant = Plant(p, 1.0 / fs)
    block = int(10 * fs)
    with RunWriter(path, sample_rate=fs, channels=("sample_index", "t", "torque", "position")) as w:
        for k0 in range(0, u.size, block):
            out = plant.run(u[k0 : k0 + block])
            k = np.arange(k0, k0 + out.position_meas.size)
            w.append({"sample_index": k, "t": k / fs, "torque": p.torque_constant * out.current_meas,
                      "position": out.position_meas})
    return int(u.size)


def measure_analysis(path: Path, val: Path, mode: str, budget: int = BUDGET) -> dict:
    """Peak RSS (MiB), wall and CPU time (s) and the headline figures of one analysis of a run file (``val``: the
    validation run) in a child process, as its command does with ``--memory budget``."""
    done = subprocess.run([sys.executable, "-c", _ANALYSIS_CHILD, str(path), str(val), mode, str(budget)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        return {"error": (done.stderr.strip().splitlines() or ["no output"])[-1]}
    return json.loads(done.stdout.strip().splitlines()[-1])


def analysis_rows(mode: str, r0: dict, r1: dict, n0: int, n1: int, short: float, long: float,
                  quick: bool) -> list[dict]:
    """The peak-RSS and cost-per-sample rows of ``mode`` on the long run (``r1``, ``n1`` samples) against the
    short run (``r0``, ``n0``), with the issue's targets."""
    if "error" in r0 or "error" in r1:
        return [{"name": f"{mode}_{long:g}s_20kHz", "value": None, "unit": None, "baseline_name": None,
                 "baseline_value": None, "ratio": None, "target": f"failed: {r1.get('error') or r0.get('error')}",
                 "ok": False}]
    clock = "cpu_s" if "cpu_s" in r0 and "cpu_s" in r1 else "wall_s"  # CPU time: steadier on a shared machine
    c0, c1 = 1e6 * r0[clock] / n0, 1e6 * r1[clock] / n1
    return [
        {"name": f"{mode}_{long:g}s_20kHz_peak_rss", "value": r1["peak_rss_mib"], "unit": "MiB",
         "baseline_name": f"{short:g} s run", "baseline_value": r0["peak_rss_mib"],
         "ratio": r1["peak_rss_mib"] / r0["peak_rss_mib"], "target": "<= 2048 MiB",
         "ok": r1["peak_rss_mib"] <= 2048 if not quick else None, "span": r1.get("span")},
        {"name": f"{mode}_{long:g}s_20kHz_cost_per_sample", "value": c1,
         "unit": f"{'CPU' if clock == 'cpu_s' else 'wall'} s per million samples",
         "baseline_name": f"{short:g} s run", "baseline_value": c0, "ratio": c1 / c0,
         "target": "<= 1.3x the short run's", "ok": c1 <= 1.3 * c0 if not quick else None,
         "figure": r1.get("figure"), "wall_s": r1["wall_s"], "cpu_s": r1.get("cpu_s"),
         "baseline_wall_s": r0["wall_s"], "baseline_figure": r0.get("figure")},
    ]


def analyses(quick: bool = False, long_s: float = LONG_S, files: dict | None = None,
             modes: tuple[str, ...] = MODES) -> list[dict]:
    """identify, residual and compare, each as its command does with ``--memory 2G``, on a run of ``long_s`` s at
    20 kHz against a 60 s run of the same protocol (quick: 1 s against 0.5 s), each validated on a second run of
    another seed: peak RSS and cost per sample, with the issue's targets. ``files`` ({"short": (train, validation),
    "long": (...)}): existing run files (e.g. recorded by ``hilbench run`` in lockstep) instead of writing them."""
    from hilbench.common.runfile import open_run

    short, long = (0.5, 1.0) if quick else (60.0, long_s)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        if files is None:
            files = {}
            for key, duration in (("short", short), ("long", long)):
                files[key] = (Path(tmp) / f"run_{duration:g}.h5", Path(tmp) / f"val_{duration:g}.h5")
                for seed, path in enumerate(files[key]):
                    write_run_file(path, duration, LONG_FS, seed=seed)
        counts = {}
        for key in ("short", "long"):
            with open_run(files[key][0]) as run_file:
                counts[key] = int(run_file.n_samples)
        for mode in modes:
            r0 = measure_analysis(*files["short"], mode)
            r1 = measure_analysis(*files["long"], mode)
            rows += analysis_rows(mode, r0, r1, counts["short"], counts["long"], short, long, quick)
    return rows


def paper_rows(quick: bool = False, long_s: float = LONG_S) -> list[dict]:
    """afrf (a stepped sine), skeleton (a chirp) and presliding (a nested path) read chunk by chunk
    (``long_run_paper``), the run of ``long_s`` s against a 60 s one at 20 kHz (quick: 6 s against 2 s, the
    skeleton 40 s against 20 s); an analysis that refuses the long run (the skeleton's wavelet map) is a row
    saying so."""
    from benchmarks import long_run_paper

    if not quick:
        return long_run_paper.rows((60.0, long_s), fs=LONG_FS, modes=("stream",))
    # quick: 2 s against 6 s, but the skeleton's chirps 20 s against 40 s, the shortest whose wavelet cone leaves
    # a ridge (2 s and 6 s are refused)
    return (long_run_paper.rows((2.0, 6.0), fs=LONG_FS, modes=("stream",), analyses=("afrf", "presliding"))
            + long_run_paper.rows((20.0, 40.0), fs=LONG_FS, modes=("stream",), analyses=("skeleton",)))


def measure(path: Path, n: int, mode: str, fs: float = FS) -> dict:
    """Peak RSS (MiB) and wall time (s) of one identification in a child process."""
    done = subprocess.run([sys.executable, "-c", _CHILD, str(path), str(n), str(fs), mode, str(CHUNK)],
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def run(quick: bool = False) -> list[dict]:
    return identification(quick) + analyses(quick) + paper_rows(quick)


def identification(quick: bool = False) -> list[dict]:
    durations = (2.0, 6.0) if quick else (60.0, 180.0)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        results = {}
        for duration in durations:
            path = Path(tmp) / f"run_{duration:g}.f64"
            n = record(path, duration)
            for mode in ("stream", "arrays"):
                results[(duration, mode)] = (n, measure(path, n, mode))
    short = durations[0]
    for (duration, mode), (n, r) in results.items():
        n0, r0 = results[(short, mode)]
        rows.append({
            "name": f"identify_{mode}_{duration:g}s_10kHz_peak_rss", "value": r["peak_rss_mib"], "unit": "MiB",
            "baseline_name": f"{short:g} s run", "baseline_value": r0["peak_rss_mib"],
            "ratio": r["peak_rss_mib"] / r0["peak_rss_mib"],
            "target": "stream: bounded (ratio near 1 for 3x the samples)" if mode == "stream" else None,
            "ok": (r["peak_rss_mib"] < 1.5 * r0["peak_rss_mib"]) if mode == "stream" and not quick else None,
        })
        if n > n0:  # what each further sample costs: the growth of the peak over the short run's
            grow = (r["peak_rss_mib"] - r0["peak_rss_mib"]) * 2**20 / (n - n0)
            rows.append({
                "name": f"identify_{mode}_{duration:g}s_10kHz_bytes_per_added_sample", "value": grow, "unit": "B",
                "baseline_name": "issue #26: 2.6 kB per sample", "baseline_value": 2600.0, "ratio": grow / 2600.0,
                "target": "stream: < 32 B" if mode == "stream" else None,
                "ok": grow < 32 if mode == "stream" and not quick else None,
            })
        rows.append({
            "name": f"identify_{mode}_{duration:g}s_10kHz_cost_per_sample", "value": 1e6 * r["wall_s"] / n,
            "unit": "s per million samples", "baseline_name": f"{short:g} s run",
            "baseline_value": 1e6 * r0["wall_s"] / n0,
            "ratio": (r["wall_s"] / n) / (r0["wall_s"] / n0), "target": "cost per sample near the short run's",
            "ok": None,
        })
    return rows


def main(argv: list[str] | None = None) -> None:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_long_run", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--analyses", nargs="?", type=float, const=LONG_S, metavar="S",
                    help="identify, residual and compare only, on a run of S s (default 600) against 60 s")
    ap.add_argument("--files", nargs=4, type=Path, metavar=("SHORT", "SHORT_VAL", "LONG", "LONG_VAL"),
                    help="existing run files (e.g. recorded by hilbench run in lockstep) for --analyses")
    ap.add_argument("--modes", default=",".join(MODES), help="comma-separated analyses for --analyses")
    ap.add_argument("--paper", nargs="?", type=float, const=LONG_S, metavar="S",
                    help="afrf, skeleton and presliding only, read chunk by chunk, on S s against 60 s")
    args = ap.parse_args(argv)
    if args.analyses is not None:
        files = None if args.files is None else {"short": tuple(args.files[:2]), "long": tuple(args.files[2:])}
        rows = analyses(args.quick, args.analyses, files, tuple(m for m in args.modes.split(",") if m))
    elif args.paper is not None:
        rows = paper_rows(args.quick, args.paper)
    else:
        rows = run(args.quick)
    for row in rows:
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
