"""Fixtures of the reliability suite: the drivers' simulator-process starter."""

from tests.drivers.conftest import simulator  # noqa: F401
