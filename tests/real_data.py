"""Where the tests find real measured data.

- EMPS (Janot, Gautier, Brunot 2019) ships in the repository, ``tests/data/emps/`` (see its README.md): every
  clone runs the tests that need it, never skipped.
- HSM150 and the Mnich rack-and-pinion rig do not ship (no licence): they are read from the folder named by
  the environment variable ``HILBENCH_REAL_DATA`` (holding ``hsm150/`` and ``mnich_rack_pinion/``). Tests that
  need them skip with a reason naming the variable.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ENV = "HILBENCH_REAL_DATA"
EMPS = Path(__file__).resolve().parent / "data" / "emps"
EMPS_TRAIN = EMPS / "DATA_EMPS.mat"
EMPS_TEST = EMPS / "DATA_EMPS_PULSES.mat"


def real_data(folder: str) -> Path | None:
    """``$HILBENCH_REAL_DATA/<folder>`` if the variable is set and the folder exists, else None."""
    root = os.environ.get(ENV)
    if not root:
        return None
    path = Path(root) / folder
    return path if path.is_dir() else None


def skip_reason(folder: str) -> str:
    root = os.environ.get(ENV)
    if not root:
        return f"{folder} data set: set {ENV} to the folder that holds {folder}/ (not set)"
    return f"{folder} data set: {ENV}={root} has no {folder}/ folder"


def needs(folder: str) -> pytest.MarkDecorator:
    """Skip unless ``$HILBENCH_REAL_DATA/<folder>`` exists; the reason names the variable."""
    return pytest.mark.skipif(real_data(folder) is None, reason=skip_reason(folder))
