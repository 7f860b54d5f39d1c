"""Units of imported columns, and the header names a lab's file uses for each run-file channel.

A column's unit comes from ``--unit CHANNEL=UNIT`` or from the header (``Time [ms]``, ``position (deg)``,
``torque_mNm``); :func:`factor_to_si` turns it into the factor that converts to the run-file channel's SI unit
(docs/data.md lists every accepted unit). Encoder counts are not a fixed factor: they need the counts per
revolution, so :data:`COUNTS` is returned as a marker and the importer converts.

The unit set is small and closed (what a friction bench records), so it is a table here rather than a units
library outside the project's chosen dependencies.
"""

from __future__ import annotations

import math
import re

from hilbench.bench.errors import BenchError
from hilbench.common.runfile.schema import CURRENT_CMD, POSITION_CMD, TORQUE_CMD, VELOCITY_CMD

COUNTS = "counts"

#: quantity -> accepted unit -> factor to SI (the run-file unit of the channel)
UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "min": 60.0},
    "angle": {"rad": 1.0, "mrad": 1e-3, "urad": 1e-6, "deg": math.pi / 180.0, "rev": 2.0 * math.pi},
    "length": {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9},
    "angular_velocity": {"rad/s": 1.0, "mrad/s": 1e-3, "deg/s": math.pi / 180.0, "rpm": 2.0 * math.pi / 60.0,
                         "rev/s": 2.0 * math.pi},
    "linear_velocity": {"m/s": 1.0, "mm/s": 1e-3, "um/s": 1e-6, "m/min": 1.0 / 60.0},
    "torque": {"N*m": 1.0, "mN*m": 1e-3, "uN*m": 1e-6, "kN*m": 1e3, "N*mm": 1e-3, "N*cm": 1e-2},
    "force": {"N": 1.0, "mN": 1e-3, "kN": 1e3},
    "current": {"A": 1.0, "mA": 1e-3, "uA": 1e-6},
    "counts": {COUNTS: 1.0},
}

#: run-file channel -> (quantity on a rotary axis, quantity on a linear axis)
QUANTITY: dict[str, tuple[str, str]] = {
    "t": ("time", "time"),
    "position": ("angle", "length"),
    POSITION_CMD: ("angle", "length"),
    "velocity": ("angular_velocity", "linear_velocity"),
    VELOCITY_CMD: ("angular_velocity", "linear_velocity"),
    "torque": ("torque", "force"),
    TORQUE_CMD: ("torque", "force"),
    "current": ("current", "current"),
    CURRENT_CMD: ("current", "current"),
    "counts": ("counts", "counts"),
}

#: header names (lower case, spaces and dashes as ``_``) that mean a run-file channel
ALIASES: dict[str, tuple[str, ...]] = {
    "t": ("t", "time", "timestamp", "time_stamp"),
    "position": ("position", "pos", "theta", "angle", "displacement", "x", "q"),
    POSITION_CMD: ("position_cmd", "position_ref", "pos_ref", "pos_cmd", "theta_ref", "reference"),
    "velocity": ("velocity", "vel", "speed", "omega", "v"),
    VELOCITY_CMD: ("velocity_cmd", "velocity_ref", "vel_ref", "speed_ref", "speed_cmd"),
    "torque": ("torque", "tau", "force", "f", "torque_meas"),
    TORQUE_CMD: ("torque_cmd", "torque_ref", "tau_ref", "force_cmd", "force_ref"),
    "current": ("current", "i", "iq", "i_q", "current_meas"),
    CURRENT_CMD: ("current_cmd", "current_ref", "i_ref", "iq_ref", "i_cmd"),
    "counts": ("counts", "encoder", "encoder_counts", "enc"),
}
_CHANNEL_OF = {alias: channel for channel, names in ALIASES.items() for alias in names}

#: a header's bracketed unit: ``[ms]`` or ``(deg)``; never ``(:,2)``, a MAT matrix column
_BRACKET = re.compile(r"^(?P<name>.*?)\s*[\[(](?P<unit>[^\]),:]*)[\])]\s*$")


class UnitError(BenchError):
    """A unit that is not accepted for a channel, or two different units stated for one column."""


def normalise_unit(unit: str) -> str:
    """Spelling variants to the table's spelling: ``Nm``, ``N.m``, ``N·m`` -> ``N*m``; ``µs`` -> ``us``."""
    u = unit.strip().replace("µ", "u").replace("μ", "u").replace("·", "*").replace(" ", "*")
    u = re.sub(r"(?<=N)\.(?=c?m)", "*", u)
    u = re.sub(r"^([mkuc]?)Nm(m?)$", lambda m: f"{m.group(1)}N*m{m.group(2)}", u)
    aliases = {"sec": "s", "rad/sec": "rad/s", "1/min": "rpm", "rev/min": "rpm", "degree": "deg", "degrees": "deg",
               "count": COUNTS, "cnt": COUNTS}
    return aliases.get(u, u)


def quantity_of(channel: str, axis: str) -> str:
    rotary, linear = QUANTITY[channel]
    return linear if axis == "linear" else rotary


def factor_to_si(channel: str, unit: str, axis: str) -> float | str:
    """Factor from ``unit`` to the run-file unit of ``channel`` on ``axis``, or :data:`COUNTS`.

    Raises:
        UnitError: ``unit`` is not a unit of the channel's quantity (the message lists the accepted ones).
    """
    if channel not in QUANTITY:
        raise UnitError(f"--unit {channel}=...: units apply to {', '.join(QUANTITY)}, not {channel!r}")
    quantity = quantity_of(channel, axis)
    table = dict(UNITS[quantity])
    if channel in ("position", POSITION_CMD) and axis == "rotary":
        table[COUNTS] = 1.0
    u = normalise_unit(unit)
    if u not in table:
        raise UnitError(f"{channel}: unit {unit!r} is not a unit of {quantity.replace('_', ' ')} on a {axis} axis "
                        f"(accepted: {', '.join(table)})")
    return COUNTS if u == COUNTS else table[u]


def split_header(header: str) -> tuple[str, str | None]:
    """``'Time [ms]'`` -> (``'Time'``, ``'ms'``); ``'pos (deg)'`` -> (``'pos'``, ``'deg'``); else (header, None)."""
    m = _BRACKET.match(header)
    if m and m.group("name").strip():
        return m.group("name").strip(), m.group("unit").strip()
    return header.strip(), None


def _key(name: str) -> str:
    return re.sub(r"[\s\-]+", "_", name.strip().lower())


def channel_of(header: str) -> tuple[str | None, str | None]:
    """(channel, unit stated in the header) for a header such as ``Time [s]``, ``theta``, ``torque_mNm``.

    A unit may be bracketed (``pos [deg]``) or a suffix after the last underscore (``time_ms``) when the rest
    is an alias. (None, None) when the header names no channel."""
    name, unit = split_header(header)
    key = _key(name)
    if key in _CHANNEL_OF:
        return _CHANNEL_OF[key], unit
    stem, sep, suffix = name.strip().rpartition("_")
    if sep and unit is None and _key(stem) in _CHANNEL_OF:
        channel = _CHANNEL_OF[_key(stem)]
        known = {u for q in QUANTITY[channel] for u in UNITS[q]}
        if channel.startswith("position"):
            known.add(COUNTS)
        if normalise_unit(suffix) in known:
            return channel, suffix
    return None, unit
