"""Complex Morlet wavelet band, scale grid, chunked |W| map and penalised ridge extraction.

The wavelet is PyWavelets' ``cmor{fb}-{fc}`` (the paper's, science.md §4):

    psi(t) = (pi*fb)^(-1/2) * exp(2j*pi*fc*t) * exp(-t^2/fb)

whose Fourier transform is real and Gaussian, ``Psi(f) = exp(-pi^2*fb*(f - fc)^2)``, here with Morlet's
zero-mean correction (see ``morlet_spectrum``). At scale ``s`` (seconds)
the wavelet is centred on ``f = fc/s`` Hz with a Gaussian time envelope of standard deviation
``sigma_t = s*sqrt(fb/2)`` seconds. The transform is computed in the frequency domain on the analytic
(positive-frequency) part of the signal and normalised to unit gain at the centre frequency:

    W(s, t) = IFFT[ 2*X(f)*1{f>0} * Psi(s*f) ](t)

so a sinusoid ``A*cos(2*pi*f0*t)`` gives ``|W(s, t)| = A*Psi(s*f0)``, whose maximum over ``s`` is exactly
``A`` at ``s = fc/f0`` (unbiased ridge). Up to that normalisation, the conjugation and the dropped negative
frequencies, this is ``pywt.cwt(x, scales*fs, f"cmor{fb}-{fc}", method="fft")``; it is written here because
pywt returns no time derivatives of W (needed exactly by ForceVib), approximates the transform by differencing
a convolution with the integrated wavelet, and holds all scales x samples in memory at once.

Ridge extraction follows the forward-backward penalised path of ssqueezepy / MATLAB ``tfridge``
(Iatsenko et al., arXiv:1310.7276): minimise  sum_t -ln|W(s_t, t)| + penalty * (i_t - i_{t-1})^2  over
scale-index paths, by dynamic programming, with jumps limited to ``max_jump`` bins per step.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from hilbench.analysis.errors import AnalysisError

#: Gaussian time-envelope widths kept on each side of a chunk; the envelope weight there is exp(-12.5) ~ 4e-6.
PAD_SIGMAS = 5.0


def check_cmor(fb: float, fc: float) -> str:
    """Validate the complex Morlet parameters and return the PyWavelets name ``cmor{fb}-{fc}``.

    Args:
        fb: bandwidth parameter (s^2 at unit scale), > 0.
        fc: centre frequency at unit scale (Hz*s), > 0.
    """
    if not (np.isfinite(fb) and fb > 0 and np.isfinite(fc) and fc > 0):
        raise AnalysisError(f"complex Morlet needs fb > 0 and fc > 0, got fb={fb}, fc={fc}")
    # The negative-frequency response at the ridge, Psi(-fc) = exp(-4 pi^2 fb fc^2), must be negligible.
    if math.pi**2 * fb * fc**2 < 2.5:
        raise AnalysisError(f"cmor{fb}-{fc} is not analytic enough (need pi^2*fb*fc^2 >= 2.5); "
                            "raise fb or fc")
    return f"cmor{fb}-{fc}"


def morlet_spectrum(sf: np.ndarray, fb: float, fc: float) -> np.ndarray:
    """Fourier transform of cmor{fb}-{fc} with Morlet's zero-mean correction, at ``sf = s*f`` (dimensionless).

    Psi(sf) = exp(-pi^2*fb*(sf - fc)^2) - exp(-pi^2*fb*(sf^2 + fc^2)), which is 0 at sf = 0.

    The correction term is the transform of (pi*fb)^(-1/2)*exp(-t^2/fb)*exp(-pi^2*fb*fc^2), i.e. the wavelet
    minus its mean (relative size exp(-2*pi^2*fb*fc^2) at the ridge: 2e-3 for 0.5/0.8, 1e-21 for 1.5/1.8).
    Without it, pywt's cmor0.5-0.8 passes 4 % of DC and low frequencies, and the step that Psi(0) > 0 makes at
    f = 0 once negative frequencies are removed spreads a slowly decaying 1/t tail from the record's ends.
    """
    sf = np.asarray(sf, dtype=float)
    k = math.pi**2 * fb
    out = sf - fc
    np.square(out, out=out)
    out *= -k
    np.exp(out, out=out)
    corr = np.square(sf)
    corr += fc * fc
    corr *= -k
    np.exp(corr, out=corr)
    out -= corr
    return out


def time_width(scale: np.ndarray | float, fb: float) -> np.ndarray | float:
    """Standard deviation (s) of the wavelet's Gaussian time envelope at ``scale`` (s): s*sqrt(fb/2)."""
    return np.asarray(scale) * math.sqrt(fb / 2.0)


def relative_bandwidth(fb: float, fc: float) -> float:
    """Gaussian standard deviation of Psi(s*f) over f, relative to the centre frequency.

    sigma_f/f = 1/(pi*fc*sqrt(2*fb)).
    """
    return 1.0 / (math.pi * fc * math.sqrt(2.0 * fb))


def scale_grid(f_min: float, f_max: float, fc: float, voices: int) -> np.ndarray:
    """Scales (s) whose centre frequencies fc/s span [f_min, f_max] Hz with ``voices`` per octave.

    Returns shape (n_scales,), decreasing scale = increasing frequency.
    """
    if not (0 < f_min < f_max):
        raise AnalysisError(f"frequency band must satisfy 0 < f_min < f_max, got [{f_min}, {f_max}] Hz")
    if voices < 1:
        raise AnalysisError(f"voices per octave must be >= 1, got {voices}")
    n = max(3, int(math.ceil(voices * math.log2(f_max / f_min))) + 1)
    return fc / np.geomspace(f_min, f_max, n)


@dataclass(frozen=True)
class Chunk:
    """One piece of a long record: the core [start, stop) is kept, [seg_start, seg_stop) is transformed."""

    start: int
    stop: int
    seg_start: int
    seg_stop: int


def plan_chunks(n: int, pad: int, core: int, align: int = 1) -> Iterator[Chunk]:
    """Split ``n`` samples into cores of ``core`` samples (multiples of ``align``), each padded by ``pad``."""
    core = max(align, (core // align) * align)
    pad = int(math.ceil(pad / align)) * align
    start = 0
    while start < n:
        stop = min(n, start + core)
        yield Chunk(start, stop, max(0, start - pad), min(n, stop + pad))
        start = stop


def fft_length(seg_len: int, pad: int, align: int = 1) -> int:
    """FFT length >= seg_len + pad (zeros keep the circular wrap out of the core), a multiple of ``align``."""
    return align * sfft.next_fast_len(int(math.ceil((seg_len + pad) / align)))


def analytic_spectrum(segment: np.ndarray, nfft: int) -> np.ndarray:
    """Positive-frequency half of the spectrum of the analytic signal, 2*X(f) for 0 < f < fs/2, X(0) at DC.

    Shape (nfft//2 + 1,); bins k = 0..nfft//2 at f_k = k*fs/nfft.
    """
    spec = sfft.rfft(segment, nfft)
    spec[0] = 0.0
    spec[1:] *= 2.0
    if nfft % 2 == 0:
        spec[-1] *= 0.5
    return spec


def magnitude_blocks(
    x: np.ndarray, fs: float, scales: np.ndarray, fb: float, fc: float, hop: int, core: int
) -> Iterator[np.ndarray]:
    """|W(s, t)| on the decimated grid t = 0, hop, 2*hop, ... (samples), one chunk's columns at a time, in order.

    Each scale's band-limited analytic transform is evaluated directly at the decimated rate by inverting only
    the lowest nfft/hop bins of its spectrum (exact when Psi(s*f) is negligible above fs/hop; ``hop`` is
    chosen by the caller so that it is). Memory: one chunk spectrum and one block of columns.

    Args:
        x: signal, shape (n,).
        fs: sampling rate, Hz.
        scales: wavelet scales, s, shape (n_scales,).
        hop: decimation, samples (a power of two).
        core: chunk core length, samples.
    Yields:
        float32 arrays of shape (n_scales, k), k columns each; ceil(n/hop) columns in all.
    """
    n = x.size
    pad = int(math.ceil(PAD_SIGMAS * float(time_width(scales.max(), fb)) * fs))
    for ch in plan_chunks(n, pad, core, align=hop):
        seg = x[ch.seg_start:ch.seg_stop]
        nfft = fft_length(seg.size, pad, align=hop)
        m = nfft // hop
        spec = analytic_spectrum(seg, nfft)
        nb = min(m, spec.size)
        f = np.arange(nb) * (fs / nfft)
        c0 = (ch.start - ch.seg_start) // hop
        c1 = c0 + -(-(ch.stop - ch.start) // hop)
        block = np.empty((scales.size, c1 - c0), dtype=np.float32)
        buf = np.zeros(m, dtype=complex)
        for i, s in enumerate(scales):
            buf[:nb] = spec[:nb] * morlet_spectrum(s * f, fb, fc)
            w = sfft.ifft(buf) * (m / nfft)
            block[i] = np.abs(w[c0:c1])
        yield block


def magnitude_map(
    x: np.ndarray, fs: float, scales: np.ndarray, fb: float, fc: float, hop: int, core: int
) -> np.ndarray:
    """The whole |W| map of :func:`magnitude_blocks`: float32, shape (n_scales, ceil(n/hop))."""
    out = np.empty((scales.size, -(-x.size // hop)), dtype=np.float32)
    g = 0
    for block in magnitude_blocks(x, fs, scales, fb, fc, hop, core):
        out[:, g:g + block.shape[1]] = block
        g += block.shape[1]
    return out


class RidgeTracker:
    """:func:`ridge_path` fed the columns block by block, in order: the forward pass carries the accumulated cost
    of one column, and keeps the int8 back-pointers (1 byte per cell); :meth:`path` traces back. Fed the whole
    map as one block or in any split, it gives the same path, bit for bit (the same operations in the same
    order)."""

    def __init__(self, n_scales: int, n_times: int, penalty: float, max_jump: int):
        self.penalty = float(penalty)
        self.shifts = np.arange(-max_jump, max_jump + 1)
        self.back = np.empty((n_times, n_scales), dtype=np.int8)
        self.acc: np.ndarray | None = None
        self.t = 0
        self._idx = np.arange(n_scales)
        # acc with max_jump inf on either side: row k of its sliding windows is acc shifted by shifts[k], inf where
        # bin i + shift_k is off the map; the penalties of the shifts as a column
        self._pad = np.full(n_scales + 2 * max_jump, np.inf)
        self._windows = np.lib.stride_tricks.sliding_window_view(self._pad, n_scales)
        self._pen = (self.penalty * self.shifts * self.shifts).astype(float)[:, None]
        self._cand = np.empty((self.shifts.size, n_scales))

    def push(self, log_mag: np.ndarray) -> None:
        """Columns ln|W| of shape (n_scales, k), the next k in time."""
        n_s = self._idx.size
        cost = -np.asarray(log_mag, dtype=float)
        j = (self.shifts.size - 1) // 2
        pad, windows, pen, cand, idx, back = self._pad, self._windows, self._pen, self._cand, self._idx, self.back
        start = 0
        if self.acc is None:
            self.acc = cost[:, 0].copy()
            self.t, start = 1, 1
        acc = self.acc
        cost_t = np.ascontiguousarray(cost.T)  # one column per row: contiguous in the loop below
        for t in range(start, cost.shape[1]):
            # cand[k, i] = acc[i + shift_k] + penalty*shift_k^2: coming into bin i from bin i + shift_k (inf when
            # off the map); the same additions, in the same order, as one shift at a time
            pad[j:j + n_s] = acc
            np.add(windows, pen, out=cand)
            best = cand.argmin(axis=0)
            back[self.t] = best
            acc = cand[best, idx] + cost_t[t]
            self.t += 1
        self.acc = acc

    def path(self) -> np.ndarray:
        """int array of scale indices, shape (n_times,), once every column has been pushed."""
        n_t = self.back.shape[0]
        if self.acc is None or self.t != n_t:
            raise AnalysisError(f"ridge: {self.t} of {n_t} columns given")
        path = np.empty(n_t, dtype=np.int64)
        path[-1] = int(np.argmin(self.acc))
        for t in range(n_t - 1, 0, -1):
            path[t - 1] = path[t] + self.shifts[self.back[t, path[t]]]
        return path


def ridge_path(log_mag: np.ndarray, penalty: float, max_jump: int) -> np.ndarray:
    """Penalised ridge through a time-scale map by dynamic programming.

    Minimises  sum_t -log_mag[i_t, t] + penalty * (i_t - i_{t-1})^2  with |i_t - i_{t-1}| <= max_jump.

    Args:
        log_mag: ln|W|, shape (n_scales, n_times).
        penalty: cost of a one-bin jump, in units of ln-amplitude (>= 0).
        max_jump: largest jump allowed between consecutive columns, bins (>= 1).
    Returns:
        int array of scale indices, shape (n_times,).
    """
    tracker = RidgeTracker(log_mag.shape[0], log_mag.shape[1], penalty, max_jump)
    tracker.push(log_mag)
    return tracker.path()


#: |W| below this fraction of the map's largest value counts as no signal (the floor of ln|W|)
FLOOR = 1e-12
#: columns of ln|W| handed to the ridge at a time by :func:`streamed_ridge` (float64: 8 B x scales each)
RIDGE_COLUMNS = 4096


def streamed_ridge(x: np.ndarray, fs: float, scales: np.ndarray, fb: float, fc: float, hop: int, core: int,
                   penalty: float, max_jump: int) -> np.ndarray:
    """The ridge of ln(|W| + FLOOR * max|W|) over the map of :func:`magnitude_blocks`, computed block by block
    without holding the map (1 byte per cell, :class:`RidgeTracker`).

    The whole-map version normalises by the map's maximum first; a constant per column does not move the
    ridge, so the only difference is the floor: here it is FLOOR times the largest |W| seen up to that block,
    not of the whole map. That changes a column's costs only where |W| is below 1e-12 of the record's largest,
    a column without signal (docs/long-runs.md). Returns the scale indices, shape (ceil(n/hop),)."""
    tracker = RidgeTracker(scales.size, -(-x.size // hop), penalty, max_jump)
    top = 0.0
    for block in magnitude_blocks(x, fs, scales, fb, fc, hop, core):
        top = max(top, float(block.max()))
        # the log and the tracker's cost are float64: made RIDGE_COLUMNS at a time, not for the whole block (with
        # hop 1 a block is 2^19 columns, and its float64 copies were 1.3 GB on a 600 s chirp at 20 kHz)
        for a in range(0, block.shape[1], RIDGE_COLUMNS):
            part = block[:, a:a + RIDGE_COLUMNS]
            if top > 0:
                tracker.push(np.log(part / np.float32(top) + FLOOR))
            else:  # no signal yet: every scale alike, as the floor makes them in the whole map
                tracker.push(np.full(part.shape, math.log(FLOOR)))
    if not top > 0:
        raise AnalysisError("signal has no energy in the wavelet band")
    return tracker.path()
