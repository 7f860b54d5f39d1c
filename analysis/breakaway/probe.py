"""What a break-away probe run says about the friction: the break-away current of each direction, the presliding
distance and a least-squares fit of the slides (the probe itself, the protocol played, is
``hilbench.bench.acquisition.breakaway_probe``).

The probe plays, in current mode, three slow ramps from 0 A to ``+peak``, ``-peak`` and ``+peak`` again, each
followed by a quick return to 0 A and a hold at rest; its run file records each ramp's sample range and sign
(protocol array ``ramps``). The second and third ramps each start from the motor's rest after a slide the other
way: the displacement from that turning point to the next break-away is a full reversal of the presliding loop,
twice the presliding distance for a Maxwell-slip (Masing) contact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hilbench.analysis.errors import AnalysisError

#: the protocol name of a probe run
PROBE_PROTOCOL = "breakaway_probe"
#: Signs of the slow ramps, in order; the 2nd and 3rd start after a slide the other way (full reversals).
RAMP_SIGNS = (1, -1, 1)
#: The presliding distance reported is x_p(f) of docs/presliding.md at this fraction f of the sliding level.
PRESLIDING_FRACTION = 0.9


class ProbeError(AnalysisError):
    """The probe's run file does not show what the plan needs (no slide, no rest)."""


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


def analyse_probe(path: str | Path, window: float = 0.01, velocity_threshold: float | None = None) -> ProbeResult:
    """Break-away currents and presliding distance from a probe run file.

    A ramp slides where the velocity (slope over ``window`` s) first exceeds ``velocity_threshold`` in the
    ramp's direction; the break-away current is the measured current there. The default threshold is 0.05
    rad/s or, on a coarse encoder, five counts per window, whichever is larger. The presliding distance is half
    the displacement from the previous slide's turning point (its extreme position) to where the force has
    changed by twice :data:`PRESLIDING_FRACTION` of the sliding level (Masing's rule: the virgin curve at twice
    the scale), i.e. x_p(0.9) as docs/presliding.md defines it. The sliding level is the fitted sliding current
    (:func:`_sliding_fit`, the mean of both directions); without that fit there is no presliding distance."""
    from hilbench.analysis.record import load_record

    record = load_record(path, need_torque=False, channels=("current",), protocol_arrays=("ramps",))
    return probe_of_record(record, window, velocity_threshold)


def probe_of_record(record, window: float = 0.01, velocity_threshold: float | None = None) -> ProbeResult:
    """:func:`analyse_probe` of a :class:`hilbench.analysis.record.Record` (position, the ``current`` channel,
    the protocol array ``ramps``)."""
    path = record.path
    if record.protocol_name != PROBE_PROTOCOL:
        raise ProbeError(f"{path}: a {record.protocol_name or 'unnamed'} run, not a break-away probe")
    if "current" not in record.channels or "ramps" not in record.protocol_arrays:
        raise ProbeError(f"{path}: no measured current channel or no ramps: not a probe run file")
    fs = record.sample_rate
    current = np.asarray(record.channels["current"], dtype=float)
    position = np.asarray(record.position, dtype=float)
    ramps = record.protocol_arrays["ramps"]
    peak = float(record.protocol_params["peak"])
    hold = record.protocol_params.get("hold")  # s at 0 A after each ramp, as the run file records it
    hold_text = f"{float(hold):g} s hold" if hold is not None else "hold"
    counts = float(record.calibration.get("counts_per_rev", 1 << 20))
    ratio = float(record.calibration.get("ratio", 1.0))
    count = 2 * math.pi / (counts * ratio)  # rad at the load per encoder count
    threshold = velocity_threshold or max(0.05, 5 * count / window)
    velocity = smoothed_velocity(position, fs, window)
    acceleration = smoothed_velocity(velocity, fs, window)
    breakaway: list[int | None] = []  # sample of each ramp's break-away
    for j, (start, stop, sign) in enumerate(ramps):
        start, stop = int(start), min(int(stop), position.size)
        if abs(velocity[start]) > threshold:
            raise ProbeError(f"{path}: the motor still moves at {velocity[start]:.3g} rad/s when ramp {j + 1} "
                             f"starts: the slide before did not stop in the {hold_text} at 0 A")
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
