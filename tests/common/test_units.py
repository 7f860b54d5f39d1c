"""The axis units are one consistent SI set: each derived unit is built from position, torque and the second."""

import pytest

from hilbench.common.units import AXES, AXIS_UNITS, MODE_UNITS, axis_unit, mib, rows_axis


@pytest.mark.parametrize("axis", AXES)
def test_derived_units_follow_from_position_and_torque(axis):
    u = AXIS_UNITS[axis]
    x, f = u["position"], u["torque"]
    assert u["velocity"] == f"{x}/s" and u["acceleration"] == f"{x}/s^2"
    assert u["stiffness"] == f"{f}/{x}" and u["viscous"] == f"{f}*s/{x}"
    assert u["compliance"] == f"{x}/({f})" if "*" in f else u["compliance"] == f"{x}/{f}"
    # J * acceleration is a torque: kg*m^2 * rad/s^2 = N*m (rad dimensionless), kg * m/s^2 = N
    assert {"rotary": ("kg*m^2", "N*m"), "linear": ("kg", "N")}[axis] == (u["inertia"], f)


def test_axis_unit_and_mode_units():
    assert axis_unit("torque", "linear") == "N" and axis_unit("inertia", "rotary") == "kg*m^2"
    with pytest.raises(ValueError, match="axis must be one of rotary, linear"):
        axis_unit("torque", "planar")
    assert MODE_UNITS == {"current": "A", "velocity": AXIS_UNITS["rotary"]["velocity"],
                          "position": AXIS_UNITS["rotary"]["position"]}
    assert mib(3 * (1 << 20)) == "3 MiB"


def test_rows_axis_is_the_first_named_axis_else_rotary():
    """The one reader of a set of rows' axis (the page, the GUI's results, the drift series)."""
    assert rows_axis([]) == "rotary" and rows_axis([{"axis": None}, {"axis": ""}, {}]) == "rotary"
    assert rows_axis([{"axis": None}, {"axis": "linear"}, {"axis": "rotary"}]) == "linear"
    assert rows_axis(iter([{"axis": "rotary"}])) == "rotary"  # any iterable of rows
    with pytest.raises(ValueError, match="axis must be one of rotary, linear, got 'planar'"):
        rows_axis([{"axis": "planar"}])
