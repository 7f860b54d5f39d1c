"""Units, named once: of each axis kind's quantities, of each control mode's setpoint, and of memory sizes.

Every dataset, summary line, table column and axis label takes its unit from here (SI; the glossary in
docs/metrics.md names the quantities).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any


def mib(nbytes: float) -> str:
    """Bytes as a whole number of MiB (2**20 bytes), for the memory budget's one-line messages."""
    return f"{nbytes / (1 << 20):.0f} MiB"


#: The axis kinds a run may have: a rotary axis (angles, torques) or a linear one (lengths, forces).
AXES = ("rotary", "linear")

#: SI unit of every quantity, by axis kind: position, velocity, acceleration, torque (force on a linear axis),
#: inertia (mass), stiffness, viscous coefficient and compliance.
AXIS_UNITS: dict[str, dict[str, str]] = {
    "rotary": {"position": "rad", "velocity": "rad/s", "acceleration": "rad/s^2", "torque": "N*m",
               "inertia": "kg*m^2", "stiffness": "N*m/rad", "viscous": "N*m*s/rad", "compliance": "rad/(N*m)"},
    "linear": {"position": "m", "velocity": "m/s", "acceleration": "m/s^2", "torque": "N",
               "inertia": "kg", "stiffness": "N/m", "viscous": "N*s/m", "compliance": "m/N"},
}

#: SI unit of a setpoint in each control mode (position: the angle at the encoder shaft; a torque mode streams
#: currents: the drive's torque constant turns them into torque)
MODE_UNITS: dict[str, str] = {"current": "A", "velocity": "rad/s", "position": "rad"}


def axis_unit(quantity: str, axis: str) -> str:
    """The SI unit of ``quantity`` (a key of :data:`AXIS_UNITS`) on an ``axis`` (``rotary`` or ``linear``)."""
    if axis not in AXIS_UNITS:
        raise ValueError(f"axis must be one of {', '.join(AXES)}, got {axis!r}")
    return AXIS_UNITS[axis][quantity]


def rows_axis(rows: Iterable[Mapping[str, Any]]) -> str:
    """The axis of a set of results-table rows (a campaign's, a series'): the first row's that names one in its
    ``axis`` column, ``rotary`` when none does (a run file without an axis is rotary). Every reader of the rows'
    axis (the campaign page, the GUI's results, the drift series) takes it from here. An unknown axis is refused
    (ValueError)."""
    axis = next((str(r["axis"]) for r in rows if r.get("axis")), "rotary")
    axis_unit("position", axis)  # refuses an unknown axis
    return axis


#: what drives an axis, by name: a torque on a rotary axis, a force on a linear one ("break-away torque/force")
EFFORT = {"rotary": "torque", "linear": "force"}


def field_unit(metadata: dict[bytes, bytes] | None, axis: str = "rotary") -> str:
    """The unit of a results-table column (its Parquet field ``metadata``) for a row on ``axis``: ``unit_linear`` on
    a linear axis when the column follows the axis (``unit_follows: axis``), else ``unit`` ("" when none)."""
    meta = metadata or {}
    if axis == "linear" and meta.get(b"unit_follows") == b"axis" and b"unit_linear" in meta:
        return meta[b"unit_linear"].decode()
    return meta.get(b"unit", b"").decode()


def schema_units(fields, axis: str = "rotary") -> dict[str, str]:
    """Column name -> unit on ``axis`` for every field of a results table's schema (:func:`field_unit`)."""
    axis_unit("position", axis)  # refuses an unknown axis
    return {f.name: field_unit(f.metadata, axis) for f in fields}
