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
from dataclasses import dataclass, replace
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
    #: inertia_per_kt (J/Kt, A*s^2/rad), viscous_per_kt (b/Kt, A*s/rad), spring_per_kt (k/Kt, A/rad); None
    #: when the slides were too short
    sliding: dict[str, float] | None = None
    #: a spring load (analysis._spring_probe): ``breakaway`` holds the friction current at each slide's end
    spring: bool = False
    #: rad, half the shortest full reversal between turning points (a spring load's slides; None otherwise)
    half_travel: float | None = None
    #: rad, the range of position over the probe (what a spring's force k*x is weighed over)
    travel: float = 0.0
    #: a spring load: the least squares over every moving sample (_restoring_fit; k and J within a few %)
    restoring: dict[str, float] | None = None
    ramp_time: float = 1.5    # s, as played
    return_time: float = 0.02  # s, as played (a quick return unless a spring load was probed slowly)

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
                "velocity_threshold_rad_s": self.velocity_threshold, "sliding_fit": self.sliding,
                "spring_load": self.spring, "half_travel_rad": self.half_travel, "travel_rad": self.travel,
                "restoring_fit": self.restoring}


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
    ramp_time = float(record.protocol_params.get("ramp_time", 1.5))
    return_time = float(record.protocol_params.get("return_time", 0.02))
    hold = record.protocol_params.get("hold")  # s at 0 A after each ramp, as the run file records it
    hold_text = f"{float(hold):g} s hold" if hold is not None else "hold"
    counts = float(record.calibration.get("counts_per_rev", 1 << 20))
    ratio = float(record.calibration.get("ratio", 1.0))
    count = 2 * math.pi / (counts * ratio)  # rad at the load per encoder count
    threshold = velocity_threshold or max(0.05, 5 * count / window)
    velocity = smoothed_velocity(position, fs, window)
    acceleration = smoothed_velocity(velocity, fs, window)
    spring = _restoring_fit(current, position, velocity, acceleration, threshold, peak / ramp_time, fs, window)
    if spring is not None and _is_spring(spring, position, peak):
        found = _spring_probe(path, peak, ramps, spring, current, position, velocity, acceleration, threshold)
        return replace(found, ramp_time=ramp_time, return_time=return_time)
    breakaway: list[int | None] = []  # sample of each ramp's break-away
    for j, (start, stop, sign) in enumerate(ramps):
        start, stop = int(start), min(int(stop), position.size)
        if abs(velocity[start]) > threshold:
            raise ProbeError(f"{path}: the motor still moves at {velocity[start]:.3g} rad/s when ramp {j + 1} "
                             f"starts: the slide before did not stop in the {hold_text} at 0 A")
        moving = np.flatnonzero(sign * velocity[start:stop] > threshold)
        breakaway.append(start + int(moving[0]) if moving.size else None)
    sliding = _sliding_fit(ramps, breakaway, current, position, velocity, acceleration, threshold)
    distances = _presliding_distances(ramps, breakaway, current, position, sliding)
    d = float(np.mean(distances)) if distances else None
    return ProbeResult(str(path), peak, tuple(None if k is None else float(current[k]) for k in breakaway), d,
                       threshold, sliding, travel=float(np.ptp(position)), ramp_time=ramp_time,
                       return_time=return_time)


def _presliding_distances(ramps: np.ndarray, breakaway: list[int | None], friction: np.ndarray,
                          position: np.ndarray, sliding: dict[str, float] | None) -> list[float]:
    """x_p(f) of every full reversal: from the previous slide's turning point to the sample ``breakaway`` of the
    ramp (or the end of its window), where ``friction`` (A) has changed by 2*f*level."""
    distances = []
    previous: int | None = None  # turning point (extreme position) of the previous ramp's slide
    for (_start, stop, sign), k in zip(ramps, breakaway, strict=True):
        if k is None:
            previous = None
            continue
        if previous is not None and sliding is not None:
            # Masing: from the turning point (every element slipping the other way) the force changes by
            # 2*V(dx/2); it has changed by 2*f*level where sign*friction reaches (2*f - 1)*level, and there dx/2
            # is x_p(f). The level is the fitted sliding current, the mean of both directions.
            level = (sliding["positive"] - sliding["negative"]) / 2
            reached = np.flatnonzero(sign * friction[previous:k + 1] >= (2 * PRESLIDING_FRACTION - 1) * level)
            if reached.size:
                distances.append(abs(position[previous + int(reached[0])] - position[previous]) / 2)
        stop = min(int(stop), position.size)
        previous = k + int(np.argmax(sign * position[k:stop]))
    return distances


#: Fewest sliding samples per direction the fit of the sliding level, inertia and viscous term needs.
MIN_FIT_SAMPLES = 200
#: A restoring force is a spring when the fitted spring carries at least this share of the probe's peak current
#: over the probe's travel: friction never does (a free load's presliding stiffness acts over micro-radians, and
#: its fitted k is noise, about 1e-3 of the peak over the travel on the simulated DC motor), a spring load's
#: travel is set by it (k * travel is about twice the peak: the load swings from +peak/k to -peak/k).
SPRING_SHARE = 0.5
#: Half the distance from a turning point, in presliding distances x_p(0.9), beyond which a spring load's slide is
#: taken as saturated (friction at its sliding level): on the rolling-friction virgin curve the friction at
#: 5 x_p is 99.3 % of the level (h * (1 - (d / (d + 5 * 2.16 d))^2)). With 3 x_p the paper's system read a level
#: 13 % low (1.42 against 1.64 N*m) and k 0.08 % high; with 5, 3.7 % low and 0.01 %.
SATURATION_TRAVEL = 5.0
#: ... at least this (the friction at 3 x_p of the rolling curve: 98 % of its level), else the slides are too
#: short; shorter than 5 x_p when the saturated part would be shorter than SEGMENT_TRAVEL x_p (at the cap of the
#: paper's system at 1 kHz a 0.3 rad part read k 0.17 % high and the level 30 % low; 4.65 x_p now)
MIN_SATURATION_TRAVEL = 3.0
SEGMENT_TRAVEL = 1.0


def _design(acceleration: np.ndarray, velocity: np.ndarray, position: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Columns a, v, x, [direction > 0], -[direction < 0] of the fits (direction: +1 or -1 per row)."""
    return np.column_stack([acceleration, velocity, position, (direction > 0).astype(float),
                            -(direction < 0).astype(float)])


def _solution(design: np.ndarray, target: np.ndarray) -> dict[str, float]:
    coef = np.linalg.lstsq(design, target, rcond=None)[0]
    return {"inertia_per_kt": float(coef[0]), "viscous_per_kt": float(coef[1]), "spring_per_kt": float(coef[2]),
            "positive": float(coef[3]), "negative": float(-coef[4])}


def _sliding_fit(ramps: np.ndarray, breakaway: list[int | None], current: np.ndarray, position: np.ndarray,
                 velocity: np.ndarray, acceleration: np.ndarray, threshold: float) -> dict[str, float] | None:
    """Least squares of ``current = (J/Kt)*a + (b/Kt)*v + (k/Kt)*x + I_c(direction)`` over the slides while the
    current still ramps (before the quick return): the sliding current of each direction (A), J/Kt (A*s^2/rad),
    b/Kt (A*s/rad) and k/Kt (A/rad; about 0 on a load without a spring). None when a direction has fewer than
    :data:`MIN_FIT_SAMPLES` sliding samples."""
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
    # position about its mean over the slides: the sliding currents are those at the slides' mean position, not
    # shifted by k times wherever the probe started (k is noise on a free load: 1e-3 of I_s over the travel)
    centred = position[idx] - float(np.mean(position[idx]))
    return _solution(_design(acceleration[idx], velocity[idx], centred, signs), current[idx])


def _restoring_fit(current: np.ndarray, position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray,
                   threshold: float, ramp_rate: float, fs: float, window: float) -> dict[str, float] | None:
    """The fit of :func:`_sliding_fit` over every moving sample of the run (speed above twice ``threshold``),
    both ways and whatever the ramp, except where the current changes faster than 1.5 x the slow ramps'
    ``ramp_rate`` (A/s) and two smoothing windows either side (a quick return: the smoothed acceleration lags
    it). A spring load moves through the whole probe, returns and holds included; its return is what separates
    the spring from the friction (same position, the other direction). None below :data:`MIN_FIT_SAMPLES` each
    way."""
    slope = smoothed_velocity(current, fs, window)  # A/s
    fast = (np.abs(slope) > 1.5 * ramp_rate).astype(float)
    half = max(1, int(round(2 * window * fs)))
    fast = np.convolve(fast, np.ones(2 * half + 1), "same") > 0
    idx = np.flatnonzero((np.abs(velocity) > 2 * threshold) & ~fast)
    direction = np.sign(velocity[idx])
    if min(np.sum(direction > 0), np.sum(direction < 0)) < MIN_FIT_SAMPLES:
        return None
    return _solution(_design(acceleration[idx], velocity[idx], position[idx], direction), current[idx])


def _is_spring(fit: dict[str, float], position: np.ndarray, peak: float) -> bool:
    """Whether the restoring fit's spring matters (:data:`SPRING_SHARE`)."""
    return fit["spring_per_kt"] * float(np.ptp(position)) >= SPRING_SHARE * peak


def _spring_probe(path, peak: float, ramps: np.ndarray, fit: dict[str, float], current: np.ndarray,
                  position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray,
                  threshold: float) -> ProbeResult:
    """A probe of a load on a spring. A spring load moves from the first ramp on (its travel is set by the spring;
    there is no break-away in the free load's sense): each ramp's slide runs from the previous slide's turning point
    (the extreme of position in a ramp's window, where the current turns back) to its own.

    The friction current is what the current leaves after the spring and the inertia, ``I - (k/Kt)*x - (J/Kt)*a``
    (A). It is a small difference (the spring carries about a hundred times the friction at the end of a slide of
    the paper's system), so k must be right to well under 1 %, and the least squares over every moving sample
    (:func:`_restoring_fit`) is not: a Maxwell-slip friction's presliding stiffness looks like a spring to it
    (about +0.2 % on the paper's system). So the fit is repeated over the saturated part of the full reversals
    only: the samples of ramps 2 and 3 farther from the previous turning point than 2 x :data:`SATURATION_TRAVEL`
    presliding distances, where the friction is its sliding level (within 1 % on a rolling-friction curve), so
    that ``I = (J/Kt) a + (b/Kt) v + (k/Kt) x + I_s(direction)`` holds with a constant ``I_s``. x_p comes from
    the friction current by Masing's rule (:func:`_presliding_distances`, from turning point to turning point);
    the selection and the fit are iterated until x_p settles (three rounds). ``sliding`` is that fit, None when
    the slides were too short to saturate (fewer than :data:`MIN_FIT_SAMPLES` samples each way): the plan then
    needs a larger peak. Each ramp's "break-away" entry is the friction current at its slide's turning point."""
    turning: list[int | None] = []
    for start, stop, sign in ramps:
        start, stop = int(start), min(int(stop), position.size)
        moved = np.any(sign * velocity[start:stop] > threshold)
        turning.append(start + int(np.argmax(sign * position[start:stop])) if moved else None)
    reversals = [abs(position[b] - position[a]) / 2 for a, b in zip(turning[:-1], turning[1:], strict=True)
                 if a is not None and b is not None]
    half_travel = float(min(reversals)) if reversals else None  # rad, half the shortest full reversal

    def ends_of(friction: np.ndarray) -> dict[str, float]:
        last = {s: float(friction[k]) for k, s in zip(turning, RAMP_SIGNS, strict=True) if k is not None}
        return {"positive": last.get(1, math.nan), "negative": last.get(-1, math.nan)}

    current_fit: dict[str, float] = {**fit, **ends_of(current - fit["spring_per_kt"] * position
                                                      - fit["inertia_per_kt"] * acceleration)}
    sliding: dict[str, float] | None = None
    d: float | None = None
    for _ in range(3):
        friction = current - current_fit["spring_per_kt"] * position - current_fit["inertia_per_kt"] * acceleration
        usable = current_fit["positive"] > 0 > current_fit["negative"]
        distances = _presliding_distances(ramps, turning, friction, position, current_fit if usable else None)
        if not distances:
            break
        d = float(np.mean(distances))
        if not d > 0:  # the friction changed by 1.8 x its level at once: no presliding seen, no saturation to fit
            sliding = None
            break
        # the saturated part starts at 2*saturation*x_p from the turning point and must stay SEGMENT_TRAVEL x_p
        # long: k is fitted from the slope within these parts (across them it is one with the levels)
        saturation = min(SATURATION_TRAVEL, (2 * (half_travel or 0.0) - SEGMENT_TRAVEL * d) / (2 * d))
        if saturation < MIN_SATURATION_TRAVEL:
            sliding = None
            break
        rows = []
        for (_start, _stop, sign), previous, k in zip(ramps[1:], turning[:-1], turning[1:], strict=True):
            if previous is None or k is None:
                continue
            seg = np.arange(previous, k + 1)
            far = np.abs(position[seg] - position[previous]) >= 2 * saturation * d
            seg = seg[far & (sign * velocity[seg] > 2 * threshold)]
            rows.append(np.column_stack([seg, np.full(seg.size, sign)]))
        table = np.concatenate(rows) if rows else np.empty((0, 2), dtype=int)
        idx, signs = table[:, 0], table[:, 1]
        if min(np.sum(signs > 0), np.sum(signs < 0)) < MIN_FIT_SAMPLES:
            sliding = None
            break
        sliding = current_fit = _solution(_design(acceleration[idx], velocity[idx], position[idx], signs),
                                          current[idx])
    friction = current - current_fit["spring_per_kt"] * position - current_fit["inertia_per_kt"] * acceleration
    ends = tuple(None if k is None else float(friction[k]) for k in turning)
    if sliding is None:
        d = None
    return ProbeResult(str(path), peak, ends, d, threshold, sliding, spring=True, half_travel=half_travel,
                       travel=float(np.ptp(position)), restoring=fit)
