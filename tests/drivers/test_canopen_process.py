"""CiA 402 end to end across processes: the simulated drive as its own process (``hilbench sim --canopen``)
on python-can's ``udp_multicast`` bus, kept on this host (hop limit 0) and on a port of its own."""

import os
import random
import select
import signal
import subprocess
import sys
import time

import can
import canopen
import h5py
import numpy as np
import pytest

from hilbench.analysis.identification.identify import RunArrays, identify
from hilbench.analysis.identification.maxwell_fit import LipSettings
from hilbench.drivers import cia402 as c
from hilbench.firmware_sim.devices.cia402_drive import EDS_PATH
from hilbench.firmware_sim.devices.sim_config import load_sim_config, substeps_for
from hilbench.firmware_sim.engine.plant import simulate

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]  # starts a device
def _free_udp_port() -> int:
    return random.randint(40000, 60000)


@pytest.fixture
def drive_process():
    """Start ``python -m hilbench.firmware_sim --canopen`` (real-time plant clock); yields (url, port, node)."""
    procs = []

    def start(node: int = 4, clock: str = "real") -> tuple[str, int, int]:
        port = _free_udp_port()
        group = f"239.{random.randint(1, 254)}.{random.randint(1, 254)}.{random.randint(1, 254)}"
        proc = subprocess.Popen([sys.executable, "-m", "hilbench", "sim", "--canopen", group, "--interface",
                                 "udp_multicast", "--node", str(node), "--udp-port", str(port), "--clock", clock],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        procs.append(proc)
        ready, _, _ = select.select([proc.stdout], [], [], 30)
        assert ready, "the simulated drive did not start"
        url = proc.stdout.readline().strip()
        assert url.startswith("canopen://udp_multicast/") and f"port={port}" in url, url
        return url, port, node

    yield start
    for proc in procs:
        proc.terminate()
        proc.wait(10)


HOST = """
import sys, numpy as np
from hilbench.drivers.device_url import open_device
from hilbench.drivers import protocol as p
d = open_device(sys.argv[1])
d.configure(p.Config(sample_rate=1000, current_limit=20.0, torque_constant=0.2, counts_per_rev=1 << 20,
                     watchdog_timeout=0.3))
d.arm()
for i, blk in enumerate(d.stream(np.full(120_000, 1.0))):
    if i == 10:
        print("streaming", flush=True)
"""


def test_killed_host_the_drive_stops_torque_within_its_sync_timeout(drive_process):
    url, port, node = drive_process(node=5)
    listener = can.Bus(interface="udp_multicast", channel=url.split("/")[3].split("?")[0], port=port, hop_limit=0)
    host = subprocess.Popen([sys.executable, "-c", HOST, url], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        ready, _, _ = select.select([host.stdout], [], [], 60)
        assert ready and host.stdout.readline().strip() == "streaming", host.stderr.read() if not ready else ""
        os.kill(host.pid, signal.SIGKILL)
        killed = time.monotonic()
        last_sync = emcy = None
        while time.monotonic() - killed < 3.0:  # the listener's kernel timestamps order SYNCs and the EMCY
            msg = listener.recv(0.1)
            if msg is None:
                continue
            if msg.arbitration_id == 0x80:
                last_sync = msg.timestamp
            elif msg.arbitration_id == 0x80 + node and msg.data[:2] != b"\0\0":
                emcy = (int.from_bytes(msg.data[:2], "little"), msg.timestamp, time.monotonic() - killed)
                break
        host.wait(10)
    finally:
        listener.shutdown()
        if host.poll() is None:
            host.kill()
    assert emcy is not None and last_sync is not None, "the drive sent no EMCY after its host died"
    code, stamp, after_kill = emcy
    # The SYNC timeout (0.1 s) comes before the heartbeat timeout (0.3 s): the code says which one fired. The
    # drive's monitor polls every 2 ms, measured 0.10-0.11 s from the last SYNC on a quiet machine. The drive's
    # clock starts when it *processes* the SYNC, not when the listener's kernel stamped it: under load its
    # notifier thread runs up to 0.2 s behind (CI saw 0.30 s), so the upper bound allows that lag.
    assert code == 0x8250, hex(code)
    assert 0.1 <= stamp - last_sync < 0.1 + 0.25, stamp - last_sync
    assert after_kill < 0.3 + 0.5
    # and the drive really applies no torque: ask it over SDO, as a second master would
    net = canopen.Network()
    net.connect(interface="udp_multicast", channel=url.split("/")[3].split("?")[0], port=port, hop_limit=0)
    try:
        remote = net.add_node(node, str(EDS_PATH))
        assert c.state_of(remote.sdo[c.STATUSWORD].raw) is c.State.FAULT
        assert remote.sdo[0x6074].raw == 0  # torque demand
        assert remote.sdo[c.ERROR_CODE].raw == 0x8250
    finally:
        net.disconnect()


@pytest.mark.slow
def test_cli_identify_run_against_the_drive_process_recovers_the_plant(drive_process, tmp_path):
    # The drive's plant follows the SYNC count here (--clock sync): the pipeline (CLI, separate process, bus,
    # PDOs, run file) must hand the analysis what the plant did, sample for sample, whatever this machine's
    # load does to the cycle. How real-time jitter degrades the fit is measured in benchmarks/bench_drives.py.
    url, _, _ = drive_process(node=7, clock="sync")
    out = tmp_path / "id.h5"
    cmd = [sys.executable, "-m", "hilbench", "run", "identify", "--device", url, "--sample-rate", "1000",
           "--duration", "10", "--quiet", "-o", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    with h5py.File(out) as f:
        assert f.attrs["status"] == "completed"
        s = f["samples"]
        t, tau, x, counts = s["t"][:], s["torque"][:], s["position"][:], s["counts"][:]
        np.testing.assert_array_equal(s["cycle"][:], np.arange(t.size))
        host_time = s["host_time"][:]
        u = f["protocol/setpoints"][:]
        infos = [e["message"].decode() for e in f["events"][:] if e["kind"] == b"info"]
    assert t.size == 10_000 and np.all(np.diff(host_time) > 0)
    timing = [m for m in infos if m.startswith("host-clocked timing:")]
    assert len(timing) == 1 and timing[0].startswith("host-clocked timing: 10000 cycles at 1000 Hz")
    # the drive's units, as adopted (0x608F, no factor objects on the simulated drive), said once
    assert [m for m in infos if "units adopted from the drive" in m], "\n".join(infos)
    # oracle: the C plant run directly on the per-mille commands, 10 sub-samples per cycle (see
    # test_canopen_drive.py): the file must hold exactly its samples
    p = load_sim_config().plant
    params = p.replace(counts_per_rev=2**20, torque_constant=0.2, current_limit=20.0)
    u_applied = np.rint(u * 0.2 / 0.5 * 1000) * 0.5 / 1000 / 0.2
    sim = simulate(params, np.concatenate([np.zeros(9), np.repeat(u_applied, 10)]), 1e-4, substeps_for(params, 1e-4))
    k = 9 + 10 * np.arange(u.size)
    np.testing.assert_array_equal(counts, sim.counts[k])
    np.testing.assert_allclose(tau, np.rint(sim.current_meas[k] * 0.2 / 0.5 * 1000) * 0.5 / 1000)
    # identification on the file: J within 1 % (the target; +0.40 % measured on a 15 s run, which 10 s
    # also keeps within 1 %). The virgin curve needs a longer excitation than 10 s at 1 kHz (1.06 % at 60 s,
    # the same as the plant alone gives):
    # measured on 60 s runs by benchmarks/bench_drives.py.
    m = identify(RunArrays(t, tau, x), settings=LipSettings(timing="hold_previous")).model
    assert m.inertia == pytest.approx(p.inertia, rel=0.01), timing[0]
    # the identify command states the run's timing verdict, in one line with its figures
    cmd = [sys.executable, "-m", "hilbench", "identify", str(out), "--json", str(tmp_path / "m.json")]
    if "UNFIT" in timing[0]:  # a loaded machine broke the cycle's limits: refused in one line unless allowed
        refused = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert refused.returncode == 2 and "its device marked it unfit" in refused.stderr, refused.stderr
        assert refused.stderr.count("\n") == 1
        cmd.append("--allow-incomplete")
    ident = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert ident.returncode == 0, ident.stderr
    assert f"{out}: {timing[0]}" in (ident.stderr if "UNFIT" in timing[0] else ident.stdout).splitlines()


def test_cli_info_and_one_line_refusal_against_the_drive_process(drive_process, tmp_path):
    url, _, _ = drive_process(node=9)
    info = subprocess.run([sys.executable, "-m", "hilbench", "info", "--device", url], capture_output=True,
                          text=True, timeout=120)
    assert info.returncode == 0, info.stderr
    assert "model: HB-SIM-402" in info.stdout and "clock: host-clocked; runs current at 1000, 2000 Hz" in info.stdout
    out = tmp_path / "v.h5"
    refused = subprocess.run([sys.executable, "-m", "hilbench", "run", "identify", "--device", url, "--mode",
                              "velocity", "--sample-rate", "1000", "--amplitude", "1", "--quiet", "-o", str(out)],
                             capture_output=True, text=True, timeout=120)
    assert refused.returncode == 2
    assert refused.stderr.strip().splitlines() == [
        f"hilbench run: error: cannot run identification: {url} cannot run velocity mode "
        f"(it offers current at 1000, 2000 Hz)"]
    assert not out.exists()


def test_killed_run_then_fault_show_clear_and_a_new_run_from_the_cli_alone(drive_process, tmp_path):
    # issue #25: a host killed mid-run leaves the drive in fault (SYNC lost, 0x8250) with the axis spinning; the
    # CLI alone shows the fault, clears it, and runs again, and the new run starts at rest: the torque was zeroed
    # before enable and the axis coasted to rest meanwhile (no 'uncommanded motion' flag, first sample still)
    url, _, _ = drive_process(node=6)
    # 8 A at 2 Hz swings the axis between about -37 and +37 rad/s (1 A stays stuck in friction)
    swinging = HOST.replace("np.full(120_000, 1.0)", "8.0 * np.sin(2 * np.pi * 2.0 * np.arange(120_000) / 1000)")
    host = subprocess.Popen([sys.executable, "-c", swinging, url], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        ready, _, _ = select.select([host.stdout], [], [], 60)
        assert ready and host.stdout.readline().strip() == "streaming", host.stderr.read() if not ready else ""
        time.sleep(0.5)
        os.kill(host.pid, signal.SIGKILL)
        host.wait(10)
    finally:
        if host.poll() is None:
            host.kill()
    time.sleep(0.5)  # the drive's SYNC timeout (0.1 s) has fired

    def cli(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "hilbench", *args], capture_output=True, text=True,
                              timeout=120)

    show = cli("fault", "show", "--device", url)
    assert show.returncode == 0, show.stderr
    assert "0x603F error code 0x8250 RPDO timeout" in show.stdout, show.stdout
    assert "0x1003 error history (1, newest first): 0x8250 RPDO timeout" in show.stdout, show.stdout
    cleared = cli("fault", "clear", "--device", url)
    assert cleared.returncode == 0, cleared.stderr
    assert "cleared; faults now: none" in cleared.stdout, cleared.stdout
    out = tmp_path / "again.h5"
    again = cli("run", "identify", "--device", url, "--sample-rate", "1000", "--duration", "1", "--quiet",
                "-o", str(out))
    assert again.returncode == 0, again.stderr
    with h5py.File(out) as f:
        assert f.attrs["status"] == "completed"
        velocity, torque = f["samples/velocity"][:3], f["samples/torque"][0]
        events = [m.decode() for m in f["events"]["message"][:]]
    assert not any("uncommanded motion" in e for e in events), events
    assert abs(velocity[0]) < 0.01 * 300.0 and torque == 0.0, (velocity, torque)  # the check's own limits
