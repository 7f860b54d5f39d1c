"""The break-away probe: slow current ramps both ways, and what the recorded run says about the friction.

The probe plays, in current mode, three slow ramps from 0 A to ``+peak``, ``-peak`` and ``+peak`` again, each
followed by a quick return to 0 A and a hold at rest. A ramp that crosses the break-away current sets the motor
sliding; the quick return stops it again within a fraction of a second, so the speed reached stays small however
far the peak lies above the break-away. The second and third ramps each start from the motor's rest after a
slide the other way: the displacement from that turning point to the next break-away is a full reversal of the
presliding loop, twice the presliding distance for a Maxwell-slip (Masing) contact.

:func:`analyse_probe` reads the run file back (measured current and position) and returns the break-away current
of each direction and the presliding distance; it knows nothing of the plan (:mod:`bench.acquisition.planning`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hilbench.bench.acquisition import excitations
from hilbench.bench.acquisition.protocols import ParameterSpec, Protocol, ProtocolError
from hilbench.bench.errors import BenchError

#: Time of the quick return from the peak to 0 A, s: short enough that a slide stops soon after it.
RETURN_TIME = 0.02
#: Signs of the slow ramps, in order; the 2nd and 3rd start after a slide the other way (full reversals).
RAMP_SIGNS = (1, -1, 1)
#: The presliding distance reported is x_p(f) of docs/presliding.md at this fraction f of the sliding level.
PRESLIDING_FRACTION = 0.9
RAMP_DTYPE = np.dtype([("start", "i8"), ("stop", "i8"), ("sign", "i8")])  # sample indices, stop exclusive


class ProbeError(BenchError):
    """The probe's run file does not show what the plan needs (no slide, no rest)."""


@dataclass(frozen=True)
class BreakawayProbe(Protocol):
    """Break-away probe: slow current ramps to +peak, -peak and +peak, each back to 0 A quickly and held."""

    name: ClassVar[str] = "breakaway_probe"
    MODES: ClassVar[tuple[str, ...]] = ("current",)
    SPECS: ClassVar[dict[str, ParameterSpec]] = {
        "peak": ParameterSpec("A", 1e-3, 1e3, "peak current of every ramp"),
        "ramp_time": ParameterSpec("s", 0.1, 60.0, "time of one slow ramp from 0 A to the peak"),
        "hold": ParameterSpec("s", 0.05, 10.0, "rest at 0 A before the first ramp and after every ramp"),
    }
    peak: float = 5.0
    ramp_time: float = 1.5
    hold: float = 0.3
    mode: str = "current"
    sample_rate: int = 10000

    def _knots(self) -> tuple[np.ndarray, np.ndarray]:
        """Times (s) and currents (A) of the piecewise-linear profile."""
        t, i = [0.0, self.hold], [0.0, 0.0]
        for sign in RAMP_SIGNS:
            for dt, level in ((self.ramp_time, sign * self.peak), (RETURN_TIME, 0.0), (self.hold, 0.0)):
                t.append(t[-1] + dt)
                i.append(level)
        return np.array(t), np.array(i)

    @property
    def duration_parameter(self) -> float:
        return float(self._knots()[0][-1])

    def excitation(self, limit: float | None = None) -> excitations.Excitation:
        t_knots, i_knots = self._knots()
        t = np.arange(self.n_samples) / self.sample_rate
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


@dataclass(frozen=True)
class ProbeResult:
    """What one probe run shows. Currents in A (measured), distances in rad at the load."""

    path: str
    peak: float                          # A, the probe's peak current
    breakaway: tuple[float | None, ...]  # A, signed, per ramp (None: that ramp did not slide)
    presliding_distance: float | None    # rad, x_p(0.9) from the full reversals (mean of the two)
    velocity_threshold: float            # rad/s, the speed taken as sliding
    #: the least-squares fit of the slides (see _sliding_fit): positive/negative sliding current (A, signed),
    #: inertia_per_kt (J/Kt, A*s^2/rad), viscous_per_kt (b/Kt, A*s/rad); None when the slides were too short
    sliding: dict[str, float] | None = None

    @property
    def positive(self) -> float | None:
        """Break-away current in the positive direction, A (the full-reversal ramp when it slid)."""
        return _last(self.breakaway, 1)

    @property
    def negative(self) -> float | None:
        """Break-away current in the negative direction, A (negative number)."""
        return _last(self.breakaway, -1)

    @property
    def slid_both_ways(self) -> bool:
        return self.positive is not None and self.negative is not None and self.presliding_distance is not None

    def as_dict(self) -> dict[str, Any]:
        return {"run": self.path, "peak_A": self.peak, "breakaway_positive_A": self.positive,
                "breakaway_negative_A": self.negative, "presliding_distance_rad": self.presliding_distance,
                "velocity_threshold_rad_s": self.velocity_threshold, "sliding_fit": self.sliding}


def _last(values: tuple[float | None, ...], sign: int) -> float | None:
    found = [v for v, s in zip(values, RAMP_SIGNS, strict=True) if v is not None and s == sign]
    return found[-1] if found else None


def smoothed_velocity(position: np.ndarray, fs: float, window: float) -> np.ndarray:
    """Velocity, rad/s: the slope of position over a centred ``window`` (s), i.e. the position difference
    across the window divided by its length (a moving average of the sample-to-sample velocity)."""
    half = max(1, int(round(window * fs / 2)))
    padded = np.concatenate([np.full(half, position[0]), position, np.full(half, position[-1])])
    return (padded[2 * half:] - padded[:-2 * half]) * fs / (2 * half)


def analyse_probe(path: str, window: float = 0.01, velocity_threshold: float | None = None) -> ProbeResult:
    """Break-away currents and presliding distance from a probe run file.

    A ramp slides where the velocity (slope over ``window`` s) first exceeds ``velocity_threshold`` in the
    ramp's direction; the break-away current is the measured current there. The default threshold is 0.05
    rad/s or, on a coarse encoder, five counts per window, whichever is larger. The presliding distance is half
    the displacement from the previous slide's turning point (its extreme position) to where the force has
    changed by twice :data:`PRESLIDING_FRACTION` of the sliding level (Masing's rule: the virgin curve at twice
    the scale), i.e. x_p(0.9) as docs/presliding.md defines it. The sliding level is the fitted sliding current
    (:func:`_sliding_fit`, the mean of both directions); without that fit there is no presliding distance."""
    from hilbench.analysis.runfile import open_run

    with open_run(path) as run:
        if run.protocol_name != BreakawayProbe.name:
            raise ProbeError(f"{path}: a {run.protocol_name or 'unnamed'} run, not a break-away probe")
        fs = run.sample_rate
        current = np.asarray(run.channel("current"), dtype=float)
        position = np.asarray(run.channel("position"), dtype=float)
        ramps = run.protocol_array("ramps")
        peak = float(run.protocol_params["peak"])
        hold = float(run.protocol_params.get("hold", BreakawayProbe.hold))
        counts = float(run.calibration.get("counts_per_rev", 1 << 20))
        ratio = float(run.calibration.get("ratio", 1.0))
    count = 2 * math.pi / (counts * ratio)  # rad at the load per encoder count
    threshold = velocity_threshold or max(0.05, 5 * count / window)
    velocity = smoothed_velocity(position, fs, window)
    acceleration = smoothed_velocity(velocity, fs, window)
    breakaway: list[int | None] = []  # sample of each ramp's break-away
    for j, (start, stop, sign) in enumerate(ramps):
        start, stop = int(start), min(int(stop), position.size)
        if abs(velocity[start]) > threshold:
            raise ProbeError(f"{path}: the motor still moves at {velocity[start]:.3g} rad/s when ramp {j + 1} "
                             f"starts: the slide before did not stop in the {hold:g} s hold at 0 A")
        moving = np.flatnonzero(sign * velocity[start:stop] > threshold)
        breakaway.append(start + int(moving[0]) if moving.size else None)
    sliding = _sliding_fit(ramps, breakaway, current, velocity, acceleration, threshold)
    distances = []
    previous: int | None = None  # turning point (extreme position) of the previous ramp's slide
    for (_start, stop, sign), k in zip(ramps, breakaway, strict=True):
        if k is None:
            previous = None
            continue
        if previous is not None and sliding is not None:
            # Masing: from the turning point (every element slipping the other way) the force changes by
            # 2*V(dx/2); it has changed by 2*f*level where sign*current reaches (2*f - 1)*level, and there dx/2
            # is x_p(f). The level is the fitted sliding current, the mean of both directions.
            level = (sliding["positive"] - sliding["negative"]) / 2
            reached = np.flatnonzero(sign * current[previous:k + 1] >= (2 * PRESLIDING_FRACTION - 1) * level)
            if reached.size:
                distances.append(abs(position[previous + int(reached[0])] - position[previous]) / 2)
        stop = min(int(stop), position.size)
        previous = k + int(np.argmax(sign * position[k:stop]))
    d = float(np.mean(distances)) if distances else None
    return ProbeResult(str(path), peak, tuple(None if k is None else float(current[k]) for k in breakaway), d,
                       threshold, sliding)


#: Fewest sliding samples per direction the fit of the sliding level, inertia and viscous term needs.
MIN_FIT_SAMPLES = 200


def _sliding_fit(ramps: np.ndarray, breakaway: list[int | None], current: np.ndarray, velocity: np.ndarray,
                 acceleration: np.ndarray, threshold: float) -> dict[str, float] | None:
    """Least squares of ``current = (J/Kt)*a + (b/Kt)*v + I_c(direction)`` over the slides while the current
    still ramps (before the quick return): the sliding current of each direction (A), J/Kt (A*s^2/rad) and
    b/Kt (A*s/rad). None when a direction has fewer than :data:`MIN_FIT_SAMPLES` sliding samples."""
    rows: list[np.ndarray] = []
    for (_start, stop, sign), k in zip(ramps, breakaway, strict=True):
        if k is None:
            continue
        seg = np.arange(k, min(int(stop), current.size))
        ramping = np.abs(current[seg]) >= np.abs(current[k])  # the quick return ends the fit's window
        ramping &= np.cumprod(ramping).astype(bool)
        seg = seg[ramping & (sign * velocity[seg] > 2 * threshold)]
        rows.append(np.column_stack([seg, np.full(seg.size, sign)]))
    if not rows:
        return None
    table = np.concatenate(rows)
    idx, signs = table[:, 0], table[:, 1]
    if min(np.sum(signs > 0), np.sum(signs < 0)) < MIN_FIT_SAMPLES:
        return None
    design = np.column_stack([acceleration[idx], velocity[idx], (signs > 0).astype(float), -(signs < 0).astype(float)])
    coef = np.linalg.lstsq(design, current[idx], rcond=None)[0]
    return {"inertia_per_kt": float(coef[0]), "viscous_per_kt": float(coef[1]), "positive": float(coef[2]),
            "negative": float(-coef[3])}
