"""Bounds no physical reading or setting can pass: what the device link flags and the simulator refuses.

A winding temperature below absolute zero is impossible; one above ``WINDING_TEMPERATURE_MAX_DEGC`` is past the
melting point of copper (1085 degC), so no working motor reports it. The link records such a reading as NaN with
a counted note in the run file (docs/run-file.md); the simulator's ``[drift]`` table is refused if its laws would
reach one (docs/campaign-analysis.md, "Drift physics").
"""

from __future__ import annotations

import math

ABSOLUTE_ZERO_DEGC = -273.15  # degC
WINDING_TEMPERATURE_MAX_DEGC = 1085.0  # degC, copper melts


def temperature_possible(value: float) -> bool:
    """Whether a winding temperature (degC) is a reading a motor can give: finite, above absolute zero and
    below the melting point of copper."""
    return math.isfinite(value) and ABSOLUTE_ZERO_DEGC < value < WINDING_TEMPERATURE_MAX_DEGC
