"""Reference trajectories for position tracking: plain functions returning position, velocity, acceleration.

Every reference starts and ends at rest at 0 rad (the encoder zero at CONFIG) and is sampled at ``fs`` Hz,
``t_k = k/fs``. Velocity and acceleration are the analytic derivatives (not differences), so a feed-forward
J*q''_ref uses the exact acceleration of the path.

- :func:`slow_sine`: for each amplitude A (rad), ``cycles`` periods of ``q = A*(1 - cos(2*pi*f*t))``
  (peak-to-peak 2A, reversals at every peak and trough), separated by ``rest`` s at 0. Amplitudes from a
  fraction of the presliding distance to many times it span presliding to gross sliding.
- :func:`triangle`: a triangle wave 0 -> +A -> -A -> ... -> 0 at constant speed 4*A*f, each corner replaced by
  a parabolic blend of ``corner`` s (constant acceleration), so J*q'' stays finite.
- :func:`point_to_point`: moves to each target (rad) along a minimum-jerk quintic of ``move_time`` s, each
  followed by ``rest`` s at rest (the settling window).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from hilbench.analysis.errors import AnalysisError

KINDS = ("sine", "triangle", "point_to_point")
#: The longest reference, samples (1 h at 20 kHz), checked before anything is allocated.
MAX_SAMPLES = 72_000_000


@dataclass
class Reference:
    """A sampled reference. ``position`` rad, ``velocity`` rad/s, ``acceleration`` rad/s^2, all shape (n,).

    ``moves`` (point-to-point only) is an (m, 2) int array of [start, stop) sample ranges of each move; the
    rest after move i runs from ``moves[i, 1]`` to the next move's start (or the end). ``sections`` (sine
    only) names the [start, stop) samples of each amplitude, e.g. ``("A = 0.2 mrad", 5000, 45000)``."""

    kind: str
    fs: float
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    params: dict
    moves: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), int))
    sections: list[tuple[str, int, int]] = field(default_factory=list)

    @property
    def n(self) -> int:
        return int(self.position.size)

    @property
    def t(self) -> np.ndarray:
        return np.arange(self.n) / self.fs

    def reversals(self) -> np.ndarray:
        """Sample indices where the reference starts moving against its previous direction: the first sample
        of each run of non-zero velocity whose sign differs from the previous run's. Shape (r,), int."""
        s = np.sign(self.velocity)
        idx = np.flatnonzero(s)
        if idx.size < 2:
            return np.zeros(0, int)
        flips = np.flatnonzero(s[idx[1:]] != s[idx[:-1]]) + 1
        return idx[flips]


def _count(duration: float, fs: float) -> int:
    n = int(round(duration * fs))
    if n > MAX_SAMPLES:
        raise AnalysisError(f"reference of {duration:g} s at {fs:g} Hz is {n} samples, above {MAX_SAMPLES}")
    return n


def _positive(name: str, value: float, unit: str, allow_zero: bool = False) -> float:
    value = float(value)
    if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise AnalysisError(f"{name} must be {'>= 0' if allow_zero else '> 0'} {unit}, got {value!r}")
    return value


def slow_sine(fs: float, amplitudes: Sequence[float] = (2e-4, 1e-3, 1e-2, 0.1), frequency: float = 0.5,
              cycles: int = 3, rest: float = 0.5) -> Reference:
    """Sines ``A*(1 - cos(2*pi*f*t))`` (rad) of each amplitude A, ``cycles`` whole periods each, a ``rest``
    (s) at 0 before every amplitude and at the end."""
    fs = _positive("sample rate", fs, "Hz")
    f = _positive("frequency", frequency, "Hz")
    rest = _positive("rest", rest, "s", allow_zero=True)
    if int(cycles) != cycles or cycles < 1:
        raise AnalysisError(f"cycles must be a whole number >= 1, got {cycles!r}")
    amps = [_positive("amplitude", a, "rad") for a in amplitudes]
    if not amps:
        raise AnalysisError("slow sine needs at least one amplitude")
    n_rest = _count(rest, fs)
    n_seg = _count(cycles / f, fs)
    _count(len(amps) * (n_rest + n_seg) + n_rest, 1.0)
    w = 2 * math.pi * f
    tt = np.arange(n_seg) / fs
    parts = []
    zeros = np.zeros(n_rest)
    sections = []
    for j, a in enumerate(amps):
        parts.append((zeros, zeros, zeros))
        parts.append((a * (1 - np.cos(w * tt)), a * w * np.sin(w * tt), a * w * w * np.cos(w * tt)))
        start = (j + 1) * n_rest + j * n_seg
        sections.append((f"A = {a * 1e3:.3g} mrad", start, start + n_seg))
    parts.append((zeros, zeros, zeros))
    q, v, acc = (np.concatenate([p[i] for p in parts]) for i in range(3))
    return Reference("sine", fs, q, v, acc, {"amplitudes": amps, "frequency": f, "cycles": int(cycles),
                                             "rest": rest}, sections=sections)


def _ramped(knots: Sequence[tuple[float, float]], t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration of a velocity linear between ``knots`` (time s, velocity rad/s),
    position 0 at the first knot; exact at every t (the integral of each linear piece in closed form)."""
    tk = np.array([k[0] for k in knots])
    vk = np.array([k[1] for k in knots])
    dt = np.diff(tk)
    slope = np.divide(np.diff(vk), dt, out=np.zeros_like(dt), where=dt > 0)
    qk = np.concatenate([[0.0], np.cumsum(0.5 * (vk[:-1] + vk[1:]) * dt)])
    i = np.clip(np.searchsorted(tk, t, side="right") - 1, 0, dt.size - 1)
    tau = t - tk[i]
    return qk[i] + vk[i] * tau + 0.5 * slope[i] * tau * tau, vk[i] + slope[i] * tau, slope[i]


def triangle(fs: float, amplitude: float = 0.05, frequency: float = 0.5, cycles: int = 3,
             corner: float = 0.02, rest: float = 0.5) -> Reference:
    """Triangle 0 -> +A -> -A -> ... -> 0 (rad) at speed S = 4*A*f rad/s, ``cycles`` periods, a ``rest`` (s) at
    0 before and after. Every change of velocity (start, each corner, stop) is a linear ramp of ``corner`` s
    centred where the sharp triangle changes, so the acceleration is +-2S/corner at corners (S/corner at the
    ends) and the path ends exactly at 0. ``corner`` must span at least two samples."""
    fs = _positive("sample rate", fs, "Hz")
    a = _positive("amplitude", amplitude, "rad")
    f = _positive("frequency", frequency, "Hz")
    c = _positive("corner", corner, "s")
    rest = _positive("rest", rest, "s", allow_zero=True)
    if int(cycles) != cycles or cycles < 1:
        raise AnalysisError(f"cycles must be a whole number >= 1, got {cycles!r}")
    period = 1.0 / f
    if not 2.0 / fs <= c <= period / 4:
        raise AnalysisError(f"corner {c:g} s must be between two samples ({2 / fs:g} s) and a quarter period "
                            f"({period / 4:g} s)")
    n_rest = _count(rest, fs)
    n = _count(cycles * period + c, fs) + 1
    speed = 4 * a * f
    knots = [(0.0, 0.0), (c, speed)]
    for k in range(int(cycles)):
        base = c / 2 + k * period
        knots += [(base + period / 4 - c / 2, speed), (base + period / 4 + c / 2, -speed),
                  (base + 3 * period / 4 - c / 2, -speed), (base + 3 * period / 4 + c / 2, speed)]
    end = c / 2 + cycles * period
    knots += [(end - c / 2, speed), (end + c / 2, 0.0)]
    q, v, acc = _ramped(knots, np.minimum(np.arange(n) / fs, end + c / 2))
    zeros = np.zeros(n_rest)
    params = {"amplitude": a, "frequency": f, "cycles": int(cycles), "corner": c, "rest": rest}
    return Reference("triangle", fs, np.concatenate([zeros, q, zeros]), np.concatenate([zeros, v, zeros]),
                     np.concatenate([zeros, acc, zeros]), params)


def _min_jerk(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-jerk profile 10s^3 - 15s^4 + 6s^5 and its first two derivatives in s, s in [0, 1]."""
    p = s ** 3 * (10 - 15 * s + 6 * s * s)
    dp = 30 * s * s * (1 - s) ** 2
    ddp = 60 * s * (1 - s) * (1 - 2 * s)
    return p, dp, ddp


def point_to_point(fs: float, targets: Sequence[float] = (0.05, -0.05, 0.0), move_time: float = 0.3,
                   rest: float = 0.7) -> Reference:
    """From 0 to each target (rad) in turn along a minimum-jerk quintic of ``move_time`` s, each move followed
    by ``rest`` s at rest (and ``rest`` before the first)."""
    fs = _positive("sample rate", fs, "Hz")
    tm = _positive("move time", move_time, "s")
    rest = _positive("rest", rest, "s", allow_zero=True)
    goals = [float(x) for x in targets]
    if not goals or not all(math.isfinite(x) for x in goals):
        raise AnalysisError(f"point-to-point needs finite targets in rad, got {list(targets)!r}")
    n_move = max(2, _count(tm, fs))
    n_rest = _count(rest, fs)
    _count(len(goals) * (n_move + n_rest) + n_rest, 1.0)
    s = np.arange(n_move) / n_move
    p, dp, ddp = _min_jerk(s)
    qs, vs, accs, moves = [np.zeros(n_rest)], [np.zeros(n_rest)], [np.zeros(n_rest)], []
    start, pos = n_rest, 0.0
    for goal in goals:
        d = goal - pos
        qs += [pos + d * p, np.full(n_rest, goal)]
        vs += [d * dp / tm, np.zeros(n_rest)]
        accs += [d * ddp / tm ** 2, np.zeros(n_rest)]
        moves.append((start, start + n_move))
        start += n_move + n_rest
        pos = goal
    params = {"targets": goals, "move_time": tm, "rest": rest}
    return Reference("point_to_point", fs, np.concatenate(qs), np.concatenate(vs), np.concatenate(accs), params,
                     np.asarray(moves, int).reshape(-1, 2))


def make_reference(kind: str, fs: float, **params) -> Reference:
    """Build reference ``kind`` (one of :data:`KINDS`) with keyword parameters."""
    builders = {"sine": slow_sine, "triangle": triangle, "point_to_point": point_to_point}
    if kind not in builders:
        raise AnalysisError(f"reference must be one of {', '.join(KINDS)}, got {kind!r}")
    try:
        return builders[kind](fs, **params)
    except TypeError as exc:
        raise AnalysisError(f"{kind} reference: {exc}") from None
