"""Long runs of the paper's analyses (afrf, skeleton, presliding): peak memory and wall time, read whole and chunk by
chunk, against the run's length (issue #26). ``rows(durations)`` is meant to be called from bench_long_run.

Records, written as run files (the C plant directly, as the simulated device records them: a 2^20-count encoder,
torque from the measured current):

- ``chirp``: the default chirp protocol (2 A, 0.1 Hz/s) of ``duration`` s on the DC motor at ``fs``, analysed in
  the band 0.1 Hz to twice its top frequency (a longer run sweeps higher: 6 Hz at 60 s, 60 Hz at 600 s);
- ``chirp_band`` (analysis ``skeleton_band``): the same chirp swept to ``BAND_TOP`` Hz whatever its length (rate
  ``BAND_TOP / duration``), analysed in the same band: a longer run is the same band resolved more finely, so
  the cost per sample compares like with like;
- ``stepped_sine``: the default stepped sine (0.5 and 2 A at 1, 2, 5 Hz), its measure periods scaled so that the
  run lasts about ``duration`` s;
- ``presliding``: a nested reversal path (displacement-driven) repeated to ``duration`` s, the force of the DC
  motor's Maxwell-slip elements along it.

Each analysis runs in a fresh child process; its peak RSS is ``VmHWM`` of /proc/self/status (see bench_long_run).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

FS = 10_000.0
ANALYSES = ("afrf", "skeleton", "skeleton_band", "presliding")
#: Hz: the top frequency of every ``chirp_band`` record (that of the default 60 s chirp)
BAND_TOP = 6.0

_CHILD = r"""
import json, resource, sys, time
path, analysis, mode, top = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])

def peak_kib():
    try:
        with open("/proc/self/status") as fh:
            return next(int(line.split()[1]) for line in fh if line.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

from hilbench.analysis import afrf, presliding, skeleton
from hilbench.analysis.record import load_record
base = peak_kib()
t0, cpu0 = time.perf_counter(), time.process_time()  # CPU of the analysis, not of the imports above
if analysis == "afrf":
    res = afrf.analyse(afrf.load(path)) if mode == "whole" else afrf.analyse_stream(path)
    figure = float(res.magnitudes[-1, 0, 0])
elif analysis in ("skeleton", "skeleton_band"):
    s = skeleton.SkeletonSettings(band=(0.1, 2 * top))
    res = skeleton.analyse([load_record(path)], s) if mode == "whole" else skeleton.analyse_stream([path], s)
    figure = float(res.curves.stiffness[len(res.curves.stiffness) // 2])
else:
    res = (presliding.analyse(load_record(path), replicates=4) if mode == "whole"
           else presliding.analyse_stream(path, replicates=4)[0])
    figure = float(res.quantities["breakaway"])
print(json.dumps({"wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - cpu0,
                  "peak_rss_mib": peak_kib() / 1024, "import_rss_mib": base / 1024, "figure": figure}))
"""


def _write_device_run(path: Path, u, fs: float, protocol: str, params: dict, arrays: dict | None = None) -> int:
    """The DC motor driven by current ``u`` (A), written as a device run in blocks of 10 s."""
    import numpy as np

    from hilbench.common.runfile import RunWriter
    from hilbench.firmware_sim.engine.friction_models import dc_motor
    from hilbench.firmware_sim.engine.plant import Plant

    p = dc_motor().replace(counts_per_rev=2**20, seed=0)
    plant = Plant(p, 1.0 / fs)
    block = int(10 * fs)
    with RunWriter(path, sample_rate=fs, channels=("sample_index", "t", "torque", "position"),
                   calibration={"inertia": p.inertia}, protocol_name=protocol, protocol_params=params,
                   protocol_arrays=arrays or {}) as w:
        for k0 in range(0, u.size, block):
            out = plant.run(u[k0:k0 + block])
            k = np.arange(k0, k0 + out.position_meas.size)
            w.append({"sample_index": k, "t": k / fs, "torque": p.torque_constant * out.current_meas,
                      "position": out.position_meas})
    return int(u.size)


def record(kind: str, path: Path, duration: float, fs: float = FS) -> int:
    """Write the ``kind`` record of about ``duration`` s (module docstring); returns its sample count."""

    from hilbench.bench.acquisition.protocols import Chirp, SteppedSine

    if kind in ("chirp", "chirp_band"):
        rate = BAND_TOP / duration if kind == "chirp_band" else Chirp.rate
        proto = Chirp(duration=duration, sample_rate=int(fs), rate=rate)
        return _write_device_run(path, proto.excitation().u, fs, "chirp", {"duration": duration, "rate": rate})
    if kind == "stepped_sine":
        base = SteppedSine(sample_rate=int(fs))
        scale = max(1, round(duration / (base.n_samples / fs)))
        proto = SteppedSine(sample_rate=int(fs), measure_periods=10 * scale)
        exc = proto.excitation()
        return _write_device_run(path, exc.u, fs, "stepped_sine", exc.protocol(), {"step_windows": exc.windows})
    return _write_presliding(path, duration, fs)


def _write_presliding(path: Path, duration: float, fs: float) -> int:
    """The nested path of ``presliding_cycle`` repeated to ``duration`` s, the DC motor's Maxwell-slip force along
    it plus 2 mN*m of noise, written 10 s at a time (an hour at 20 kHz is 72 M samples: the stop operator of the
    whole path would take 16 floats a sample). The path ends each repeat where the next starts and its last stroke
    passes every earlier turning point, so from the second repeat on the elements' state, and the force, repeat
    exactly: the first two repeats are simulated and the second one tiled."""
    import numpy as np

    from hilbench.common.runfile import RunWriter
    from hilbench.firmware_sim.engine.friction_models import dc_motor
    from hilbench.firmware_sim.engine.plant import stop_operator

    cycle = presliding_cycle()
    p = dc_motor()
    k = np.asarray(p.ms_stiffness)
    two = stop_operator(np.tile(cycle, 2), np.asarray(p.ms_slip) / k) @ k
    n = int(duration * fs)
    rng = np.random.default_rng(0)  # drawn block by block: the same stream as one draw of n
    block = int(10 * fs)
    with RunWriter(path, sample_rate=fs, channels=("sample_index", "t", "position", "torque"),
                   record="displacement-driven", protocol_name="presliding", protocol_params={"inertia": 0.0}) as w:
        for k0 in range(0, n, block):
            i = np.arange(k0, min(n, k0 + block))
            phase = i % cycle.size
            force = np.where(i < cycle.size, two[phase], two[cycle.size + phase])
            w.append({"sample_index": i, "t": i / fs, "position": cycle[phase],
                      "torque": force + 2e-3 * rng.standard_normal(i.size)})
    return n


def presliding_cycle() -> np.ndarray:
    """One repeat of the nested presliding path (rad): cosine strokes of 2000 samples (0.1 s at 20 kHz) between
    the turning points 0, 6, -4, 3, -2, 1.5, -1, 0.5, -0.25, 2.5, -5, 8 and back to 0, in units of the DC motor's
    largest slip distance (1.2 s a repeat at 20 kHz)."""
    import numpy as np

    from hilbench.firmware_sim.engine.friction_models import DC_MOTOR_D

    turns = np.array([0.0, 6, -4, 3, -2, 1.5, -1, 0.5, -0.25, 2.5, -5, 8, 0]) * DC_MOTOR_D
    return np.concatenate([a + (b - a) * 0.5 * (1 - np.cos(np.pi * np.linspace(0, 1, 2000, endpoint=False)))
                           for a, b in zip(turns[:-1], turns[1:], strict=True)])


def measure(path: Path, analysis: str, mode: str, top: float = 0.0) -> dict:
    """Peak RSS (MiB), wall time (s) and one result figure of ``analysis`` read ``mode`` in a child process;
    ``top``: the chirp's top frequency, Hz (the skeleton's band is 0.1 Hz to twice it)."""
    done = subprocess.run([sys.executable, "-c", _CHILD, str(path), analysis, mode, str(top)], capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{analysis} {mode} on {path.name}: {done.stderr.strip().splitlines()[-1]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def rows(durations: tuple[float, ...] = (60.0, 300.0), fs: float = FS,
         modes: tuple[str, ...] = ("whole", "stream"), analyses: tuple[str, ...] = ANALYSES) -> list[dict]:
    """Rows (name, value, unit, baseline, ratio) for each analysis, mode and duration; the baseline is the first
    duration's run read the same way. A run an analysis refuses (one line, e.g. the skeleton's wavelet map over
    its bound) is a row with that line as its ``target`` and ``ok`` False."""
    out = []
    kinds = {"afrf": "stepped_sine", "skeleton": "chirp", "skeleton_band": "chirp_band", "presliding": "presliding"}
    with tempfile.TemporaryDirectory() as tmp:
        for analysis in analyses:
            results = {}
            for duration in durations:
                path = Path(tmp) / f"{analysis}_{duration:g}.h5"
                n = record(kinds[analysis], path, duration, fs)
                for mode in modes:
                    # the default chirp sweeps at 0.1 Hz/s; its harmonics and the encoder noise put the spectral
                    # band at ~10x its top frequency: the skeleton is given 0.1 Hz to twice the top frequency
                    top = BAND_TOP if analysis == "skeleton_band" else 0.1 * duration
                    try:
                        results[(duration, mode)] = (n, measure(path, analysis, mode, top))
                    except RuntimeError as exc:
                        results[(duration, mode)] = (n, {"error": str(exc)})
                path.unlink()
            for (duration, mode), (n, r) in results.items():
                n0, r0 = results[(durations[0], mode)]
                tag = f"{analysis}_{mode}_{duration:g}s_{fs / 1e3:g}kHz"
                if "error" in r or "error" in r0:
                    out.append({"name": tag, "value": None, "unit": None, "baseline_name": None,
                                "baseline_value": None, "ratio": None, "ok": False,
                                "target": f"refused: {r.get('error') or r0.get('error')}"})
                    continue
                out.append({"name": f"{tag}_peak_rss", "value": r["peak_rss_mib"], "unit": "MiB",
                            "baseline_name": f"{durations[0]:g} s run", "baseline_value": r0["peak_rss_mib"],
                            "ratio": r["peak_rss_mib"] / r0["peak_rss_mib"], "samples": n,
                            "target": "<= 2048 MiB (issue 26)", "ok": r["peak_rss_mib"] <= 2048})
                # the cost target is the long run's against the 60 s one; quick runs of seconds are noise. CPU
                # time of the child (steadier than wall time on a shared machine), wall time where it is missing
                clock = "cpu_s" if r.get("cpu_s") and r0.get("cpu_s") else "wall_s"
                ratio = (r[clock] / n) / (r0[clock] / n0)
                out.append({"name": f"{tag}_cost_per_sample", "value": 1e6 * r[clock] / n,
                            "unit": f"{'CPU' if clock == 'cpu_s' else 'wall'} s per million samples",
                            "baseline_name": f"{durations[0]:g} s run", "baseline_value": 1e6 * r0[clock] / n0,
                            "wall_s": r["wall_s"], "baseline_wall_s": r0["wall_s"],
                            "ratio": ratio, "figure": r["figure"], "cpu_s": r.get("cpu_s"),
                            "baseline_cpu_s": r0.get("cpu_s"), "target": "<= 1.3x the short run (issue 26)",
                            "ok": ratio <= 1.3 if duration >= 600 else None})
    return out


if __name__ == "__main__":
    durations = tuple(float(a) for a in sys.argv[1:]) or (60.0, 300.0)
    for row in rows(durations):
        print(json.dumps(row))
