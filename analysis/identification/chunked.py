"""The filtered regression of ``maxwell_fit`` over a record given chunk by chunk, in bounded memory.

A record is read through a *chunk source*: a callable that returns a fresh iterator of ``(position, torque)``
array pairs (rad or m, N*m or N), consecutive pieces of the record in order, of any lengths. The fit reads the
record several times (the grid scan, one pass per threshold set, the final prediction), so the source must be
re-iterable: a file reader opens the file again, ``array_chunks`` slices arrays.

Exactness. The record is processed in blocks of ``block`` samples on the global sample index, so the result does
not depend on how the source cuts its chunks (bit for bit). Each block is computed on a window reaching
``margin`` samples beyond it on either side (clipped at the record's ends, where the window edge is the record
edge and the computation is the whole-record one):

- the zero-phase filter (forward-backward) of the window differs from the whole record's only through the
  window's start-up transients, which decay as exp(-0.38*2*pi*fc*t) (the Butterworth's slowest pole); the default
  margin, 4x ``regressors.edge_samples`` = 40 time constants, leaves exp(-40) = 4e-18 of the signal;
- the stop-operator deflections are carried exactly from block to block (the state at the next window's start);
- differences and the triangle average need one neighbour, held in the window.

The regression rows are accumulated into the triangular factor R of the QR decomposition of [A | y] (A: the
regressor columns at the rows, y: L[tau]). The least-squares problems of the fit (NNLS on unit-norm columns)
are then solved on R: |A c - y|^2 = |R_11 c - r_12|^2 + r_22^2, so the solution equals the one on the full A,
without the squared condition number of the normal equations X^T X. Memory: one window of the stop-operator
columns (block x thresholds) and R; the fit's per-row outputs (``LipFit.measured``, ``predicted``, ``rows``)
are 24 bytes per row, i.e. 3 bytes per sample at the default thinning of 8.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.regressors import (
    edge_samples,
    torque_at_samples,
    triangle_average,
    zero_phase_lowpass,
)

ChunkSource = Callable[[], Iterable[tuple[np.ndarray, np.ndarray]]]
#: Samples per processing block (stop-operator columns of one window: block x 64 thresholds x 8 bytes = 8 MiB).
BLOCK = 1 << 14
#: Points kept of the path for the reversal travels (as regressors.reversal_travels' default thinning).
THINNED_POINTS = 20_000
#: Samples per block of the noise estimate (median absolute deviation of second differences).
NOISE_BLOCK = 1 << 16


def array_chunks(position: np.ndarray, torque: np.ndarray, size: int = 1 << 16) -> ChunkSource:
    """A chunk source over two arrays of equal length, ``size`` samples per chunk."""
    x = np.asarray(position, float)
    tau = np.asarray(torque, float)
    if x.shape != tau.shape or x.ndim != 1:
        raise AnalysisError(f"position and torque must be 1-D of equal length, got {x.shape} and {tau.shape}")
    if size < 1:
        raise AnalysisError(f"chunk size must be >= 1, got {size}")

    def chunks() -> Iterator[tuple[np.ndarray, np.ndarray]]:
        for i in range(0, x.size, size):
            yield x[i : i + size], tau[i : i + size]

    return chunks


def default_margin(fs: float, cutoff: float) -> int:
    """Window margin, samples: 40 time constants of the filter's slowest pole (see the module docstring)."""
    return 4 * edge_samples(fs, cutoff)


def _checked(pairs: Iterable[tuple[np.ndarray, np.ndarray]]) -> Iterator[tuple[np.ndarray, np.ndarray, int]]:
    """The chunks as float arrays, checked (1-D, equal length, finite), with the global index of their start."""
    start = 0
    for x, tau in pairs:
        x = np.asarray(x, float).ravel()
        tau = np.asarray(tau, float).ravel()
        if x.size != tau.size:
            raise AnalysisError(f"chunk at sample {start}: position and torque lengths differ ({x.size}, {tau.size})")
        for name, arr in (("position", x), ("torque", tau)):
            bad = ~np.isfinite(arr)
            if bad.any():
                raise AnalysisError(f"{name} contains NaN or inf (first at sample {start + int(np.argmax(bad))})")
        yield x, tau, start
        start += x.size


@dataclass
class RecordScan:
    """What one pass over a record tells: its length and the figures the threshold grid needs."""

    n: int
    quantum: float  # smallest nonzero position increment, rad or m
    noise: float  # white-noise level of the position, 1.4826*median(block MADs of D^2 x)/sqrt(6)
    thinned: np.ndarray  # x[::step] (step a power of 2) with at most 2*THINNED_POINTS points
    position_range: float
    torque_range: float

    @property
    def resolution(self) -> float:
        """As ``regressors.position_resolution``: the larger of the quantum and the noise level."""
        return max(self.quantum, self.noise)


def scan(source: ChunkSource) -> RecordScan:
    """One pass: length, quantum, noise level (median over blocks of NOISE_BLOCK samples of the second differences'
    MAD: the whole-record MAD when the record is at most one block), a thinned path, ranges."""
    n = 0
    quantum = np.inf
    prev = np.empty(0)
    d2_buf: list[np.ndarray] = []
    d2_len = 0
    mads: list[float] = []
    weights: list[int] = []
    step = 1
    thin: list[np.ndarray] = []
    thin_len = 0
    xmin = tmin = np.inf
    xmax = tmax = -np.inf

    def block_mad(d2: np.ndarray) -> None:
        if d2.size:
            mads.append(float(np.median(np.abs(d2 - np.median(d2)))))
            weights.append(d2.size)

    for x, tau, start in _checked(source()):
        if x.size == 0:
            continue
        xmin, xmax = min(xmin, float(x.min())), max(xmax, float(x.max()))
        tmin, tmax = min(tmin, float(tau.min())), max(tmax, float(tau.max()))
        joined = np.concatenate([prev, x])
        dx = np.abs(np.diff(joined))
        nz = dx[dx > 0]
        if nz.size:
            quantum = min(quantum, float(nz.min()))
        d2 = np.diff(joined, 2)
        prev = joined[-2:]
        while d2.size:  # second differences, cut into fixed blocks on their global index
            take = min(NOISE_BLOCK - d2_len, d2.size)
            d2_buf.append(d2[:take])
            d2_len += take
            d2 = d2[take:]
            if d2_len == NOISE_BLOCK:
                block_mad(np.concatenate(d2_buf))
                d2_buf, d2_len = [], 0
        first = (-start) % step  # thinned points: every step-th sample on the global index
        thin.append(x[first::step])
        thin_len += thin[-1].size
        if thin_len > 2 * THINNED_POINTS:  # keep every other point and double the step
            joined_thin = np.concatenate(thin)[::2]
            thin, thin_len, step = [joined_thin], joined_thin.size, step * 2
        n += x.size
    if d2_len:
        block_mad(np.concatenate(d2_buf))
    if n == 0:
        raise AnalysisError("the record is empty")
    # the median of block MADs: the whole record's MAD for a single block, a robust estimate otherwise
    noise = 1.4826 * float(np.median(mads)) / np.sqrt(6.0) if mads else 0.0
    return RecordScan(n, float(quantum) if np.isfinite(quantum) else 0.0, noise, np.concatenate(thin),
                      xmax - xmin, tmax - tmin)


@dataclass
class Window:
    """Samples [wa, wa + x.size) of the record around the block [a, b); ``n`` is the record length once the
    source is exhausted (the last blocks), else None."""

    a: int
    b: int
    wa: int
    x: np.ndarray
    tau: np.ndarray
    n: int | None


def windows(source: ChunkSource, block: int, margin: int) -> Iterator[Window]:
    """The record in blocks of ``block`` samples on the global index, each with ``margin`` samples on either
    side (clipped at the record's ends). ``block`` is raised to 2*``margin`` so that the next window starts
    inside this one. Holds one window and one source chunk at a time."""
    block = max(int(block), 2 * int(margin), 1)
    m = int(margin)
    buf_x = np.empty(0)
    buf_t = np.empty(0)
    buf0 = 0  # global index of buf[0]
    a = 0  # start of the next block

    def ready(n_total: int | None) -> Iterator[Window]:
        nonlocal buf_x, buf_t, buf0, a
        while True:
            end = buf0 + buf_x.size
            if (n_total is None and end < a + block + m) or (n_total is not None and a >= n_total):
                return
            b = min(a + block, end)
            wa, wb = max(0, a - m), min(end, b + m)
            yield Window(a, b, wa, buf_x[wa - buf0 : wb - buf0], buf_t[wa - buf0 : wb - buf0], n_total)
            keep_from = b - m  # the next window's start
            if keep_from > buf0:
                buf_x, buf_t = buf_x[keep_from - buf0 :], buf_t[keep_from - buf0 :]
                buf0 = keep_from
            a = b

    for x, tau, _ in _checked(source()):
        buf_x = np.concatenate([buf_x, x])
        buf_t = np.concatenate([buf_t, tau])
        yield from ready(None)
    yield from ready(buf0 + buf_x.size)


class StopCarry:
    """Stop-operator deflections of the path from relaxed elements, window by window, the state carried
    exactly from one window to the next (which starts ``margin`` before the block's end)."""

    def __init__(self, deltas: np.ndarray, margin: int):
        self.deltas = np.asarray(deltas, float)
        self.margin = int(margin)
        self.state = np.zeros(self.deltas.size)

    def window(self, w: Window) -> np.ndarray:
        """Deflections at every sample of the window, (w.x.size, m)."""
        from hilbench.firmware_sim.engine.plant import stop_operator

        s = stop_operator(w.x, self.deltas, initial=self.state)
        if w.n is None or w.b < w.n:
            self.state = s[w.b - self.margin - w.wa].copy()
        return s


@dataclass
class Block:
    """Regression rows of one block: filtered signals at the rows (as ``regressors.FilteredData``), shape (r,),
    the stop-operator columns (r, m), and the rows' global indices."""

    torque: np.ndarray
    acceleration: np.ndarray
    velocity: np.ndarray
    position: np.ndarray
    sign: np.ndarray
    stop: np.ndarray
    rows: np.ndarray


def blocks(source: ChunkSource, fs: float, cutoff: float, *, order: int = 4, decimation: int = 1,
           timing: str = "hold_next", deltas: np.ndarray | None = None, block: int = BLOCK,
           margin: int | None = None) -> Iterator[Block]:
    """The regression rows of the record, block by block (module docstring). Rows are those of
    ``regressors.filtered_data``: every ``decimation``-th sample from ``edge`` to ``n - edge``."""
    if not 0 < cutoff < fs / 2:
        raise AnalysisError(f"filter cutoff {cutoff} Hz must be in (0, {fs / 2}) Hz (Nyquist)")
    d = np.empty(0) if deltas is None else np.asarray(deltas, float)
    edge = edge_samples(fs, cutoff)
    m = default_margin(fs, cutoff) if margin is None else int(margin)
    if m < edge:
        raise AnalysisError(f"window margin {m} is below the filter start-up length {edge}")
    dec = max(1, int(decimation))
    dt = 1.0 / fs
    stop_carry = StopCarry(d, m)
    for w in windows(source, block, m):
        both = zero_phase_lowpass(np.vstack([w.x, torque_at_samples(w.tau, timing)]), fs, cutoff, order)
        xf, tauf = both[0], both[1]
        v = np.gradient(xf, dt) if xf.size > 1 else np.zeros_like(xf)
        acc = np.zeros_like(xf)
        acc[1:-1] = (xf[2:] - 2.0 * xf[1:-1] + xf[:-2]) / dt**2
        sgn = zero_phase_lowpass(np.sign(v), fs, cutoff, order)
        # rows below b: inside the record's n - edge unless this is one of the last blocks (n known)
        hi = w.b if w.n is None else min(w.b, w.n - edge)
        first = max(edge, w.a)
        first += (-(first - edge)) % dec
        rows = np.arange(first, hi, dec)
        local = rows - w.wa
        if d.size:
            s = stop_carry.window(w)
            sf = zero_phase_lowpass(np.ascontiguousarray(s.T), fs, cutoff, order)
            stop = np.ascontiguousarray(triangle_average(sf, local).T) if rows.size else np.empty((0, d.size))
        else:
            stop = np.empty((rows.size, 0))
        if rows.size:
            yield Block(tauf[local], acc[local], v[local], triangle_average(xf, local),
                        triangle_average(sgn, local), stop, rows)
