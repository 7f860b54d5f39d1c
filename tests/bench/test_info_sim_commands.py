"""``bench info`` and ``bench sim`` (device-link subcommands), and the drivers' import boundary."""

import os
import subprocess
import sys
from pathlib import Path

from bench.cli import main

ROOT = Path(__file__).resolve().parents[2]


def test_bench_info_on_the_simulator(capsys):
    assert main(["info", "--device", "sim://?pacing=lockstep"]) == 0
    out = capsys.readouterr().out
    for line in ("model: HB-SIM-1", "protocol version: 1", "state: UNCONFIGURED", "faults: none",
                 "config: not configured", "counters: crc_errors=0"):
        assert line in out


def test_bench_info_bad_url_is_one_line(capsys):
    assert main(["info", "--device", "gopher://x"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown scheme" in err


def test_bench_sim_prints_pty_path_first():
    proc = subprocess.Popen([sys.executable, "-m", "bench.cli", "sim", "--serial", "--pacing", "lockstep"],
                            stdout=subprocess.PIPE, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    try:
        path = proc.stdout.readline().decode().strip()
        assert path.startswith("/dev/")
        assert main(["info", "--device", f"serial://{path}"]) == 0
    finally:
        proc.terminate()
        proc.wait()
        proc.stdout.close()


def test_drivers_never_import_firmware_sim_bench_or_analysis():
    code = ("import sys, drivers.device_url, drivers.amplifier, drivers.links, drivers.fault_injection; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('firmware_sim', 'bench', 'analysis')]; "
            "print(bad)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert res.stdout.strip() == "[]"


def test_firmware_imports_only_the_protocol_from_drivers():
    code = ("import sys, firmware_sim.device, firmware_sim.firmware, firmware_sim.__main__; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('drivers', 'bench', 'analysis')))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    mods = eval(res.stdout)
    assert all(m in ("drivers", "drivers.errors") or m.startswith("drivers.protocol") for m in mods), mods
