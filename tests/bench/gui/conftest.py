import pytest

from hilbench.bench.gui.app import qt_problem

_PROBLEM = qt_problem()


def pytest_collection_modifyitems(config, items):
    if not _PROBLEM:
        return
    skip = pytest.mark.skip(reason=f"GUI cannot run here: {_PROBLEM}")
    for item in items:
        path = str(item.fspath).replace("\\", "/")
        if "tests/bench/gui/" in path and not path.endswith("test_display_buffer.py"):  # plain numpy
            item.add_marker(skip)
