"""Host-clocked drives: ``hilbench run identify`` at 1 kHz against ``hilbench sim --canopen`` and ``--odrive``
(their own processes, udp_multicast on this host, plant in real time), quiet and with a CPU-heavy process
running.

Reported per case: cycle-time p50/p99/max (host send times of SYNC, in the cycle process), missed and late
cycles (definitions: drivers/host_cycle.py), host CPU (the ``hilbench run`` process and its cycle process,
% of one core over the run's wall time), the drive process's CPU, and the identification errors of J and
of the virgin curve on the recorded samples. Baseline: the quiet case of the same run.
"""

from __future__ import annotations

import json
import os
import random
import select
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from hilbench.drivers.host_cycle import timing_summary


class HostRunError(RuntimeError):
    """``hilbench run`` against the drive exited non-zero (its last stderr line is the message)."""


HOG = "import time\nend = time.monotonic() + 3600\nwhile time.monotonic() < end:\n    pass\n"


def _start_drive(kind: str) -> tuple[subprocess.Popen, str]:
    port = random.randint(40000, 60000)
    group = f"239.{random.randint(1, 254)}.{random.randint(1, 254)}.{random.randint(1, 254)}"
    proc = subprocess.Popen([sys.executable, "-m", "hilbench", "sim", f"--{kind}", group, "--interface",
                             "udp_multicast", "--node", "2", "--udp-port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    ready, _, _ = select.select([proc.stdout], [], [], 120)
    if not ready:
        proc.kill()
        raise RuntimeError("the simulated drive did not start")
    return proc, proc.stdout.readline().strip()


def _cpu_of(proc: subprocess.Popen, t0: float) -> float:
    """Wait for ``proc`` and return its CPU time (with its reaped children), % of one core since ``t0``; its
    exit status is kept in ``proc.returncode``."""
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return 100.0 * (usage.ru_utime + usage.ru_stime) / (time.monotonic() - t0)


def identification_errors(path: Path) -> tuple[float, float]:
    """Relative error of J and RMS relative error of the virgin curve, identified from a run file (on its
    host_time when the drive sampled at each SYNC, as ``hilbench identify`` does)."""
    from hilbench.analysis.identification.identify import RunArrays, identify
    from hilbench.analysis.identification.maxwell_fit import LipSettings
    from hilbench.analysis.identification.regressors import reversal_travels
    from hilbench.analysis.models.friction_model import FrictionModel
    from hilbench.analysis.record import on_host_time
    from hilbench.common.runfile import host_sampled
    from hilbench.firmware_sim.devices.sim_config import load_sim_config

    with h5py.File(path) as f:
        s = f["samples"]
        t, tau, x = s["t"][:], s["torque"][:], s["position"][:]
        identity = json.loads(f["device/identity"][()])
        if host_sampled(identity, s):  # CiA 402: the drive sampled at each SYNC; analyse on those times
            t, x, tau, _ = on_host_time(s["host_time"][:], float(f.attrs["sample_rate"]), x, tau, "hold_previous")
    p = load_sim_config().plant
    m = identify(RunArrays(t, tau, x), settings=LipSettings(timing="hold_previous")).model
    truth = FrictionModel("rotary", p.inertia, np.array(p.ms_stiffness), p.ms_delta, viscous=p.viscous)
    q = 2 * np.pi / 2**20
    grid = np.geomspace(2 * q, min(0.5 * reversal_travels(x, 4 * q).max(), 100 * 5e-4), 200)
    virgin = float(np.sqrt(np.mean((m.virgin_curve(grid) / truth.virgin_curve(grid) - 1) ** 2)))
    return m.inertia / p.inertia - 1, virgin


def measure(kind: str, seconds: float, loaded: bool, identify: bool) -> dict:
    t_drive = time.monotonic()
    drive, url = _start_drive(kind)
    hog = subprocess.Popen([sys.executable, "-c", HOG]) if loaded else None
    try:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "run.h5"
            t0 = time.monotonic()
            with (Path(tmp) / "stderr").open("wb") as err:
                host = subprocess.Popen([sys.executable, "-m", "hilbench", "run", "identify", "--device", url,
                                         "--sample-rate", "1000", "--duration", str(seconds), "--quiet",
                                         "-o", str(path)], stdout=subprocess.DEVNULL, stderr=err)
                host_cpu = _cpu_of(host, t0)
            if host.returncode != 0:
                lines = (Path(tmp) / "stderr").read_text(errors="replace").strip().splitlines()
                raise HostRunError(f"hilbench run identify against the {kind} drive exited {host.returncode}: "
                                   f"{lines[-1] if lines else 'no message'}")
            with h5py.File(path) as f:
                host_time = f["samples/host_time"][:]
                status = f.attrs["status"]
            rate = 1000.0
            summary = timing_summary(host_time, host_time[0] + np.arange(host_time.size) / rate, rate)
            errors = identification_errors(path) if identify else (float("nan"), float("nan"))
        drive.terminate()
        drive_cpu = _cpu_of(drive, t_drive)
    finally:
        if drive.poll() is None:
            drive.kill()
        if hog is not None:
            hog.kill()
            hog.wait()
    return {"summary": summary, "host_cpu": host_cpu, "drive_cpu": drive_cpu, "status": status,
            "j_error": errors[0], "virgin_error": errors[1]}


def run(quick: bool = False) -> list[dict]:
    seconds = 1.0 if quick else 60.0
    rows = []
    for kind, label in (("canopen", "CiA 402"), ("odrive", "ODrive")):
        rows += _rows(kind, label, seconds, quick)
    return rows


def _measured(kind: str, seconds: float, loaded: bool, identify: bool) -> tuple[dict, str]:
    """``measure`` with one retry when the host run fails; the failure is reported in the rows, not hidden."""
    try:
        return measure(kind, seconds, loaded, identify), ""
    except HostRunError as exc:
        return measure(kind, seconds, loaded, identify), str(exc)


def _rows(kind: str, label: str, seconds: float, quick: bool) -> list[dict]:
    quiet, failed = _measured(kind, seconds, loaded=False, identify=not quick)
    cases = [("quiet", quiet, failed)]
    if not quick:  # the smoke run (tests) stops at the quiet case
        cases.append(("loaded", *_measured(kind, seconds, loaded=True, identify=True)))
    rows = []
    for tag, m, failed in cases:
        s = m["summary"]
        name = f"{label} 1 kHz {seconds:g} s {tag}"
        rows.append({"name": f"{name}: host runs", "value": 2.0 if failed else 1.0, "unit": "runs",
                     "baseline_name": None, "baseline_value": None, "ratio": None,
                     "target": f"1 (the first failed: {failed})" if failed else "1", "ok": not failed})
        base = quiet["summary"]
        for key, what in (("p50", "cycle time p50"), ("p99", "cycle time p99"), ("max", "cycle time max")):
            value, ref = getattr(s, key) * 1e3, getattr(base, key) * 1e3
            rows.append({"name": f"{name}: {what}", "value": value, "unit": "ms",
                         "baseline_name": f"quiet {what}", "baseline_value": ref, "ratio": value / ref,
                         "target": "report", "ok": None})
        rows += [
            {"name": f"{name}: missed cycles", "value": float(s.missed), "unit": "cycles",
             "baseline_name": None, "baseline_value": None, "ratio": None,
             "target": f"report (late: {s.late}; {'fit' if s.fit else 'UNFIT'} for identification)", "ok": None},
            {"name": f"{name}: host CPU", "value": m["host_cpu"], "unit": "% of one core",
             "baseline_name": "quiet host CPU", "baseline_value": quiet["host_cpu"],
             "ratio": m["host_cpu"] / quiet["host_cpu"] if quiet["host_cpu"] > 0 else None,
             "target": "report", "ok": None},
            {"name": f"{name}: drive process CPU", "value": m["drive_cpu"], "unit": "% of one core",
             "baseline_name": None, "baseline_value": None, "ratio": None, "target": "report", "ok": None},
        ]
        if not quick:
            rows += [
                {"name": f"{name}: J error", "value": 100 * m["j_error"], "unit": "%", "baseline_name": None,
                 "baseline_value": None, "ratio": None, "target": "|.| < 1 %", "ok": bool(abs(m["j_error"]) < 0.01)},
                {"name": f"{name}: virgin curve RMS error", "value": 100 * m["virgin_error"], "unit": "%",
                 "baseline_name": None, "baseline_value": None, "ratio": None, "target": "< 2 %",
                 "ok": bool(m["virgin_error"] < 0.02)},
            ]
    return rows


if __name__ == "__main__":
    for row in run(quick="--quick" in sys.argv):
        print(row)
