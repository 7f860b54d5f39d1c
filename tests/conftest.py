import os
import threading
from pathlib import Path

import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("MPLBACKEND", "Agg")

TESTS = Path(__file__).resolve().parent
#: what a device process looks like on this machine's process table: the simulated devices (sim://, the CiA 402
#: drive, the ODrive) and the emulated Cortex-M target
DEVICE_COMMANDS = ("-m hilbench.firmware_sim", "qemu-system-")
#: a simulated device in lockstep waits for the host and keeps no clock of its own: nothing in it is timing
#: sensitive, so a test may start one in the parallel part
UNPACED = "--pacing lockstep"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # A test that starts a device says so by requesting the `starts_devices` fixture (a module: `pytestmark =
    # pytest.mark.usefixtures("starts_devices")`); it, and a test marked `realtime` itself, is realtime, which `make
    # test` runs one at a time after the parallel part so that no other test competes with it for the cores. The
    # folder a test sits in plays no part; `_device_guard` fails a test that starts a device without saying so.
    # A test of such a module that itself starts none says so with the `device_free` marker.
    for item in items:
        if "starts_devices" in getattr(item, "fixturenames", ()) and not item.get_closest_marker("device_free"):
            item.add_marker(pytest.mark.realtime)


@pytest.fixture
def starts_devices() -> None:
    """Declares that the test starts a device paced in real time (a simulator process, a drive, QEMU, the GUI's
    live view)."""


def _device_processes(root: int) -> set[str]:
    """Command lines of ``root``'s descendants that are devices paced in real time (Linux /proc)."""
    parent: dict[int, int] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
                parent[int(d.name)] = int(stat[stat.rindex(")") + 2:].split()[1])
            except (OSError, ValueError, IndexError):
                continue
    found: set[str] = set()
    for pid in parent:
        p, depth = pid, 0
        while p in parent and p != root and depth < 32:
            p, depth = parent[p], depth + 1
        if p == root and pid != root:
            try:
                cmd = (Path("/proc") / str(pid) / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except OSError:
                continue
            if any(c in cmd for c in DEVICE_COMMANDS) and UNPACED not in cmd:
                found.add(cmd.strip()[:160])
    return found


@pytest.fixture(autouse=True)
def _device_guard(request: pytest.FixtureRequest):
    """A test that did not declare `starts_devices` must not start one: it would run in the parallel part, where
    a device's timing competes with other tests. Descendant processes are sampled every 0.1 s while it runs."""
    if request.node.get_closest_marker("realtime") \
            or not Path("/proc/self/stat").exists():
        yield
        return
    seen: set[str] = set()
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(0.1):
            seen.update(_device_processes(os.getpid()))

    t = threading.Thread(target=sample, daemon=True)
    t.start()
    try:
        yield
    finally:
        stop.set()
        t.join()
    if seen:
        pytest.fail("this test starts a device without declaring it: add pytestmark = pytest.mark.usefixtures("
                    f"\"starts_devices\") to its module (seen: {sorted(seen)[0]})", pytrace=False)
