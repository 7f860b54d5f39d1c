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
#: Shapes of the ramps and returns (protocol parameter ``shape``; runs without it: linear)
PROBE_SHAPES = ("linear", "cosine")
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
    presliding_distance: float | None    # rad, x_p(0.9) from the full reversals (a spring load's: of the fitted branch)
    velocity_threshold: float            # rad/s, the speed taken as sliding
    #: the least-squares fit of the slides: positive/negative sliding current (A, signed), inertia_per_kt (J/Kt,
    #: A*s^2/rad), viscous_per_kt (b/Kt, A*s/rad); a spring load's (_spring_probe) also spring_per_kt (k/Kt,
    #: A/rad) and rest_position (rad, where the spring holds the load at 0 A); None when the slides were too short
    sliding: dict[str, float] | None = None
    #: a spring load (analysis._spring_probe): ``breakaway`` holds the friction current at each slide's end
    spring: bool = False
    #: rad, half the shortest full reversal between turning points (a spring load's slides; None otherwise)
    half_travel: float | None = None
    #: rad, the range of position over the probe (what a spring's force k*x is weighed over)
    travel: float = 0.0
    #: the least squares over every moving sample with a spring term (_restoring_fit): what tells a spring load
    #: (_is_spring) from a free one, whose k it shows as noise; None below MIN_FIT_SAMPLES moving samples each way
    restoring: dict[str, float] | None = None

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
    # the ramps' steepest current slope, A/s (a cosine ramp's is pi/2 times the linear one's)
    steepest = peak / ramp_time * (math.pi / 2 if record.protocol_params.get("shape") == "cosine" else 1.0)
    hold = record.protocol_params.get("hold")  # s at 0 A after each ramp, as the run file records it
    hold_text = f"{float(hold):g} s hold" if hold is not None else "hold"
    counts = float(record.calibration.get("counts_per_rev", 1 << 20))
    ratio = float(record.calibration.get("ratio", 1.0))
    count = 2 * math.pi / (counts * ratio)  # rad at the load per encoder count
    threshold = velocity_threshold or max(0.05, 5 * count / window)
    velocity = smoothed_velocity(position, fs, window)
    acceleration = smoothed_velocity(velocity, fs, window)
    spring = _restoring_fit(current, position, velocity, acceleration, threshold, steepest, fs, window)
    if spring is not None and _is_spring(spring, position, peak):
        return _spring_probe(path, peak, ramps, spring, current, position, velocity, acceleration, threshold)
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
                       threshold, sliding, travel=float(np.ptp(position)), restoring=spring)


def _presliding_distances(ramps: np.ndarray, breakaway: list[int | None], friction: np.ndarray,
                          position: np.ndarray, sliding: dict[str, float] | None) -> list[float]:
    """x_p(f) of every full reversal of a free load: from the previous slide's turning point to the sample
    ``breakaway`` of the ramp (or the end of its window), where ``friction`` (A) has changed by 2*f*level from
    minus the level (the slide before saturated; the current at the turning point itself carries the quick
    return's deceleration)."""
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
#: its fitted k is noise: under 2 % of the sliding current over the travel on the simulated DC motor,
#: tests/bench/test_plan.py), a spring load's travel is set by it (k * travel is about twice the peak: the load
#: swings from +peak/k to -peak/k).
SPRING_SHARE = 0.5
#: x_p(f) / d of the rolling-friction virgin curve h * (1 - (d / (d + x))^2): 1/sqrt(1 - f) - 1 (2.162 at 0.9)
XP_OVER_D = 1 / math.sqrt(1 - PRESLIDING_FRACTION) - 1
#: A spring load's slides must reach this many x_p from the previous turning point (half the full reversal, where
#: the rolling curve is at 98 % of its level) for the level to be fitted rather than extrapolated; else the plan
#: needs a larger peak.
MIN_SATURATION_TRAVEL = 3.0
#: The search for the branch's d (rad) spans this range of the probe's travel (log scale: a coarse grid of
#: D_GRID values, then a bounded Brent search around the best)
D_RANGE = (1e-6, 1.0)
D_GRID = 49


def _design(acceleration: np.ndarray, velocity: np.ndarray, position: np.ndarray | None,
            direction: np.ndarray) -> np.ndarray:
    """Columns a, v, [x], [direction > 0], -[direction < 0] of the fits (direction: +1 or -1 per row; no spring
    column when ``position`` is None)."""
    columns = [acceleration, velocity] + ([] if position is None else [position])
    return np.column_stack([*columns, (direction > 0).astype(float), -(direction < 0).astype(float)])


def _solution(design: np.ndarray, target: np.ndarray) -> dict[str, float]:
    """The coefficients of :func:`_design`'s columns by name (spring_per_kt only when it has the x column)."""
    coef = np.linalg.lstsq(design, target, rcond=None)[0]
    names = ("inertia_per_kt", "viscous_per_kt", "spring_per_kt")[:design.shape[1] - 2]
    return {**{n: float(c) for n, c in zip(names, coef, strict=False)},
            "positive": float(coef[-2]), "negative": float(-coef[-1])}


def _sliding_fit(ramps: np.ndarray, breakaway: list[int | None], current: np.ndarray, position: np.ndarray,
                 velocity: np.ndarray, acceleration: np.ndarray, threshold: float) -> dict[str, float] | None:
    """Least squares of ``current = (J/Kt)*a + (b/Kt)*v + I_c(direction)`` over the slides of a free load while
    the current still ramps (before the quick return): the sliding current of each direction (A), J/Kt
    (A*s^2/rad) and b/Kt (A*s/rad). No spring term: a free load has none to fit (its k would be noise traded
    against the two intercepts; :func:`_restoring_fit` shows it). None when a direction has fewer than
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
    return _solution(_design(acceleration[idx], velocity[idx], None, signs), current[idx])


def _restoring_fit(current: np.ndarray, position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray,
                   threshold: float, ramp_rate: float, fs: float, window: float) -> dict[str, float] | None:
    """Least squares of ``current = (J/Kt)*a + (b/Kt)*v + (k/Kt)*x + I_c(direction)`` over every moving sample of
    the run (speed above twice ``threshold``), both ways and whatever the ramp, except where the current changes
    faster than 1.5 x the slow ramps' steepest slope ``ramp_rate`` (A/s) and two smoothing windows either side (a
    quick return: the smoothed acceleration lags it). A spring load moves through the whole probe, returns and
    holds included; its return is what separates the spring from the friction (same position, the other
    direction). None below :data:`MIN_FIT_SAMPLES` each way."""
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


def _branch_shape(distance: np.ndarray, amplitude: np.ndarray, d: float) -> np.ndarray:
    """g(s) of a Masing branch of the rolling-friction virgin curve phi(x) = h (1 - (d / (d + x))^2) (d in rad)
    in a loop of half-travel ``amplitude`` A (rad): the friction ``distance`` s (rad) from the turning point is
    ``h * g(s)``, the turning point's -phi(A) plus twice the virgin curve at half the distance,
    g = 1 + (d / (d + A))^2 - 2 (d / (d + s/2))^2. It rises from -phi(A)/h to phi(A)/h at s = 2A (short of 1: a
    loop of finite travel never saturates every element)."""
    return 1 + (d / (d + amplitude)) ** 2 - 2 * (d / (d + distance / 2)) ** 2


def _branch_fit(rows: np.ndarray, current: np.ndarray, position: np.ndarray, velocity: np.ndarray,
                acceleration: np.ndarray) -> tuple[float, np.ndarray]:
    """The least squares ``I = (J/Kt) a + (b/Kt) v + (k/Kt) (x - mean x) + c' + I_s dir g(s)`` over ``rows``
    (sample, direction, previous turning point, own turning point), with d of :func:`_branch_shape` the one of
    least residual (a log grid over :data:`D_RANGE` of the travel, then Brent). Returns d (rad) and the
    coefficients (J/Kt, b/Kt, k/Kt, c', I_s)."""
    from scipy.optimize import minimize_scalar

    idx, signs, turns, ends = rows.T
    distance = np.abs(position[idx] - position[turns])
    amplitude = np.abs(position[ends] - position[turns]) / 2
    # x about its mean over the fitted samples: a shift of the encoder's zero moves c' only, to rounding
    columns = [acceleration[idx], velocity[idx], position[idx] - float(np.mean(position[idx])), np.ones(idx.size)]
    target = current[idx]

    # only the g column changes with d: the other columns are projected out once (Frisch-Waugh), so that each d
    # costs a pass over the samples, and the residual is taken from what they leave (no cancellation against the
    # spring's large share of the current: the minimum is flat and must be found to 1e-6)
    basis = np.linalg.qr(np.column_stack(columns))[0]
    left = target - basis @ (basis.T @ target)

    def residual(log_d: float) -> float:
        """The least squares' residual sum at d = exp(log_d)."""
        shape = signs * _branch_shape(distance, amplitude, math.exp(log_d))
        shape = shape - basis @ (basis.T @ shape)
        return float(left @ left - (shape @ left) ** 2 / (shape @ shape))

    def solve(log_d: float) -> np.ndarray:
        design = np.column_stack([*columns, signs * _branch_shape(distance, amplitude, math.exp(log_d))])
        return np.linalg.lstsq(design, target, rcond=None)[0]

    scale = float(np.max(amplitude))
    grid = np.linspace(math.log(D_RANGE[0] * scale), math.log(D_RANGE[1] * scale), D_GRID)
    best = int(np.argmin([residual(g) for g in grid]))
    lo, hi = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
    found = minimize_scalar(residual, bounds=(lo, hi), method="bounded", options={"xatol": 1e-9})
    return math.exp(float(found.x)), solve(float(found.x))


def _spring_probe(path, peak: float, ramps: np.ndarray, fit: dict[str, float], current: np.ndarray,
                  position: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray,
                  threshold: float) -> ProbeResult:
    """A probe of a load on a spring. A spring load moves from the first ramp on (its travel is set by the spring;
    there is no break-away in the free load's sense): each ramp's slide runs from the previous slide's turning point
    (the extreme of position in a ramp's window, where the current turns back) to its own.

    The friction current is what the current leaves after the spring, the inertia and the viscous term,
    ``I - (k/Kt)*x - (J/Kt)*a - (b/Kt)*v - c`` (A), where ``c = -(k/Kt)*x_r`` is the spring's pull at encoder
    zero (its rest x_r need not be there). It is a small difference (the spring carries a hundred times the
    friction at the end of a slide of the paper's system at 270 A), so k must be right to well under 1 %. The
    least squares over every moving sample (:func:`_restoring_fit`) is not: a Maxwell-slip friction's presliding
    stiffness looks like a spring to it; and a constant sliding level fitted over the slides' far parts trades k
    against the level there (x has the sign of the direction at the ends of the travel), reading the level low
    and x_p, which Masing's rule takes from the level, lower still. So the friction of the full reversals (ramps
    2 and 3, every moving sample) is modelled as the Masing branch of the rolling-friction virgin curve,
    ``I_s * dir * g(s)``
    (:func:`_branch_shape`, s the distance from the previous turning point), and fitted with the spring, the
    inertia, the viscous term and the offset: ``I = (J/Kt) a + (b/Kt) v + (k/Kt) x + c + I_s dir g(s)``, with the
    curve's d the one of least residual (:func:`_branch_fit`). The presliding distance is that curve's x_p(0.9),
    :data:`XP_OVER_D` x d. ``sliding`` is that fit (``positive = I_s``, ``negative = -I_s``: on a spring an
    asymmetry of the friction is one with the rest offset, which takes it); None when the slides did not reach
    :data:`MIN_SATURATION_TRAVEL` x_p from their turning points (or fewer than :data:`MIN_FIT_SAMPLES` samples
    each way): the plan then needs a larger peak. Each ramp's "break-away" entry is the friction current at its
    slide's turning point."""
    turning: list[int | None] = []
    for start, stop, sign in ramps:
        start, stop = int(start), min(int(stop), position.size)
        moved = np.any(sign * velocity[start:stop] > threshold)
        turning.append(start + int(np.argmax(sign * position[start:stop])) if moved else None)
    reversals = [abs(position[b] - position[a]) / 2 for a, b in zip(turning[:-1], turning[1:], strict=True)
                 if a is not None and b is not None]
    half_travel = float(min(reversals)) if reversals else None  # rad, half the shortest full reversal
    rows = []
    for (_start, _stop, sign), previous, k in zip(ramps[1:], turning[:-1], turning[1:], strict=True):
        if previous is None or k is None:
            continue
        seg = np.arange(previous, k + 1)
        seg = seg[sign * velocity[seg] > 2 * threshold]
        rows.append(np.column_stack([seg, np.full(seg.size, sign), np.full(seg.size, previous),
                                     np.full(seg.size, k)]))
    table = np.concatenate(rows) if rows else np.empty((0, 4), dtype=int)
    sliding: dict[str, float] | None = None
    d: float | None = None
    # until the branch fit stands, the friction is what the restoring fit leaves (its intercepts are c +- I_s)
    model = (fit["spring_per_kt"], fit["inertia_per_kt"], fit["viscous_per_kt"],
             (fit["positive"] + fit["negative"]) / 2)
    if min(np.sum(table[:, 1] > 0), np.sum(table[:, 1] < 0)) >= MIN_FIT_SAMPLES:
        shape_d, coef = _branch_fit(table, current, position, velocity, acceleration)
        inertia, viscous, spring, centred, level = map(float, coef)
        offset = centred - spring * float(np.mean(position[table[:, 0]]))  # c at x = 0
        x_p = XP_OVER_D * shape_d
        if level > 0 and spring > 0 and (half_travel or 0.0) >= MIN_SATURATION_TRAVEL * x_p:
            model, d = (spring, inertia, viscous, offset), x_p
            sliding = {"inertia_per_kt": inertia, "viscous_per_kt": viscous, "spring_per_kt": spring,
                       "positive": level, "negative": -level, "rest_position": -offset / spring}
    spring, inertia, viscous, offset = model
    friction = current - spring * position - inertia * acceleration - viscous * velocity - offset
    ends = tuple(None if k is None else float(friction[k]) for k in turning)
    return ProbeResult(str(path), peak, ends, d, threshold, sliding, spring=True, half_travel=half_travel,
                       travel=float(np.ptp(position)), restoring=fit)
