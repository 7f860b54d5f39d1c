"""``hilbench info`` and ``hilbench sim`` (device-link subcommands), and the drivers' import boundary."""

import subprocess
import sys
from pathlib import Path

from hilbench.bench.cli import main

ROOT = Path(__file__).resolve().parents[2]


def test_bench_info_on_the_simulator(capsys):
    assert main(["info", "--device", "sim://?pacing=lockstep"]) == 0
    out = capsys.readouterr().out
    for line in ("model: HB-SIM-1", "protocol version: 3", "sensors: none", "state: UNCONFIGURED", "faults: none",
                 "config: not configured", "counters: crc_errors=0"):
        assert line in out


def test_bench_info_bad_url_is_one_line(capsys):
    assert main(["info", "--device", "gopher://x"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown scheme" in err


def test_bench_sim_refuses_bad_moteus_position_gains_in_one_line(capsys):
    # before any bus opens or the simulator process starts: a negative gain, and gains given to a non-moteus drive
    for argv, words in ((["--moteus", "239.1.2.3", "--pid-position", "4", "-1", "0.1", "0"], "finite and >= 0"),
                        (["--odrive", "239.1.2.3", "--pid-position", "4", "0", "0.1", "0"], "(--moteus)")):
        assert main(["sim", *argv, "--interface", "udp_multicast"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--pid-position" in err and words in err, err


def test_bench_sim_prints_pty_path_first():
    proc = subprocess.Popen([sys.executable, "-m", "hilbench.bench.cli", "sim", "--serial", "--pacing", "lockstep"],
                            stdout=subprocess.PIPE, cwd=ROOT)
    try:
        path = proc.stdout.readline().decode().strip()
        assert path.startswith("/dev/")
        assert main(["info", "--device", f"serial://{path}"]) == 0
    finally:
        proc.terminate()
        proc.wait()
        proc.stdout.close()


def test_drivers_never_import_firmware_sim_bench_or_analysis():
    code = ("import sys, hilbench.drivers.device_url, hilbench.drivers.amplifier, hilbench.drivers.links, "
            "hilbench.drivers.fault_injection; "
            "bad = [m for m in sys.modules if m.split('.')[:2] in (['hilbench', 'firmware_sim'], "
            "['hilbench', 'bench'], ['hilbench', 'analysis'])]; "
            "print(bad)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert res.stdout.strip() == "[]"


def test_firmware_imports_only_the_protocol_from_drivers():
    code = ("import sys, hilbench.firmware_sim.devices.device, hilbench.firmware_sim.devices.core_c, "
            "hilbench.firmware_sim.__main__; "
            "print(sorted(m.removeprefix('hilbench.') for m in sys.modules "
            "if m.split('.')[:2] in (['hilbench', 'drivers'], ['hilbench', 'bench'], ['hilbench', 'analysis'])))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    mods = eval(res.stdout)
    assert all(m in ("drivers", "drivers.errors") or m.startswith("drivers.protocol") for m in mods), mods


def test_bench_info_names_the_temperature_sensor_of_a_drifting_simulator(capsys, tmp_path):
    sim = tmp_path / "sim.toml"
    sim.write_text("[drift]\nambient = 25.0\n")
    assert main(["info", "--device", f"sim://?pacing=lockstep&config={sim}"]) == 0
    assert "sensors: temperature (winding temperature in every sample block, degC)" in capsys.readouterr().out
