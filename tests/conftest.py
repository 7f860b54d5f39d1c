import os
from pathlib import Path

import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("MPLBACKEND", "Agg")

TESTS = Path(__file__).resolve().parent
#: folders whose tests start a realtime device, a drive process, QEMU or the GUI's live view: `make test` runs
#: them one at a time, so that no other test competes with them for the cores (the rest runs in parallel)
REALTIME = {"bench", "drivers", "reliability", "benchmarks", "firmware"}


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # a test in those folders that declares it starts no device (module pytestmark or a parameter's marks:
    # `device_free`) runs in the parallel part; a test marked `realtime` itself is realtime wherever it is
    for item in items:
        parts = Path(item.path).resolve().relative_to(TESTS).parts
        if parts[0] in REALTIME and not item.get_closest_marker("device_free"):
            item.add_marker(pytest.mark.realtime)
