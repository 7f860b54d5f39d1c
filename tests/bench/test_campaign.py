"""Campaigns: validation before anything moves, and kill-then-resume with no duplicate or missing run."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from hilbench.analysis.runfile import open_run
from hilbench.bench.campaign import CampaignError, load_campaign

GOOD = """
[defaults]
device = "sim://?pacing=lockstep"
sample_rate = 10000
current_limit = "8 A"

[[run]]
name = "id"
protocol = "identification"
repeats = 2
amplitude = "4 A"
duration = "{duration} s"

[[run]]
name = "ss"
protocol = "stepped_sine"
frequencies = [10.0, 20.0]
amplitudes = ["1 A"]
settle_periods = 2
measure_periods = 4
"""


def _write(tmp_path, text, name="c.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("old", "new", "line", "reason"),
    [
        ('amplitude = "4 A"', 'amplitude = "4 N*m"', 11, "unit 'N*m' is wrong, expected 'A'"),
        ('amplitude = "4 A"', "amplitde = 4", 11, "unknown key 'amplitde'"),
        ('amplitude = "4 A"', "amplitude = 4000", 11, "outside"),
        ("repeats = 2", "repeats = 0", 10, "repeats must be"),
        ('protocol = "stepped_sine"', 'protocol = "sweep"', 16, "protocol must be one of"),
        ('current_limit = "8 A"', 'current_limit = "8 V"', 5, "unit 'V' is wrong"),
    ],
)
def test_bad_campaign_is_refused_with_file_line_and_reason(tmp_path, old, new, line, reason):
    path = _write(tmp_path, GOOD.format(duration=1).replace(old, new))
    with pytest.raises(CampaignError) as info:
        load_campaign(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}:{line}:"), msg
    assert reason in msg


def test_bad_campaign_from_the_cli_is_one_line_and_exit_2(tmp_path):
    path = _write(tmp_path, GOOD.format(duration=1).replace("repeats = 2", "repeats = 2\nfoo = 1"))
    cp = subprocess.run([sys.executable, "-m", "hilbench.bench.cli", "campaign", str(path)], capture_output=True,
                        text=True, timeout=60)
    assert cp.returncode == 2
    assert len(cp.stderr.strip().splitlines()) == 1 and "unknown key 'foo'" in cp.stderr
    assert not (tmp_path / "c").exists()  # nothing moved


def test_killed_campaign_resumes_to_every_run_completed_once(tmp_path):
    # real-time pacing so the kill lands inside the second run
    path = _write(tmp_path, GOOD.format(duration=2).replace("?pacing=lockstep", ""))
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "hilbench.bench.cli", "campaign", str(path), "-o", str(out),
                             "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        index = out / "index.json"
        if index.exists() and len(json.loads(index.read_text())["runs"]) == 1 and (out / "id-2.h5").exists():
            break
        time.sleep(0.05)
    else:
        proc.kill()
        pytest.fail("first run did not complete")
    time.sleep(0.5)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    with open_run(out / "id-2.h5") as run:
        assert run.status == "crashed"
    cp = subprocess.run([sys.executable, "-m", "hilbench.bench.cli", "campaign", str(path), "-o", str(out), "--resume",
                         "--quiet"], capture_output=True, text=True, timeout=120)
    assert cp.returncode == 0, cp.stderr
    assert "id-1: skipped" in cp.stdout
    runs = json.loads((out / "index.json").read_text())["runs"]
    assert [r["key"] for r in runs] == ["id-1", "id-2", "ss-1"]
    assert all(r["status"] == "completed" for r in runs)
    for r in runs:
        with open_run(out / r["file"]) as run:
            assert run.status == "completed" and run.uid == r["uid"]
    assert (out / "id-2.failed-1.h5").exists()  # the crashed attempt is kept, not listed
