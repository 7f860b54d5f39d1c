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


#: the modules that take longest (seconds of test time, measured on 2 cores with --durations=0), run first: `make
#: test` hands whole modules to its workers in collection order (--dist loadfile), and one of these coming last
#: left the other worker idle for up to a minute (longest first is the classic bound for that schedule)
SLOWEST_FIRST = ("benchmarks/test_quick.py", "test_packaging.py", "analysis/drift/test_drift_stationary.py",
                 "analysis/identification/test_identification.py", "analysis/reproductions/test_paper.py",
                 "analysis/residual/test_residual_loop.py", "bench/test_demo.py",
                 "analysis/identification/test_uncertainty.py", "bench/test_default_chirp_warning.py",
                 "bench/test_identify_command.py", "analysis/drift/test_drift_temperature.py",
                 "bench/test_documented_path.py")


def _slowest_first(item: pytest.Item) -> int:
    path = Path(str(item.path)).resolve()
    rel = path.relative_to(TESTS).as_posix() if TESTS in path.parents else ""
    return SLOWEST_FIRST.index(rel) if rel in SLOWEST_FIRST else len(SLOWEST_FIRST)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    items.sort(key=_slowest_first)  # stable: the order within a module, and of the other modules, is kept
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
