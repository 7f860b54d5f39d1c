"""Soak: realtime streaming at 10 kHz against one simulated amplifier, with random host kills and reconnects.

One simulator process (``python -m hilbench.firmware_sim --serial``, realtime pacing) lives through the
whole soak, like a bench's device. Hosts are real ``hilbench run identify`` processes on
``serial://PTY`` at 10 kHz, 0.5-4 s each; half of them get SIGKILL at a random moment. After a kill the
next host reconnects with ``hilbench fault clear`` (the device's watchdog has latched a fault by then).

Every run file is then checked against the setpoints it stores: sample indices 0..n-1 with no gap
(``lost``) and no repeat, and every sample's commanded current equal to its float32 setpoint
(``invented`` counts samples that are neither). A killed run must repair to ``crashed`` and open.
Targets: 0 samples lost or invented, 0 files that do not open, 0 faults in runs that were not killed.
Full length 10 min (``python -m benchmarks --only soak``); ``--quick`` 8 s (the smoke test's).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RATE = 10_000  # Hz


def _hilbench(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hilbench", *args], capture_output=True, text=True,
                          timeout=timeout)


def check_file(path: Path, killed: bool) -> dict[str, int]:
    """Lost and invented samples of one run file, and whether it opened (after repair if it crashed)."""
    from hilbench.common.runfile import RunFileError, open_run, repair

    out = {"lost": 0, "invented": 0, "unreadable": 0, "samples": 0, "absent": 0}
    if not path.exists():
        out["absent" if killed else "unreadable"] = 1  # a host killed before its file appeared
        return out
    try:
        repair(path)  # marks a killed run 'crashed'; leaves a finished one as it is
        with open_run(path) as run:
            status = run.status
            n = run.n_samples
            index = run.channel("sample_index")
            cmd = run.channel("current_cmd")
            setpoints = run.protocol_array("setpoints").astype(np.float32).astype(np.float64)
    except RunFileError:
        out["unreadable"] = 1
        return out
    out["samples"] = n
    steps = np.diff(np.concatenate([[-1], index]))
    repeated = int(np.sum(steps < 1))
    # lost: device samples missing from the file, within what it holds (all the setpoints once completed)
    expected = setpoints.size if status == "completed" else (int(index.max()) + 1 if n else 0)
    out["lost"] += int(np.setdiff1d(np.arange(expected), index).size)
    m = min(n, setpoints.size)
    wrong = int(np.sum(cmd[:m] != setpoints[index[:m].clip(0, setpoints.size - 1)]))
    beyond = max(0, n - setpoints.size)
    out["invented"] += repeated + wrong + beyond
    if killed and status != "crashed":
        out["unreadable"] += 1  # a killed run must say so
    return out


def soak(seconds: float, seed: int = 12, work: Path | None = None) -> dict:
    from hilbench.drivers.device_url import start_simulator, stop_simulator

    rng = np.random.default_rng(seed)
    work = Path(work or tempfile.mkdtemp(prefix="hilbench-soak-"))
    proc, pty = start_simulator({"pacing": "realtime"})
    totals = {"runs": 0, "kills": 0, "completed": 0, "faults_latched": 0, "faults_unexpected": 0, "lost": 0,
              "invented": 0, "unreadable": 0, "absent": 0, "samples": 0, "host_errors": 0}
    t_end = time.monotonic() + seconds
    try:
        i = 0
        while time.monotonic() < t_end:
            duration = float(rng.uniform(0.5, 4.0))
            kill = bool(rng.random() < 0.5)
            out = work / f"run{i:04d}.h5"
            host = subprocess.Popen([sys.executable, "-m", "hilbench", "run", "identify", "--device",
                                     f"serial://{pty}", "--sample-rate", str(RATE), "--duration", f"{duration:.3f}",
                                     "--seed", str(i), "--quiet", "-o", str(out)],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            killed = False
            if kill:  # at a random moment of the stream (the file appears just before ARM)
                deadline = time.monotonic() + 30
                while not out.exists() and host.poll() is None and time.monotonic() < deadline:
                    time.sleep(0.01)
                try:
                    host.wait(timeout=float(rng.uniform(0.0, duration)))
                except subprocess.TimeoutExpired:
                    host.kill()
                    killed = True
            _, err = host.communicate(timeout=120)
            totals["runs"] += 1
            totals["kills"] += killed
            if not killed and host.returncode != 0:
                totals["host_errors"] += 1
                print(f"soak: run {i} exit {host.returncode}: {err.strip().splitlines()[-1:]}", file=sys.stderr)
            if killed:
                time.sleep(0.6)  # past the 0.5 s watchdog: the device has latched its fault
            cleared = _hilbench("fault", "clear", "--device", f"serial://{pty}")
            first = cleared.stdout.splitlines()[0] if cleared.stdout else "faults: ?"
            if first != "faults: none":
                totals["faults_latched"] += 1
                totals["faults_unexpected"] += not killed
            checked = check_file(out, killed)
            for key, value in checked.items():
                totals[key] += value
            if not killed and checked["unreadable"] == 0 and host.returncode == 0:
                totals["completed"] += 1
            if proc.poll() is not None:
                err = proc.stderr.read().decode(errors="replace").strip().splitlines()
                raise RuntimeError(f"soak: the simulator died after run {i} (exit {proc.returncode}): "
                                   f"{' | '.join(err[-6:])}")
            if checked["unreadable"] == 0 and out.exists():
                for p in (out, Path(str(out) + ".lock")):
                    if p.exists():
                        os.unlink(p)  # keep the disk small over 10 minutes
            i += 1
    finally:
        stop_simulator(proc)
    totals["seconds"] = seconds
    return totals


def run(quick: bool = False) -> list[dict]:
    seconds = 8.0 if quick else 600.0
    t = soak(seconds)
    tag = f"soak {seconds:g} s, 10 kHz"

    def row(name, value, unit, target, ok):
        return {"name": f"{tag}: {name}", "value": float(value), "unit": unit, "baseline_name": None,
                "baseline_value": None, "ratio": None, "target": target, "ok": ok}

    return [
        row("runs", t["runs"], "runs", "report", None),
        row("host kills (SIGKILL)", t["kills"], "runs", "report", None),
        row("runs completed (not killed)", t["completed"], "runs", f"== {t['runs'] - t['kills']} (all not killed)",
            t["completed"] == t["runs"] - t["kills"]),
        row("faults latched", t["faults_latched"], "faults", "report (each after a kill)", None),
        row("faults in runs not killed", t["faults_unexpected"], "faults", "== 0", t["faults_unexpected"] == 0),
        row("samples checked", t["samples"], "samples", "report", None),
        row("samples lost", t["lost"], "samples", "== 0", t["lost"] == 0),
        row("samples invented", t["invented"], "samples", "== 0", t["invented"] == 0),
        row("run files that do not open", t["unreadable"], "files", "== 0", t["unreadable"] == 0),
    ]


if __name__ == "__main__":
    for r in run(quick="--quick" in sys.argv):
        print(f"{r['name']:<50} {r['value']:12.0f} {r['unit']:<8} target {r['target']} ok {r['ok']}")
