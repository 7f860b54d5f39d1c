"""The presliding analysis of a record read chunk by chunk (docs/long-runs.md, "presliding").

The analysis works on the record averaged in blocks of m = ceil(n/MAX_SAMPLES) samples
(:func:`~.analyse.block_means`), so what it needs from the raw samples reduces to:

- pass 1: the block means of t, x and the force (each block's mean over the same samples as the whole read: equal
  to rounding), the position step (:func:`~hilbench.analysis.identification.regressors.position_resolution`: the
  smallest nonzero increment, exact; the noise level from the median absolute deviation of the second differences,
  exact up to :data:`NOISE_SAMPLES` samples, beyond that over every k-th second difference, a sample of at least
  that many), and the count of samples where x moves;
- pass 2, once the turning points are known: each turning point's extreme force (the raw force's moving average,
  filtered chunk by chunk over a segment padded by the filter's length, so equal to the whole record's to
  rounding) and whether every move is a whole number of steps (a quantised record).

Not streamed: the edge-pinned fit of a quantised record (the dwells at count edges need the raw path); a record read
chunk by chunk reports it as not made, with that reason, and the fits that use its origin take x[0] as rest.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.ndimage import uniform_filter1d

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.presliding.analyse import (
    EXTREME_WINDOW_S,
    HYSTERESIS_STEPS,
    MAX_SAMPLES,
    PreslidingResult,
    analyse_blocks,
)
from hilbench.analysis.presliding.identify import PreslidingSettings
from hilbench.analysis.presliding.quantities import DEFAULT_FRACTION, encoder_step
from hilbench.analysis.presliding.span import XMeans, plan_span

#: second differences kept for the noise level's median (float64: 32 MiB)
NOISE_SAMPLES = 1 << 22
#: why a streamed read makes no edge-pinned fit
NOT_STREAMED = ("the edge-pinned fit reads the whole raw path and the record was read chunk by chunk "
                "(--memory): raise --memory to make it")


class _Blocks:
    """Block means of several channels given chunk by chunk (the tail that fills no block is dropped)."""

    def __init__(self, m: int, channels: int):
        self.m = m
        self.carry = np.empty((channels, 0))
        self.parts: list[np.ndarray] = []

    def push(self, chunk: np.ndarray) -> None:
        data = np.concatenate([self.carry, chunk], axis=1) if self.carry.size else chunk
        k = (data.shape[1] // self.m) * self.m
        if k:
            self.parts.append(data[:, :k].reshape(data.shape[0], -1, self.m).mean(axis=2))
        self.carry = data[:, k:]

    def result(self) -> np.ndarray:
        return np.concatenate(self.parts, axis=1) if self.parts else np.empty((self.carry.shape[0], 0))


def _pass_one(reader, names, n: int, max_samples: int, chunk: int, progress, calibrated: float | None = None
              ) -> tuple[np.ndarray, int, float, int]:
    """(block means (3, n/m), m, position step, samples where x moves); the step is ``calibrated`` when given."""
    m = max(1, -(-n // max_samples))
    blocks = _Blocks(m, 3)
    stride = max(1, -(-n // NOISE_SAMPLES))
    quantum, moves = math.inf, 0
    d2_parts: list[np.ndarray] = []
    tail = np.empty(0)
    for start, (t, x, f) in reader.chunks(names, chunk, progress=progress):
        blocks.push(np.vstack([t, x, f]))
        ext = np.concatenate([tail, x])
        dx = np.diff(ext)
        nz = np.abs(dx[dx != 0])
        moves += int(nz.size)
        if nz.size:
            quantum = min(quantum, float(nz.min()))
        d2 = np.diff(ext, 2)
        first = start - tail.size  # record index of ext[0]; d2[i] belongs to sample first + i
        keep = (first + np.arange(d2.size)) % stride == 0
        d2_parts.append(d2[keep])
        tail = ext[-2:]
    d2 = np.concatenate(d2_parts) if d2_parts else np.empty(0)
    noise = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / np.sqrt(6.0) if d2.size else 0.0
    step = calibrated or max(0.0 if math.isinf(quantum) else quantum, noise)
    return blocks.result(), m, step, moves


def _pass_two(reader, force_name: str, position_name: str, centres: np.ndarray, window: int, step: float,
              chunk: int, progress) -> tuple[np.ndarray, bool]:
    """(each turning point's extreme force, whether every move of x is a whole number of steps)."""
    n = reader.n_samples
    rev = np.asarray(centres, dtype=np.int64)
    bounds = np.concatenate([[0], rev, [n - 1]])
    lo = (rev + bounds[:-2]) // 2
    hi = (rev + bounds[2:]) // 2 + 1
    first_f = reader.read(force_name, 0, 1)[0]
    rising = reader.read(force_name, int(rev[0]), int(rev[0]) + 1)[0] >= first_f if rev.size else True
    is_max = (np.arange(rev.size) % 2 == 0) == rising
    out = np.where(is_max, -np.inf, np.inf)
    whole_steps = step > 0
    pad = window + 1
    prev_x = None
    for a in range(0, n, max(1, chunk)):
        b = min(a + chunk, n)
        s0, s1 = max(0, a - pad), min(n, b + pad)
        smooth = uniform_filter1d(reader.read(force_name, s0, s1), window, mode="nearest")[a - s0:b - s0]
        for i in np.flatnonzero((lo < b) & (hi > a)):
            seg = smooth[max(lo[i], a) - a:min(hi[i], b) - a]
            out[i] = max(out[i], seg.max()) if is_max[i] else min(out[i], seg.min())
        x = reader.read(position_name, a, b)
        if whole_steps:
            dx = np.diff(np.concatenate([x[:0] if prev_x is None else prev_x, x]))
            mv = dx[dx != 0]
            whole_steps = bool(np.all(np.abs(mv / step - np.round(mv / step)) < 1e-3))
        prev_x = x[-1:]
        if progress is not None:
            progress(n + b, 2 * n)
    return out, whole_steps


def analyse_stream(reader, fs: float, axis: str, force_name: str, settings: PreslidingSettings | None = None, *,
                   counts_per_rev: float | None = None, hysteresis: float | None = None,
                   fraction: float = DEFAULT_FRACTION, replicates: int = 20, seed: int = 0,
                   max_samples: int = MAX_SAMPLES, chunk: int = 1 << 18,
                   progress: Callable[[int, int], None] | None = None) -> PreslidingResult:
    """:func:`~.analyse.analyse` on a run file open in ``reader``
    (:class:`hilbench.analysis.channel_windows.ChannelReader`), two passes of ``chunk`` samples (module
    docstring); ``progress(done, total)`` counts the samples of both passes. A record whose blocks would be too long
    for its path is cut to its first repeats as :func:`~.analyse.analyse` cuts it (:mod:`~.span`): the span is then
    read again, as a record of its own, and the progress restarts over it."""
    n = reader.n_samples
    if n < 3:
        raise AnalysisError(f"{reader.path}: {n} samples; a presliding record needs a virgin ramp and reversals")
    if max_samples < 100:
        raise AnalysisError(f"max_samples must be >= 100, got {max_samples}")
    options = {"counts_per_rev": counts_per_rev, "hysteresis": hysteresis, "fraction": fraction,
               "replicates": replicates, "seed": seed}
    calibrated = encoder_step(axis, counts_per_rev)  # the step as analyse.analyse takes it
    first = _pass_one(reader, ("t", "position", force_name), n, max_samples, chunk, _ticks(progress, n), calibrated)
    span = plan_span(n, max_samples, HYSTERESIS_STEPS * first[2] if hysteresis is None else hysteresis,
                     _x_means(reader, first, n, chunk), lambda a, b: reader.read("position", a, b))
    if span is None:
        return _analyse_read(reader, first, fs, axis, force_name, settings, chunk, progress, options)
    head = _Head(reader, span.samples)
    again = _pass_one(head, ("t", "position", force_name), head.n_samples, max_samples, chunk,
                      _ticks(progress, head.n_samples), calibrated)
    res = _analyse_read(head, again, fs, axis, force_name, settings, chunk, progress, options)
    res.warnings.append(span.warning(n, fs, max_samples))
    return res


def _ticks(progress: Callable[[int, int], None] | None, n: int) -> Callable[[int, int], None] | None:
    """Pass one's progress as a share of both passes over ``n`` samples."""
    return None if progress is None else (lambda d, t: progress(d, 2 * n))


def _analyse_read(reader, first: tuple[np.ndarray, int, float, int], fs: float, axis: str, force_name: str,
                  settings: PreslidingSettings | None, chunk: int, progress, options: dict) -> PreslidingResult:
    """The analysis of all of ``reader``'s record from pass one's ``first`` (block means, m, step, moves); pass two
    runs once the turning points are known."""
    means, m, step, moves = first
    n = reader.n_samples
    window = max(1, round(EXTREME_WINDOW_S * fs))
    state: dict[str, bool] = {}

    def extremes_of(rev: np.ndarray) -> np.ndarray:
        out, whole_steps = _pass_two(reader, force_name, "position", rev * m + m // 2, window, step, chunk,
                                     progress)
        state["quantised"] = whole_steps and 0 < moves <= 0.5 * (n - 1)
        return out

    res = analyse_blocks(means[0], means[1], means[2], fs / m, m, step, axis, settings,
                         (None, None, "the displacement is not quantised in whole steps", None, None), extremes_of,
                         **options)
    if state.get("quantised"):
        res.edge_error = NOT_STREAMED
    return res


def _x_means(reader, first: tuple[np.ndarray, int, float, int], n: int, chunk: int) -> XMeans:
    """:data:`~.span.XMeans` on the run file: pass one's block means for the whole record at its block, else a
    pass over the position of the head asked for (one chunk and its blocks in memory)."""
    def means(m: int, head: int) -> np.ndarray:
        if m == first[1] and head >= n:
            return first[0][1]
        blocks = _Blocks(m, 1)
        for _, (x,) in reader.chunks(("position",), chunk, stop=head):
            blocks.push(x[None, :])
        return blocks.result()[0]

    return means


class _Head:
    """The first ``n`` samples of a run file open in ``reader``, read as a record of their own."""

    def __init__(self, reader, n: int):
        self._reader = reader
        self.path = reader.path
        self.n_samples = int(n)

    def read(self, name: str, start: int, stop: int) -> np.ndarray:
        return self._reader.read(name, start, min(stop, self.n_samples))

    def chunks(self, names, chunk: int, progress=None):
        return self._reader.chunks(names, chunk, stop=self.n_samples, progress=progress)
