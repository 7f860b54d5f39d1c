"""Units, named once: of each axis kind's quantities, of each control mode's setpoint, and of memory sizes.

Every dataset, summary line, table column and axis label takes its unit from here (SI; docs/units.md).
"""

from __future__ import annotations


def mib(nbytes: float) -> str:
    """Bytes as a whole number of MiB (2**20 bytes), for the memory budget's one-line messages."""
    return f"{nbytes / (1 << 20):.0f} MiB"
