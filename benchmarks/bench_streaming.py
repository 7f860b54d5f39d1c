"""Sustained real-time streaming over a pty to the simulated amplifier (``sim://``, realtime pacing).

For 10 kHz and 20 kHz (60 s each; quick mode 1 s each): lost samples, host CPU (% of one core, all host
threads, from getrusage) and command latency (status request round trip while streaming, p50/p99).
Baselines are measured in the same run on the same connection while armed but idle (heartbeats only).
Target: 0 lost samples at 20 kHz with the host under half a core.
"""

from __future__ import annotations

import resource
import threading
import time

import numpy as np


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _rtts(amp, stop: threading.Event, out: list[float], period: float = 0.02) -> None:
    while not stop.is_set():
        t0 = time.perf_counter()
        amp.status()
        out.append(time.perf_counter() - t0)
        stop.wait(period)


def measure(rate: int, seconds: float) -> dict:
    """Stream ``seconds`` of a 5 Hz current sine at ``rate`` Hz; return lost samples, CPU and latencies."""
    from hilbench.drivers import protocol as p
    from hilbench.drivers.device_url import open_device
    from hilbench.drivers.errors import DriverError

    with open_device("sim://?pacing=realtime") as amp:
        amp.configure(p.Config(sample_rate=rate, current_limit=3.0, torque_constant=0.2,
                               watchdog_timeout=0.5))  # the bench's default (bench.acquisition.runner.DeviceSettings)
        amp.arm()
        # idle baseline: connected and armed, heartbeats only
        stop, idle_rtt = threading.Event(), []
        c0, w0 = _cpu(), time.perf_counter()
        pinger = threading.Thread(target=_rtts, args=(amp, stop, idle_rtt))
        pinger.start()
        time.sleep(min(1.0, max(0.5, seconds / 4)))
        stop.set()
        pinger.join()
        idle_cpu = (_cpu() - c0) / (time.perf_counter() - w0) * 100
        n = int(round(seconds * rate))
        setpoints = 1.0 * np.sin(2 * np.pi * 5.0 * np.arange(n) / rate)
        stop, rtt = threading.Event(), []
        pinger = threading.Thread(target=_rtts, args=(amp, stop, rtt))
        received = 0
        c0, w0 = _cpu(), time.perf_counter()
        pinger.start()
        fault = ""
        try:
            for blk in amp.stream(setpoints, allow_loss=True):
                received += len(blk)
        except DriverError as exc:  # e.g. a watchdog trip: the rest of the stream counts as lost
            fault = str(exc)
        finally:
            stop.set()
            pinger.join()
        wall = time.perf_counter() - w0
        cpu = (_cpu() - c0) / wall * 100
    return {"lost": n - received, "fault": fault, "cpu": cpu, "idle_cpu": idle_cpu, "wall": wall,
            "rtt": np.array(rtt) * 1e3, "idle_rtt": np.array(idle_rtt) * 1e3}


def run(quick: bool = False) -> list[dict]:
    seconds = 1.0 if quick else 60.0
    rows = []
    for rate in (10000, 20000):
        m = measure(rate, seconds)
        tag = f"pty {rate // 1000} kHz {seconds:g} s"
        idle50 = float(np.percentile(m["idle_rtt"], 50))
        rows += [
            {"name": f"{tag}: lost samples", "value": float(m["lost"]), "unit": "samples",
             "baseline_name": None, "baseline_value": None, "ratio": None,
             "target": "== 0" + (f" (stream ended: {m['fault']})" if m["fault"] else ""),
             "ok": m["lost"] == 0},
            {"name": f"{tag}: host CPU", "value": m["cpu"], "unit": "% of one core",
             "baseline_name": "host CPU armed idle", "baseline_value": m["idle_cpu"],
             "ratio": m["cpu"] / m["idle_cpu"] if m["idle_cpu"] > 0 else None,
             "target": "< 50 % of one core" if rate == 20000 else "report", "ok": m["cpu"] < 50.0},
            {"name": f"{tag}: command latency p50", "value": idle50 if not len(m["rtt"]) else
             float(np.percentile(m["rtt"], 50)), "unit": "ms",
             "baseline_name": "latency p50 armed idle", "baseline_value": idle50,
             "ratio": float(np.percentile(m["rtt"], 50)) / idle50 if len(m["rtt"]) else None,
             "target": "report", "ok": None},
            {"name": f"{tag}: command latency p99", "value": float(np.percentile(m["rtt"], 99)), "unit": "ms",
             "baseline_name": "latency p99 armed idle",
             "baseline_value": float(np.percentile(m["idle_rtt"], 99)),
             "ratio": float(np.percentile(m["rtt"], 99)) / float(np.percentile(m["idle_rtt"], 99)),
             "target": "report", "ok": None},
        ]
    return rows


if __name__ == "__main__":
    import sys

    for row in run(quick="--quick" in sys.argv):
        print(f"{row['name']:<45} {row['value']:10.3f} {row['unit']:<14} baseline {row['baseline_value']} "
              f"ratio {row['ratio']} target {row['target']} ok {row['ok']}")
