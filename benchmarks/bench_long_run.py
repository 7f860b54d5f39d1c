"""Long runs: peak memory and wall time of the identification against the run's length (issue #26).

A record of the bench's default identification protocol on the DC motor at 10 kHz (the C plant directly, as the
simulated device records it: torque from the measured current, a 2^20-count encoder) is written to a raw file.
Each measurement runs in a fresh child process. Its peak RSS is ``VmHWM`` of /proc/self/status, the high-water
mark of the child's own address space: ``resource.getrusage(RUSAGE_SELF).ru_maxrss`` of a child started by
``subprocess`` (vfork + exec) also holds the parent's high-water mark, which here is the record's generation.
Elsewhere than on Linux the benchmark falls back to ``ru_maxrss``.

- ``stream``: ``identify_chunks`` (the NNLS fit and its figures: equation error, open-loop and segmented
  simulation) reading the file chunk by chunk (the loader's path);
- ``arrays``: ``identify`` on the whole record loaded as arrays (the array API).

Cost per sample is compared with a 1-minute run measured in the same benchmark (``quick``: 2 s and 6 s).
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

_CHILD = r"""
import json, resource, sys, time
import numpy as np
from hilbench.analysis.identification.identify import RunArrays, identify, identify_chunks
from hilbench.analysis.identification.maxwell_fit import LipSettings

path, n, fs, mode, chunk = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4], int(sys.argv[5])
def peak_kib():
    try:
        with open("/proc/self/status") as fh:
            return next(int(line.split()[1]) for line in fh if line.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

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


def measure(path: Path, n: int, mode: str, fs: float = FS) -> dict:
    """Peak RSS (MiB) and wall time (s) of one identification in a child process."""
    done = subprocess.run([sys.executable, "-c", _CHILD, str(path), str(n), str(fs), mode, str(CHUNK)],
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def run(quick: bool = False) -> list[dict]:
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


if __name__ == "__main__":
    for row in run(quick="--quick" in sys.argv):
        print(row)
