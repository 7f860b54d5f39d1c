"""The guard behind make test's two parts (tests/conftest.py): it sees a device process among a test's
descendants, also a grandchild, and lets a lockstep simulator (no clock of its own) pass."""

import subprocess
import sys
import time

import pytest

from tests.conftest import _device_processes

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc (Linux only)")


def _spawn(*argv: str) -> subprocess.Popen:
    # a shell between us and the "device" makes it a grandchild, as a CLI subprocess's simulator is; the stand-in
    # sleeps, and its arguments make its command line read as the simulator's (`... -m hilbench.firmware_sim ...`)
    cmd = f"{sys.executable} -c 'import time; time.sleep(3)' -m {' '.join(argv)}"
    return subprocess.Popen(["sh", "-c", f"{cmd}; :"])


def _seen_within(proc: subprocess.Popen, seconds: float = 2.0) -> set[str]:
    deadline = time.monotonic() + seconds
    found: set[str] = set()
    while not found and time.monotonic() < deadline:
        found = _device_processes(__import__("os").getpid())
        time.sleep(0.05)
    proc.kill()
    proc.wait()
    return found


@pytest.mark.realtime  # it starts (a stand-in of) a device on purpose: the guard itself is off for it
def test_a_device_grandchild_is_seen():
    found = _seen_within(_spawn("hilbench.firmware_sim", "--serial"))
    assert any("-m hilbench.firmware_sim" in c for c in found), found


@pytest.mark.realtime
def test_a_lockstep_simulator_and_other_children_are_not_devices():
    assert _seen_within(_spawn("hilbench.firmware_sim", "--serial", "--pacing", "lockstep"), 0.6) == set()
    assert _seen_within(_spawn("something_else"), 0.6) == set()
    # a process that only imports the package (as the wheel tests' `python -c "import hilbench.firmware_sim..."`)
    assert _seen_within(_spawn("x", "hilbench.firmware_sim.engine._plant"), 0.6) == set()
