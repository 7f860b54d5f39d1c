"""Fixtures of the reliability suite: the drivers' simulator-process starter and small disks."""

import pytest

from tests.drivers.conftest import simulator  # noqa: F401
from tests.reliability.small_disk import SmallDisk


@pytest.fixture
def small_disk(tmp_path):
    """Make :class:`SmallDisk` s of a given size in bytes (unmounted at the end)."""
    disks = []

    def make(size: int, name: str = "disk") -> SmallDisk:
        disks.append(SmallDisk(tmp_path / name, size))
        return disks[-1]

    yield make
    for d in disks:
        d.close()
