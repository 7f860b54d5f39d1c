"""Display-side data for the live plots: a rolling ring buffer and min/max decimation per pixel column.

Display only: the run file keeps every sample. Nothing here imports Qt, so it is tested as plain numpy.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np


class RingBuffer:
    """The last ``capacity`` samples of a time axis and named channels (float64).

    ``append`` copies at most ``capacity`` samples of a block; ``snapshot`` returns them oldest first.
    Not thread-safe: fill and read it in one thread (the GUI thread).
    """

    def __init__(self, channels: Sequence[str], capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1 sample, got {capacity}")
        self.channels = tuple(channels)
        self.capacity = int(capacity)
        self._t = np.empty(self.capacity)
        self._data = np.empty((len(self.channels), self.capacity))
        self._head = 0  # index where the next sample goes
        self._size = 0
        self.total = 0  # samples ever appended

    def __len__(self) -> int:
        return self._size

    def clear(self) -> None:
        self._head = self._size = self.total = 0

    def append(self, t: np.ndarray, values: Mapping[str, np.ndarray]) -> None:
        """Append a block: ``t`` (s, shape (n,)) and one array of shape (n,) per channel."""
        t = np.asarray(t, dtype=float).ravel()
        n = t.size
        if n == 0:
            return
        self.total += n
        rows = [np.asarray(values[c], dtype=float).ravel() for c in self.channels]
        if n > self.capacity:
            t = t[-self.capacity:]
            rows = [r[-self.capacity:] for r in rows]
            n = self.capacity
        first = min(n, self.capacity - self._head)
        self._t[self._head:self._head + first] = t[:first]
        for i, r in enumerate(rows):
            self._data[i, self._head:self._head + first] = r[:first]
        rest = n - first
        if rest:
            self._t[:rest] = t[first:]
            for i, r in enumerate(rows):
                self._data[i, :rest] = r[first:]
        self._head = (self._head + n) % self.capacity
        self._size = min(self.capacity, self._size + n)

    def snapshot(self) -> tuple[np.ndarray, np.ndarray]:
        """(t, data): copies oldest first, shapes (size,) and (n_channels, size)."""
        if self._size < self.capacity:
            return self._t[:self._size].copy(), self._data[:, :self._size].copy()
        order = np.r_[self._head:self.capacity, 0:self._head]
        return self._t[order], self._data[:, order]

    def last(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """(t, data) of the newest ``min(n, size)`` samples, oldest first (copies of just those)."""
        n = max(0, min(int(n), self._size))
        start = (self._head - n) % self.capacity
        if start + n <= self.capacity:
            return self._t[start:start + n].copy(), self._data[:, start:start + n].copy()
        order = np.r_[start:self.capacity, 0:self._head]
        return self._t[order], self._data[:, order]

    def latest_time(self) -> float:
        if self._size == 0:
            return float("nan")
        return float(self._t[(self._head - 1) % self.capacity])


def minmax_decimate(t: np.ndarray, y: np.ndarray, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """Reduce a trace to at most ``2*columns`` points that draw the same envelope at ``columns`` pixels.

    The samples are cut into ``columns`` consecutive bins of ``ceil(n / columns)`` samples (the last one
    shorter); each bin becomes two points, its minimum and its maximum, both at the bin's first time, in
    the order they occur. A line through these points covers exactly the vertical extent the full trace
    covers in every pixel column, so spikes one sample wide stay visible. NaNs are ignored unless a whole
    bin is NaN. Traces with ``n <= 2*columns`` samples are returned unchanged.

    Args:
        t: times, shape (n,), s (ascending).
        y: values, shape (n,) or (k, n) for k traces sharing ``t``.
        columns: pixel columns, >= 1.
    Returns:
        (t_out, y_out): shapes (m,) and y's leading shape + (m,), m <= 2*columns.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    n = t.size
    if columns < 1:
        raise ValueError(f"columns must be >= 1, got {columns}")
    if n <= 2 * columns:
        return t, y
    size = -(-n // columns)
    n_bins = -(-n // size)
    pad = n_bins * size - n
    lead = y.shape[:-1]
    yy = y.reshape(-1, n)
    if pad:  # repeat the last sample: it changes neither minimum nor maximum of the last bin
        yy = np.concatenate([yy, np.repeat(yy[:, -1:], pad, axis=1)], axis=1)
    bins = yy.reshape(yy.shape[0], n_bins, size)
    with np.errstate(invalid="ignore"):
        all_nan = np.isnan(bins).all(axis=2)
        filled_lo = np.where(np.isnan(bins), np.inf, bins)
        filled_hi = np.where(np.isnan(bins), -np.inf, bins)
    i_lo = filled_lo.argmin(axis=2)
    i_hi = filled_hi.argmax(axis=2)
    lo = np.take_along_axis(bins, i_lo[..., None], axis=2)[..., 0]
    hi = np.take_along_axis(bins, i_hi[..., None], axis=2)[..., 0]
    lo[all_nan] = np.nan
    hi[all_nan] = np.nan
    lo_first = i_lo <= i_hi
    out = np.empty((yy.shape[0], n_bins, 2))
    out[..., 0] = np.where(lo_first, lo, hi)
    out[..., 1] = np.where(lo_first, hi, lo)
    t_bins = t[::size]
    t_out = np.repeat(t_bins, 2)
    return t_out, out.reshape(*lead, 2 * n_bins)
