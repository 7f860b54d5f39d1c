"""A chirp record too long to hold whole, reduced to what ForceVib needs, read chunk by chunk (docs/long-runs.md).

Two passes over the file, each holding one chunk (plus one spectrum segment):

1. The analysis band, from the energy spectrum averaged over segments of :data:`SEGMENT` samples (each detrended
   as :func:`hilbench.analysis.skeleton.instantaneous.spectral_extent` detrends the whole record; a record no
   longer than one segment gives the whole record's spectrum, hence its band, exactly).
2. A decimated copy of the response and of the centred force: both through the same Butterworth low-pass of order
   :data:`FILTER_ORDER` (``scipy.signal.sosfilt``, its state carried across chunk edges), cut off at a quarter of
   the new rate, then every q-th sample. q keeps the new rate at :data:`OVERSAMPLE` x the band's top frequency:
   the filter's gain is then within 3e-5 of 1 up to 2.2 x the top frequency (where the widest wavelet's gain has
   fallen to 1 %) and below -60 dB from the new Nyquist frequency on, so what ForceVib reads is kept and nothing
   folds onto it. Response and force see the same filter, so its phase (a delay of about half a period of the
   top frequency) shifts both alike and leaves the ratio Z/Y, hence k_eq and c_eq, as they are.

ForceVib then runs on the decimated copy in memory (n/q samples).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator

import numpy as np
from scipy import signal

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.skeleton.instantaneous import detrended_energy, extent_of_energy

#: samples per spectrum segment of pass 1 (frequency resolution fs/SEGMENT: 0.01 Hz at 10 kHz)
SEGMENT = 1 << 20
#: the decimated rate, in multiples of the band's top frequency
OVERSAMPLE = 15
#: order of the anti-alias Butterworth low-pass (cut off at a quarter of the decimated rate)
FILTER_ORDER = 10


def streamed_extent(chunks: Iterable[np.ndarray], n: int, fs: float, segment: int = SEGMENT
                    ) -> tuple[float, float, float]:
    """:func:`~hilbench.analysis.skeleton.instantaneous.spectral_extent` of a record of ``n`` samples given in
    chunks: the energy spectra of consecutive segments of min(n, ``segment``) samples summed (a tail shorter than
    a segment is left out)."""
    length = min(n, segment)
    total = None
    buf: list[np.ndarray] = []
    held = 0
    for c in chunks:
        buf.append(c)
        held += c.size
        while held >= length:
            joined = np.concatenate(buf)
            seg, rest = joined[:length], joined[length:]
            energy = detrended_energy(seg)
            total = energy if total is None else total + energy
            buf, held = [rest], rest.size
    if total is None:
        raise AnalysisError(f"record of {n} samples: nothing to take a spectrum of")
    return extent_of_energy(total, fs, length)


def decimation_factor(fs: float, f_top: float) -> int:
    """q such that fs/q >= :data:`OVERSAMPLE` * ``f_top`` (1: no decimation)."""
    if not (f_top > 0 and math.isfinite(f_top)):
        raise AnalysisError(f"band top {f_top} Hz: must be positive")
    return max(1, int(fs // (OVERSAMPLE * f_top)))


def centred_chunks(pairs: Iterable[tuple[np.ndarray, np.ndarray]], timing: str
                   ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """``(x, force)`` chunks with the force centred on the sample instants as
    :func:`hilbench.analysis.skeleton.centred_force` centres a whole channel (one sample carried across edges;
    with ``hold_previous`` the output lags the input by one sample, flushed at the end)."""
    prev_x = prev_f = None
    for x, f in pairs:
        if timing == "hold_next":
            before = np.insert(f[:-1], 0, f[0] if prev_f is None else prev_f[-1])
            prev_f = f
            yield x, 0.5 * (f + before)
        elif timing == "hold_previous":
            if prev_x is not None:
                x, f = np.concatenate([prev_x, x]), np.concatenate([prev_f, f])
            prev_x, prev_f = x[-1:], f[-1:]
            if x.size > 1:
                yield x[:-1], 0.5 * (f[:-1] + f[1:])
        else:
            yield x, f
    if timing == "hold_previous" and prev_x is not None:
        yield prev_x, prev_f


class Decimator:
    """Low-pass and keep every q-th sample of several channels given chunk by chunk (module docstring)."""

    def __init__(self, fs: float, q: int):
        self.q = int(q)
        self.sos = signal.butter(FILTER_ORDER, fs / (4.0 * self.q), fs=fs, output="sos") if self.q > 1 else None
        self._zi: np.ndarray | None = None
        self._offset = 0

    def push(self, chunk: np.ndarray) -> np.ndarray:
        """``chunk`` of shape (channels, m) -> the kept samples, shape (channels, k)."""
        if self.sos is None:
            return chunk
        if self._zi is None:  # start in the steady state of the first sample: no step transient
            self._zi = signal.sosfilt_zi(self.sos)[:, None, :] * chunk[None, :, 0, None]
        y, self._zi = signal.sosfilt(self.sos, chunk, axis=-1, zi=self._zi)
        first = (-self._offset) % self.q
        self._offset += chunk.shape[-1]
        return y[:, first::self.q]


def decimated_copy(pairs: Iterable[tuple[np.ndarray, np.ndarray]], fs: float, q: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(x, force) at fs/q from ``(x, force)`` chunks (already centred)."""
    dec = Decimator(fs, q)
    parts = [dec.push(np.vstack([x, f])) for x, f in pairs]
    both = np.concatenate(parts, axis=1)
    return both[0].copy(), both[1].copy()
