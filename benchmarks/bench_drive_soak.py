"""Drive soak: CiA 402, ODrive and moteus runs at 1 kHz with random host kills, drive kills and stray datagrams.

Three simulated drives (``hilbench sim --canopen``, ``--odrive`` and ``--moteus``, each its own process on
udp_multicast, on this host only) live through the soak. Hosts are real ``hilbench run identify`` processes on
their URLs, 0.5-3 s each, taking the drives in turn. Each run draws its trouble: SIGKILL of the host at a random
moment (40 %), SIGKILL of the drive (15 %; it is started again afterwards), and a burst of stray datagrams on the
drive's group (30 %).

After a host kill, the drive must be at zero torque within its documented timeout (CiA 402: SYNC timeout 0.1 s;
ODrive: watchdog 0.2 s; moteus: its servo.default_timeout_s, 0.1 s) plus a 0.5 s allowance for this loaded
machine: the soak then asks it (CiA 402: statusword by SDO; ODrive: the axis state in its heartbeat; moteus: its
mode register, by a query that commands nothing). A drive still in operation enabled, closed loop, or position or
current mode is a motor left energised. Then ``hilbench fault clear`` re-arms it, as an operator would.

Every run file is checked: sample indices 0..n-1 without gap or repeat (``lost``); every commanded current is one
the host sent (CiA 402: the per-mille quantisation of its setpoint; ODrive: the drive's torque target is a
setpoint it received, or 0 before the first; moteus: the float32 torque command sent for that sample)
(``invented``); a completed run holds every planned sample; a killed run repairs to ``crashed``; a run whose
drive was killed is never ``completed``.
Targets: 0 motors left energised, 0 samples lost or invented, 0 files that do not open.
Full length 10 min (``python -m benchmarks --only drive_soak``); ``--quick`` one run; ``--seconds S`` a soak of
S seconds, ``--kinds moteus`` (or a comma list) on those drives only
(``python -m benchmarks.bench_drive_soak --seconds 60 --kinds moteus``).
"""

from __future__ import annotations

import os
import random
import select
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RATE = 1000  # Hz
KT, RATED = 0.2, 0.5  # N*m/A (the host's default), N*m (the simulated drive's 0x6076)
ALLOWANCE = 0.5  # s beyond a drive's own timeout, for this loaded machine
TIMEOUT = {"canopen": 0.1, "odrive": 0.2, "moteus": 0.1}  # s: each drive's own documented timeout
KINDS = (("canopen", 4), ("odrive", 2), ("moteus", 3))  # the simulated drives and their node (controller) ids


class SimDrive:
    """One simulated drive process on its own udp_multicast group and port; restartable after a kill."""

    def __init__(self, kind: str, node: int) -> None:
        self.kind, self.node = kind, node
        self.port = random.randint(40000, 60000)
        self.group = f"239.{random.randint(1, 254)}.{random.randint(1, 254)}.{random.randint(1, 254)}"
        self.proc: subprocess.Popen | None = None
        self.url = ""
        self.start()

    def start(self) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "hilbench", "sim", f"--{self.kind}", self.group,
                                      "--interface", "udp_multicast", "--node", str(self.node), "--udp-port",
                                      str(self.port)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        ready, _, _ = select.select([self.proc.stdout], [], [], 60)
        if not ready:
            raise RuntimeError(f"the simulated {self.kind} drive did not start")
        self.url = self.proc.stdout.readline().strip()

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(10)

    def stray(self, count: int) -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP) as s:
            s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
            for i in range(count):
                s.sendto(bytes([i % 256]) * (1 + i % 17), (self.group, self.port))

    def energised(self) -> bool:
        """Whether the drive still drives its motor: CiA 402 in operation enabled, ODrive in closed loop, moteus in
        position or current mode."""
        import can

        if self.kind == "moteus":
            return moteus_mode(self.group, self.port, self.node) in (9, 10)

        if self.kind == "canopen":
            import canopen

            from hilbench.drivers import cia402 as c
            from hilbench.firmware_sim.devices.cia402_drive import EDS_PATH

            net = canopen.Network()
            net.connect(interface="udp_multicast", channel=self.group, port=self.port, hop_limit=0)
            try:
                node = net.add_node(self.node, str(EDS_PATH))
                node.sdo.RESPONSE_TIMEOUT = 2.0
                return c.state_of(int(node.sdo[c.STATUSWORD].raw)) is c.State.OPERATION_ENABLED
            finally:
                net.disconnect()
        from hilbench.drivers import odrive_can as o

        bus = can.Bus(interface="udp_multicast", channel=self.group, port=self.port, hop_limit=0)
        try:
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline:
                msg = bus.recv(0.2)
                if msg is not None and msg.arbitration_id == o.can_id(self.node, o.Cmd.HEARTBEAT):
                    return o.HEARTBEAT.unpack(bytes(msg.data).ljust(8, b"\0"))[1] == o.AxisState.CLOSED_LOOP_CONTROL
            raise RuntimeError("the simulated ODrive sent no heartbeat")
        finally:
            bus.shutdown()


def moteus_mode(group: str, port: int, controller: int) -> int:
    """The mode register of the moteus controller on ``group``/``port``, by a query that writes nothing (so it
    neither commands the controller nor feeds its watchdog)."""
    import can
    import moteus

    query = moteus.Controller(controller).make_query()
    bus = can.Bus(interface="udp_multicast", channel=group, port=port, hop_limit=0, fd=True)
    try:
        bus.send(can.Message(arbitration_id=0x8000 | controller, data=query.data, is_extended_id=True, is_fd=True,
                             bitrate_switch=True))
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            msg = bus.recv(0.2)
            if msg is not None and msg.arbitration_id == controller << 8:
                return int(moteus.parse_registers(bytes(msg.data)).response[moteus.Register.MODE])
        raise RuntimeError("the simulated moteus controller did not answer a query")
    finally:
        bus.shutdown()


def check_drive_file(path: Path, kind: str, killed: bool, drive_killed: bool) -> dict[str, int]:
    """Lost and invented samples of one drive run file, and whether it opened and says what happened."""
    from hilbench.common.runfile import RunFileError, open_run, repair

    out = {"lost": 0, "invented": 0, "unreadable": 0, "samples": 0, "absent": 0, "short_completed": 0,
           "drive_ended": 0}
    if not path.exists():
        out["absent" if killed else "unreadable"] = 1
        return out
    try:
        repair(path)
        with open_run(path) as run:
            status, n = run.status, run.n_samples
            index = run.channel("sample_index")
            cmd = run.channel("current_cmd")
            setpoints = run.protocol_array("setpoints")
    except RunFileError:
        out["unreadable"] = 1
        return out
    out["samples"] = n
    out["lost"] = int(np.sum(index != np.arange(n)))  # a gap or a repeat moves every later index
    if status == "completed" and n != setpoints.size:
        out["short_completed"] = 1  # a run that ends short is never completed
        out["lost"] += abs(setpoints.size - n)
    if kind == "canopen":  # the host's own command, quantised to per mille of the rated torque
        expected = np.rint(setpoints * KT / RATED * 1000) * RATED / 1000 / KT
        wrong = ~np.isclose(cmd, expected[np.clip(index, 0, setpoints.size - 1)], rtol=1e-12, atol=0.0)
        out["invented"] = int(np.sum(wrong)) + max(0, n - setpoints.size)
    elif kind == "moteus":  # the torque command sent for that sample, float32 on the wire
        expected = np.float32(setpoints * KT).astype(np.float64) / KT
        wrong = cmd != expected[np.clip(index, 0, setpoints.size - 1)]
        out["invented"] = int(np.sum(wrong)) + max(0, n - setpoints.size)
    else:  # the drive's own torque target: a setpoint it received (float32 on the wire) or 0 before the first
        sent = np.concatenate([[0.0], (setpoints * KT).astype(np.float32).astype(np.float64)])
        out["invented"] = int(np.sum(~np.isin((cmd * KT).astype(np.float32).astype(np.float64), sent)))
    if killed and status != "crashed" and not (status == "completed" and n == setpoints.size):
        out["unreadable"] += 1  # a killed run must say so (unless the kill came after it had finished)
    out["drive_ended"] = int(drive_killed and status != "completed")  # the drive's death ended the run
    return out


def _wait_streaming(out: Path, host: subprocess.Popen, samples: int = 50, timeout: float = 60.0) -> None:
    """Wait until the run file holds ``samples`` flushed samples (the stream runs), or the host has ended."""
    from hilbench.common.runfile import RunFileError, open_run

    deadline = time.monotonic() + timeout
    while host.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
        if not out.exists():
            continue
        try:
            with open_run(out) as run:
                if run.refresh() >= samples:
                    return
        except RunFileError:
            continue


def soak(seconds: float, seed: int = 30, work: Path | None = None, kinds: tuple[str, ...] | None = None) -> dict:
    """The soak over the drives ``kinds`` (default: all of :data:`KINDS`); totals, and runs and host kills per kind."""
    rng = np.random.default_rng(seed)
    random.seed(seed)
    work = Path(work or tempfile.mkdtemp(prefix="hilbench-drive-soak-"))
    drives = [SimDrive(kind, node) for kind, node in KINDS if kinds is None or kind in kinds]
    totals = {k: 0 for k in ("runs", "kills", "drive_kills", "stray_bursts", "stray_datagrams", "completed",
                             "energised", "lost", "invented", "unreadable", "absent", "samples", "short_completed",
                             "host_errors", "clear_failed", "drive_ended")}
    t_end = time.monotonic() + seconds
    try:
        i = 0
        while time.monotonic() < t_end:
            drive = drives[i % len(drives)]
            duration = float(rng.uniform(0.5, 3.0))
            kill, drive_kill, stray = rng.random() < 0.4, rng.random() < 0.15, rng.random() < 0.3
            out = work / f"{drive.kind}{i:04d}.h5"
            host = subprocess.Popen([sys.executable, "-m", "hilbench", "run", "identify", "--device", drive.url,
                                     "--sample-rate", str(RATE), "--duration", f"{duration:.3f}", "--amplitude",
                                     "2", "--seed", str(i), "--quiet", "-o", str(out)],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            killed = drive_killed = False
            if kill or drive_kill or stray:  # at a random moment of the stream (files flush every 0.5 s of it)
                _wait_streaming(out, host, int(rng.uniform(0.05, 0.9) * duration * RATE))
                if stray:
                    drive.stray(int(rng.integers(1, 20)))
                    totals["stray_bursts"] += 1
                if drive_kill and host.poll() is None:
                    drive.kill()
                    drive_killed = True
                elif kill and host.poll() is None:
                    os.kill(host.pid, signal.SIGKILL)
                    killed = True
                    time.sleep(TIMEOUT[drive.kind] + ALLOWANCE)
                    totals["energised"] += drive.energised()
            _, err = host.communicate(timeout=300)
            totals["runs"] += 1
            totals["kills"] += killed
            for key, value in ((f"runs {drive.kind}", 1), (f"kills {drive.kind}", killed)):
                totals[key] = totals.get(key, 0) + value
            totals["drive_kills"] += drive_killed
            if drive_killed:
                drive.start()
            elif not killed and host.returncode != 0:
                totals["host_errors"] += 1
                print(f"drive soak: run {i} ({drive.kind}) exit {host.returncode}: {err.strip().splitlines()[-1:]}",
                      file=sys.stderr)
            cleared = subprocess.run([sys.executable, "-m", "hilbench", "fault", "clear", "--device", drive.url],
                                     capture_output=True, text=True, timeout=120)
            totals["clear_failed"] += cleared.returncode != 0
            checked = check_drive_file(out, drive.kind, killed, drive_killed)
            for key, value in checked.items():
                totals[key] += value
            if not killed and not drive_killed and host.returncode == 0 and checked["unreadable"] == 0:
                totals["completed"] += 1
            for p in (out, Path(str(out) + ".lock")):
                if p.exists() and checked["unreadable"] == 0:
                    os.unlink(p)
            i += 1
    finally:
        for drive in drives:
            drive.stop()
    totals["seconds"] = seconds
    return totals


def run(quick: bool = False, seconds: float | None = None, kinds: tuple[str, ...] | None = None) -> list[dict]:
    """The soak's rows: ``quick`` one run (make test runs every benchmark quick), else ``seconds`` (default 600)
    on the drives ``kinds`` (default all)."""
    seconds = 1.0 if quick else (seconds or 600.0)
    if quick and kinds is None:  # make test's smoke run: one drive (starting all three took 15 s of the serial part)
        kinds = ("moteus",)
    t = soak(seconds, kinds=kinds)
    tag = f"drive soak {seconds:g} s, 1 kHz"

    def row(name, value, unit, target, ok):
        return {"name": f"{tag}: {name}", "value": float(value), "unit": unit, "baseline_name": None,
                "baseline_value": None, "ratio": None, "target": target, "ok": ok}

    clean = t["runs"] - t["kills"] - t["drive_kills"]
    return [
        row("runs (CiA 402, ODrive and moteus in turn)", t["runs"], "runs", "report", None),
        row("host kills (SIGKILL)", t["kills"], "runs", "report", None),
        *[row(f"{name} (host kills)", t[f"runs {name}"], "runs", f"{t[f'kills {name}']} killed", None)
          for name in ("canopen", "odrive", "moteus") if f"runs {name}" in t],
        row("drive kills (SIGKILL)", t["drive_kills"], "runs", "report", None),
        row("runs ended by the drive's death (aborted, not completed)", t["drive_ended"], "runs", "report", None),
        row("stray datagram bursts", t["stray_bursts"], "bursts", "report", None),
        row("motors left energised past the timeout", t["energised"], "drives", "== 0", t["energised"] == 0),
        row("runs completed (not killed)", t["completed"], "runs", f"== {clean}", t["completed"] == clean),
        row("samples checked", t["samples"], "samples", "report", None),
        row("samples lost", t["lost"], "samples", "== 0", t["lost"] == 0),
        row("samples invented", t["invented"], "samples", "== 0", t["invented"] == 0),
        row("short runs called completed", t["short_completed"], "runs", "== 0", t["short_completed"] == 0),
        row("run files that do not open", t["unreadable"], "files", "== 0", t["unreadable"] == 0),
        row("fault clear refused", t["clear_failed"], "runs", "== 0", t["clear_failed"] == 0),
    ]


if __name__ == "__main__":
    # a short soak of its own length, on some of the drives: python -m benchmarks.bench_drive_soak --seconds 60
    # --kinds moteus
    argv = sys.argv[1:]
    for r in run(quick="--quick" in argv, seconds=float(argv[argv.index("--seconds") + 1]) if "--seconds" in argv
                 else None, kinds=tuple(argv[argv.index("--kinds") + 1].split(",")) if "--kinds" in argv else None):
        print(f"{r['name']:<60} {r['value']:12.0f} {r['unit']:<8} target {r['target']} ok {r['ok']}")
