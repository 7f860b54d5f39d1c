"""A campaign played on the simulated amplifier with its thermal model on ([drift] in its TOML): every run file
holds the winding temperature the device reported (channel ``temperature``, degC) and a summary line, the
winding warms from run to run, and ``hilbench analyse`` reads it into ``temperature_mean``."""

import json
import subprocess
import sys

import h5py
import numpy as np
import pyarrow.parquet as pq

SIM = """
[drift]
ambient = 21.0
thermal_time_constant = 60.0   # s: the few seconds between runs cool the winding by a few per cent only
thermal_resistance = 20.0      # K/W
winding_resistance = 1.0       # ohm
level_temperature_coefficient = -0.002
"""

CAMPAIGN = """
[defaults]
device = "sim://?pacing=lockstep&config={config}"
sample_rate = 1000
current_limit = "10 A"

[[run]]
name = "warm"
protocol = "identification"
amplitude = "8 A"
duration = "1 s"
repeats = 4
"""


def test_a_campaign_records_the_winding_temperature_and_analyse_reads_it(tmp_path):
    sim = tmp_path / "sim.toml"
    sim.write_text(SIM)
    plan = tmp_path / "c.toml"
    plan.write_text(CAMPAIGN.format(config=sim))
    out = tmp_path / "runs"
    done = subprocess.run([sys.executable, "-m", "hilbench", "campaign", str(plan), "-o", str(out), "--quiet"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    keys = [e["key"] for e in json.loads((out / "index.json").read_text())["runs"]]
    assert keys == [f"warm-{r}" for r in range(1, 5)]
    firsts, lasts = [], []
    for key in keys:
        with h5py.File(out / f"{key}.h5") as f:
            temperature = f["samples/temperature"][:]
            assert f["samples/temperature"].attrs["unit"] == "degC"
            events = [e["message"].decode() for e in f["events"][:] if e["kind"] == b"info"]
        assert temperature.size == 1000 and np.all(np.isfinite(temperature))
        # one reading per sample block, held: the channel steps up block by block while the current flows
        assert np.all(np.diff(temperature) >= 0) and temperature[-1] > temperature[0]
        (line,) = [m for m in events if m.startswith("winding temperature")]
        assert line == (f"winding temperature {temperature[0]:.2f} -> {temperature[-1]:.2f} degC "
                        f"(max {temperature.max():.2f} degC)")
        firsts.append(float(temperature[0]))
        lasts.append(float(temperature[-1]))
    assert 21.0 < firsts[0] < 24.0  # from ambient: the first reading comes after the first block (0.5 s)
    # each run starts warmer than the one before (cooling between runs < heating during one)
    assert all(b > a for a, b in zip(firsts, firsts[1:], strict=False)), firsts
    assert all(b > a for a, b in zip(lasts, lasts[1:], strict=False)), lasts
    done = subprocess.run([sys.executable, "-m", "hilbench", "analyse", str(out), "--serial", "--quiet"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    rows = pq.read_table(out / "analysis" / "results.parquet").to_pylist()
    by_repeat = sorted(rows, key=lambda r: r["repeat"])
    assert [r["status"] for r in by_repeat] == ["ok"] * 4, [(r["status"], r["error"]) for r in by_repeat]
    means = np.array([r["temperature_mean"] for r in by_repeat])
    assert np.all(np.diff(means) > 0), means
