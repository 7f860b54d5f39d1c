"""The break-away probe: slow current ramps both ways, and what the recorded run says about the friction.

The probe plays, in current mode, three slow ramps from 0 A to ``+peak``, ``-peak`` and ``+peak`` again, each
followed by a quick return to 0 A and a hold at rest. A ramp that crosses the break-away current sets the motor
sliding; the quick return stops it again within a fraction of a second, so the speed reached stays small however
far the peak lies above the break-away (a load on a spring is probed with slow cosine ramps and returns instead,
``shape = "cosine"``: see RETURN_TIME). The second and third ramps each start from the motor's rest after a
slide the other way: the displacement from that turning point to the next break-away is a full reversal of the
presliding loop, twice the presliding distance for a Maxwell-slip (Masing) contact.

:func:`analyse_probe` (:mod:`hilbench.analysis.breakaway.probe`, the registry's ``breakaway`` analysis) reads the
run file back (measured current and position) and returns the break-away current of each direction and the
presliding distance; it knows nothing of the plan (:mod:`bench.acquisition.planning`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hilbench.analysis.breakaway.probe import (  # noqa: F401 (re-exported: the probe's analysis)
    PROBE_PROTOCOL,
    PROBE_SHAPES,
    RAMP_SIGNS,
    SPRING_SHARE,
    ProbeError,
    ProbeResult,
    analyse_probe,
    smoothed_velocity,
)
from hilbench.bench.acquisition import excitations
from hilbench.bench.acquisition.protocols import PROTOCOLS, ParameterSpec, Protocol, ProtocolError

#: Time of the quick return from the peak to 0 A, s: short enough that a slide stops soon after it. A load on a
#: spring is probed with a slow return instead (``return_time = ramp_time``, bench.acquisition.planning) and cosine
#: ramps: the spring bounds its travel, and a quick release, or a ramp's corner, would set it swinging at sqrt(k/J)
#: with little friction damping (a corner's swing, (change of the ramp rate)/(k*omega_n), reverses the load's motion
#: when it exceeds its speed along the ramp: inner presliding loops the friction fit does not model).
RETURN_TIME = 0.02
RAMP_DTYPE = np.dtype([("start", "i8"), ("stop", "i8"), ("sign", "i8")])  # sample indices, stop exclusive


@dataclass(frozen=True)
class BreakawayProbe(Protocol):
    """Break-away probe: slow current ramps to +peak, -peak and +peak, each back to 0 A (quickly by default) and
    held."""

    name: ClassVar[str] = PROBE_PROTOCOL
    MODES: ClassVar[tuple[str, ...]] = ("current",)
    SPECS: ClassVar[dict[str, ParameterSpec]] = {
        "peak": ParameterSpec("A", 1e-3, 1e3, "peak current of every ramp"),
        "ramp_time": ParameterSpec("s", 0.1, 60.0, "time of one slow ramp from 0 A to the peak"),
        "hold": ParameterSpec("s", 0.05, 10.0, "rest at 0 A before the first ramp and after every ramp"),
        "return_time": ParameterSpec("s", 0.001, 60.0, "time of the return from the peak to 0 A"),
        "shape": ParameterSpec("", None, None, "ramps and returns: linear, or cosine (half a cosine period each: no "
                               "corner to set a spring load swinging)", kind="choice", choices=PROBE_SHAPES),
    }
    peak: float = 5.0
    ramp_time: float = 1.5
    hold: float = 0.3
    return_time: float = RETURN_TIME
    shape: str = "linear"
    mode: str = "current"
    sample_rate: int = 10000

    def _knots(self) -> tuple[np.ndarray, np.ndarray]:
        """Times (s) and currents (A) of the piecewise-linear profile."""
        t, i = [0.0, self.hold], [0.0, 0.0]
        for sign in RAMP_SIGNS:
            for dt, level in ((self.ramp_time, sign * self.peak), (self.return_time, 0.0), (self.hold, 0.0)):
                t.append(t[-1] + dt)
                i.append(level)
        return np.array(t), np.array(i)

    @property
    def duration_parameter(self) -> float:
        return float(self._knots()[0][-1])

    def excitation(self, limit: float | None = None) -> excitations.Excitation:
        t_knots, i_knots = self._knots()
        t = np.arange(self.n_samples) / self.sample_rate
        if self.shape == "cosine":  # each segment as half a cosine period: the current's slope is 0 at every knot
            j = np.clip(np.searchsorted(t_knots, t, side="right") - 1, 0, t_knots.size - 2)
            span = np.diff(t_knots)[j]
            frac = np.clip(np.divide(t - t_knots[j], span, out=np.ones_like(t), where=span > 0), 0.0, 1.0)
            u = i_knots[j] + (i_knots[j + 1] - i_knots[j]) * (1 - np.cos(np.pi * frac)) / 2
        else:
            u = np.interp(t, t_knots, i_knots)
        if limit is not None and self.peak > limit:
            raise ProtocolError(f"probe peak {self.peak:g} A is above the current limit {limit:g} A")
        return excitations.Excitation(name=self.name, mode="current", fs=float(self.sample_rate), u=u,
                                      params=self.parameters())

    def protocol_arrays(self) -> dict[str, np.ndarray]:
        """``ramps``: the sample range and sign of every slow ramp (what :func:`analyse_probe` reads)."""
        t_knots = self._knots()[0]
        rows = []
        for j, sign in enumerate(RAMP_SIGNS):
            start = 1 + 3 * j  # knot where ramp j starts; its hold ends at knot start + 3
            rows.append((int(round(t_knots[start] * self.sample_rate)),
                         min(self.n_samples, int(round(t_knots[start + 3] * self.sample_rate))), sign))
        return {"ramps": np.array(rows, dtype=RAMP_DTYPE)}


# a campaign may play probes ([[run]] protocol = "breakaway_probe": the break-away followed over a campaign, each
# probe a row of the registry's ``breakaway`` step); bench/__init__.py imports this module, as compensation.py
PROTOCOLS[BreakawayProbe.name] = BreakawayProbe
