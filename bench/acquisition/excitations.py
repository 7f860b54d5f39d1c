"""Excitation signals for the bench: pure, seeded functions that return setpoint arrays.

Every generator returns an :class:`Excitation`: the setpoint ``u`` (A in current mode, rad/s in velocity
mode), its sample rate and a JSON-able protocol description that records the mode and every parameter,
so a run file can state exactly what was played.

Signals (``t = k / fs`` for sample ``k``):

- :func:`random_enveloped`: uniform noise, zero-phase Butterworth low-pass at ``cutoff`` (40 Hz by default),
  normalised to peak 1 and multiplied by :func:`rectangular_envelope` (the three-term series of a
  rectangular wave). This is the identification input of Tjahjowidodo (2012), Sec. 7.
- :func:`quadratic_chirp`: ``G·sin(π·a·t²)``, instantaneous frequency ``a·t`` Hz.
- :func:`sweep`: linear or logarithmic sine sweep from ``f_start`` to ``f_stop`` Hz.
- :func:`stepped_sine`: steps of ``A·sin(2π f t)`` over frequencies × amplitudes, each with a settle and a
  measure window of whole periods, plus the table of windows.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hilbench.common.units import MODE_UNITS

# Sanity bounds on |u| used when the caller gives no ``limit``; the device configuration should pass its own.
DEFAULT_LIMITS = {"current": 50.0, "velocity": 2000.0}

STEP_WINDOW_DTYPE = np.dtype(
    [
        ("frequency", "f8"),  # Hz, the frequency actually played (snapped to whole periods)
        ("frequency_requested", "f8"),  # Hz
        ("amplitude", "f8"),  # A or rad/s
        ("settle_start", "i8"),  # sample index, inclusive
        ("settle_stop", "i8"),  # sample index, exclusive
        ("measure_start", "i8"),
        ("measure_stop", "i8"),
        ("settle_periods", "i8"),
        ("measure_periods", "i8"),
    ]
)


@dataclass(frozen=True)
class Excitation:
    """A setpoint array and its description.

    Attributes:
        name: generator name (``random_enveloped``, ``quadratic_chirp``, ``sweep``, ``stepped_sine``).
        mode: ``"current"`` (u in A) or ``"velocity"`` (u in rad/s; m/s on a linear axis).
        fs: sample rate in Hz.
        u: setpoint, shape (n,), float64.
        params: every parameter needed to regenerate ``u`` (JSON-able).
        windows: stepped sine only: structured array of :data:`STEP_WINDOW_DTYPE`, one row per step.
    """

    name: str
    mode: str
    fs: float
    u: np.ndarray
    params: dict[str, Any]
    windows: np.ndarray | None = field(default=None)

    @property
    def t(self) -> np.ndarray:
        """Sample times in s, ``t[k] = k / fs``, shape (n,)."""
        return np.arange(self.u.size) / self.fs

    @property
    def unit(self) -> str:
        """Unit of ``u``: ``A`` (current mode) or ``rad/s`` (velocity mode)."""
        return MODE_UNITS[self.mode]

    def protocol(self) -> dict[str, Any]:
        """JSON-able protocol description: name, mode, unit, fs (Hz), n_samples and all parameters."""
        return {
            "name": self.name,
            "mode": self.mode,
            "unit": self.unit,
            "fs": self.fs,
            "n_samples": int(self.u.size),
            "params": dict(self.params),
        }


def _check_positive(**values: float) -> None:
    for key, value in values.items():
        number = isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
        if not (number and math.isfinite(value) and value > 0):
            raise ValueError(f"{key} must be a finite number > 0, got {value!r}")


def _check_mode(mode: str) -> None:
    if mode not in DEFAULT_LIMITS:  # the generators play currents or velocities (positions: reversal_path)
        raise ValueError(f"mode must be one of {sorted(DEFAULT_LIMITS)}, got {mode!r}")


def _n_samples(duration: float, fs: float) -> int:
    _check_positive(duration=duration, fs=fs)
    n = int(round(duration * fs))
    if n < 2:
        raise ValueError(f"duration {duration} s at fs {fs} Hz gives fewer than 2 samples")
    return n


def _check_limit(u: np.ndarray, mode: str, limit: float | None) -> None:
    bound = DEFAULT_LIMITS[mode] if limit is None else limit
    _check_positive(limit=bound)
    peak = float(np.max(np.abs(u))) if u.size else 0.0
    if peak > bound * (1 + 1e-12):
        raise ValueError(
            f"peak setpoint {peak:.6g} {MODE_UNITS[mode]} exceeds the {mode}-mode limit {bound:.6g} {MODE_UNITS[mode]}"
        )


def rectangular_envelope(t: np.ndarray, amplitude: float, period: float, offset: float = 0.0) -> np.ndarray:
    """Three-term Fourier series of a rectangular wave.

    ``e(t) = offset + (4·amplitude/π)·[sin(ωt) + sin(3ωt)/3 + sin(5ωt)/5]``, ``ω = 2π/period``: the first
    three non-zero harmonics of a square wave that switches between ``offset ± amplitude``.

    Args:
        t: times in s, any shape.
        amplitude: half peak-to-peak of the rectangular wave (units of the setpoint), >= 0.
        period: period in s, > 0.
        offset: mean value (units of the setpoint).

    Returns:
        Envelope with the shape of ``t``.
    """
    _check_positive(period=period)
    if not (math.isfinite(amplitude) and amplitude >= 0):
        raise ValueError(f"amplitude must be finite and >= 0, got {amplitude!r}")
    if not math.isfinite(offset):
        raise ValueError(f"offset must be finite, got {offset!r}")
    w = 2.0 * math.pi / period
    t = np.asarray(t, dtype=float)
    series = sum(np.sin(k * w * t) / k for k in (1, 3, 5))
    return offset + (4.0 * amplitude / math.pi) * series


def lowpass_uniform_noise(n: int, fs: float, cutoff: float, seed: int, order: int = 4) -> np.ndarray:
    """Uniform noise on [-1, 1], low-passed and normalised to peak 1.

    The filter is a Butterworth of ``order`` run forward and backward (``scipy.signal.sosfiltfilt``), so
    its magnitude response is ``|H(f)|² = 1 / (1 + (f/cutoff)^(2·order))`` (−6 dB at ``cutoff``) with zero
    phase.

    Args:
        n: number of samples.
        fs: sample rate in Hz.
        cutoff: cut-off in Hz, 0 < cutoff < fs/2.
        seed: seed of ``numpy.random.default_rng``; the same seed gives the same array.
        order: Butterworth order (1..10).

    Returns:
        Array of shape (n,), max |x| = 1.
    """
    from scipy import signal

    _check_positive(fs=fs, cutoff=cutoff)
    if cutoff >= fs / 2:
        raise ValueError(f"cutoff {cutoff} Hz must be below the Nyquist frequency {fs / 2} Hz")
    if not 1 <= order <= 10:
        raise ValueError(f"order must be in 1..10, got {order}")
    if n < 2:
        raise ValueError(f"need at least 2 samples, got {n}")
    # The filter starts from the first raw sample (up to 1) while the filtered noise has an rms of about
    # sqrt(cutoff/fs): filtering just the n samples left that start transient in the output, where it set the
    # peak (at sample 0) and so scaled the whole input down by the rate (rms 0.26 at 2 kHz, 0.091 at 10 kHz,
    # 0.061 at 20 kHz for 40 Hz). So the noise is drawn with a margin of ten time constants of the slowest pole
    # pair (about 1/(2.4 cutoff) s each) on both sides, filtered, and the margins dropped: e^-10 of the
    # transient is left and the n samples kept are stationary noise.
    margin = int(math.ceil(4 * fs / cutoff))
    rng = np.random.default_rng(seed)
    raw = rng.uniform(-1.0, 1.0, n + 2 * margin)
    sos = signal.butter(order, cutoff, btype="low", fs=fs, output="sos")
    x = signal.sosfiltfilt(sos, raw)[margin:margin + n]
    return x / np.max(np.abs(x))


def random_enveloped(
    duration: float,
    fs: float,
    *,
    amplitude: float,
    period: float,
    offset: float = 0.0,
    cutoff: float = 40.0,
    order: int = 4,
    seed: int = 0,
    mode: str = "current",
    limit: float | None = None,
) -> Excitation:
    """Random-enveloped excitation: ``u = noise(t) · e(t)``.

    ``noise`` is :func:`lowpass_uniform_noise` (peak 1) and ``e`` is :func:`rectangular_envelope`, so
    ``|u(t)| <= |e(t)|``.

    Args:
        duration: length in s; ``n = round(duration·fs)`` samples.
        fs: sample rate in Hz.
        amplitude, period, offset: envelope parameters (setpoint units, s, setpoint units).
        cutoff: low-pass cut-off in Hz (40 Hz by default, as in the paper).
        order: Butterworth order of the low-pass.
        seed: random seed (the same seed reproduces ``u`` exactly).
        mode: ``"current"`` (A) or ``"velocity"`` (rad/s).
        limit: largest allowed |u| in setpoint units (default :data:`DEFAULT_LIMITS`).
    """
    _check_mode(mode)
    n = _n_samples(duration, fs)
    t = np.arange(n) / fs
    u = lowpass_uniform_noise(n, fs, cutoff, seed, order) * rectangular_envelope(t, amplitude, period, offset)
    _check_limit(u, mode, limit)
    params = dict(
        duration=duration, amplitude=amplitude, period=period, offset=offset, cutoff=cutoff, order=order,
        seed=seed, limit=limit,
    )
    return Excitation("random_enveloped", mode, float(fs), u, params)


def quadratic_chirp(
    duration: float, fs: float, *, gain: float, a: float, mode: str = "current", limit: float | None = None
) -> Excitation:
    """Chirp ``u = G·sin(π·a·t²)``; phase ``π·a·t²`` so the instantaneous frequency is ``a·t`` Hz.

    Args:
        duration: length in s.
        fs: sample rate in Hz; ``a·duration`` must stay below fs/2.
        gain: G, peak setpoint (A or rad/s), > 0.
        a: sweep rate in Hz/s, > 0 (the paper: 0.1 Hz/s).
        mode, limit: see :func:`random_enveloped`.
    """
    _check_mode(mode)
    n = _n_samples(duration, fs)
    _check_positive(gain=gain, a=a)
    if a * duration >= fs / 2:
        raise ValueError(f"final frequency a·duration = {a * duration} Hz reaches Nyquist ({fs / 2} Hz)")
    t = np.arange(n) / fs
    u = gain * np.sin(math.pi * a * t**2)
    _check_limit(u, mode, limit)
    params = dict(duration=duration, gain=gain, a=a, limit=limit)
    return Excitation("quadratic_chirp", mode, float(fs), u, params)


def sweep(
    duration: float,
    fs: float,
    *,
    gain: float,
    f_start: float,
    f_stop: float,
    method: str = "linear",
    mode: str = "current",
    limit: float | None = None,
) -> Excitation:
    """Sine sweep ``u = G·sin(φ(t))`` from ``f_start`` to ``f_stop`` Hz over ``duration`` (T) s.

    - linear: ``f(t) = f0 + (f1 − f0)·t/T``
    - log:    ``f(t) = f0·(f1/f0)^(t/T)``

    Built with ``scipy.signal.chirp(..., phi=-90)`` so ``u(0) = 0``.
    """
    from scipy import signal

    _check_mode(mode)
    n = _n_samples(duration, fs)
    _check_positive(gain=gain, f_start=f_start, f_stop=f_stop)
    if method not in ("linear", "log"):
        raise ValueError(f"method must be 'linear' or 'log', got {method!r}")
    if max(f_start, f_stop) >= fs / 2:
        raise ValueError(f"sweep frequencies must stay below the Nyquist frequency {fs / 2} Hz")
    t = np.arange(n) / fs
    scipy_method = "linear" if method == "linear" else "logarithmic"
    u = gain * signal.chirp(t, f0=f_start, t1=duration, f1=f_stop, method=scipy_method, phi=-90.0)
    _check_limit(u, mode, limit)
    params = dict(duration=duration, gain=gain, f_start=f_start, f_stop=f_stop, method=method, limit=limit)
    return Excitation("sweep", mode, float(fs), u, params)


def stepped_sine(
    fs: float,
    *,
    frequencies: Sequence[float],
    amplitudes: Sequence[float],
    settle_periods: int = 5,
    measure_periods: int = 10,
    mode: str = "current",
    limit: float | None = None,
) -> Excitation:
    """Stepped sine over amplitudes × frequencies (amplitude is the outer loop).

    Each step plays ``A·sin(2π·f·(k − k0)/fs)`` from its first sample ``k0``: ``settle_periods`` whole
    periods (transient, to discard), then ``measure_periods`` whole periods (to analyse). To make both
    windows hold whole periods exactly, the frequency is snapped: with ``g = gcd(settle, measure)``, a
    block of ``g`` periods gets ``B = round(g·fs/f)`` samples and the played frequency is ``g·fs/B``
    (relative change <= 1/(2·g·fs/f)). Steps start and end at phase 0, so the signal is continuous.

    Returns:
        :class:`Excitation` whose ``windows`` is a structured array (:data:`STEP_WINDOW_DTYPE`) with, per
        step, the played and requested frequency (Hz), amplitude, and start/stop (exclusive) sample of the
        settle and measure windows.
    """
    _check_mode(mode)
    _check_positive(fs=fs)
    freqs = [float(f) for f in frequencies]
    amps = [float(a) for a in amplitudes]
    if not freqs or not amps:
        raise ValueError("stepped_sine needs at least one frequency and one amplitude")
    for f in freqs:
        _check_positive(frequency=f)
        if f >= fs / 4:  # fewer than 4 samples per period would not resolve the sine's amplitude
            raise ValueError(f"frequency {f} Hz is too close to Nyquist: keep it below fs/4 = {fs / 4} Hz")
    for a in amps:
        _check_positive(amplitude=a)
    if int(settle_periods) != settle_periods or settle_periods < 0:
        raise ValueError(f"settle_periods must be a whole number >= 0, got {settle_periods!r}")
    if int(measure_periods) != measure_periods or measure_periods < 1:
        raise ValueError(f"measure_periods must be a whole number >= 1, got {measure_periods!r}")
    settle_periods, measure_periods = int(settle_periods), int(measure_periods)
    g = math.gcd(settle_periods, measure_periods)

    rows = []
    pieces = []
    start = 0
    for amp in amps:
        for f_req in freqs:
            block = max(1, int(round(g * fs / f_req)))
            f = g * fs / block
            n_settle = settle_periods // g * block
            n_measure = measure_periods // g * block
            k = np.arange(n_settle + n_measure)
            # k·f/fs = k·g/block exactly periodic in block samples; mod keeps the phase argument small.
            pieces.append(amp * np.sin(2.0 * math.pi * ((k * g) % block) / block))
            rows.append(
                (f, f_req, amp, start, start + n_settle, start + n_settle, start + n_settle + n_measure,
                 settle_periods, measure_periods)
            )
            start += n_settle + n_measure
    u = np.concatenate(pieces)
    _check_limit(u, mode, limit)
    windows = np.array(rows, dtype=STEP_WINDOW_DTYPE)
    params = dict(
        frequencies=freqs, amplitudes=amps, settle_periods=settle_periods, measure_periods=measure_periods,
        limit=limit,
    )
    return Excitation("stepped_sine", mode, float(fs), u, params, windows)


#: Turning points of a reversal path: the sample at which the path arrives at each point (index into the
#: setpoint array; the hold that follows starts there) and the point itself (the path's unit).
TURNING_POINT_DTYPE = np.dtype([("index", "i8"), ("position", "f8")])


def nested_reversal_points(amplitudes: Sequence[float], close_inner: bool = True,
                           repeats: int = 1) -> np.ndarray:
    """Turning points of a virgin ramp followed by nested reversals (Al-Bender & Symens' presliding test).

    With amplitudes ``A1 >= A2 >= ... >= An > 0`` the turning points are ``T_i = (-1)**(i+1) * A_i``. The path
    starts at rest at 0, ramps to ``T1`` (the virgin curve), then visits ``T2 .. Tn``: each reversal is nested
    inside the previous one. With ``close_inner`` it then retraces ``T_{n-1} .. T1``, closing the inner loops
    one at a time from the innermost (each return to an earlier turning point wipes out the loops inside it);
    without, it returns to ``T1`` at once. That cycle (from ``T1`` back to ``T1``) is played ``repeats`` times.
    Returns the points, starting with 0, shape (m,).
    """
    a = np.asarray(amplitudes, dtype=np.float64)
    if a.ndim != 1 or a.size < 1 or not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise ValueError(f"amplitudes must be a non-empty list of finite values > 0, got {amplitudes!r}")
    if np.any(np.diff(a) > 0):
        raise ValueError(f"nested reversals need non-increasing amplitudes (A1 >= A2 >= ...), got {a.tolist()}")
    turning = a * np.where(np.arange(a.size) % 2 == 0, 1.0, -1.0)
    back = turning[-2::-1] if close_inner else turning[:1]
    cycle = np.concatenate([turning[1:], back]) if a.size > 1 else np.empty(0)
    return np.concatenate([[0.0], turning[:1], np.tile(cycle, repeats)])


def reversal_path_lengths(points: np.ndarray, rate: float, settle: float, fs: float) -> tuple[np.ndarray, int]:
    """Samples of each ramp between consecutive ``points`` at ``rate`` (unit/s; at least one) and of each
    hold (``settle`` s: one at rest before the first ramp, one after every ramp): ``(ramp_samples, hold)``."""
    _check_positive(rate=rate, fs=fs)
    if not (math.isfinite(settle) and settle >= 0):
        raise ValueError(f"settle must be a finite number of seconds >= 0, got {settle!r}")
    ramps = np.maximum(1, np.round(np.abs(np.diff(points)) / rate * fs)).astype(np.int64)
    return ramps, int(round(settle * fs))


def reversal_path(points: np.ndarray, rate: float, settle: float, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Piecewise-linear displacement through ``points`` at constant speed ``rate`` (unit/s), holding each
    point (and the start) for ``settle`` s: the quasi-static reference of a presliding test.

    Ramp j has ``n_j = max(1, round(|p_{j+1} - p_j| / rate * fs))`` samples ``p_j + (p_{j+1} - p_j) * (k+1)/n_j``,
    k = 0..n_j-1, so it ends exactly on the point. Returns ``(u, turning)``: the path, shape (n,), and the
    :data:`TURNING_POINT_DTYPE` table of the points (index of the sample that reaches each point; the
    start has index 0).
    """
    points = np.asarray(points, dtype=np.float64)
    ramps, hold = reversal_path_lengths(points, rate, settle, fs)
    pieces = [np.full(hold, points[0])]
    turning = np.zeros(points.size, dtype=TURNING_POINT_DTYPE)
    turning["position"] = points
    n = hold
    for j, m in enumerate(ramps):
        k = np.arange(1, m + 1) / m
        pieces.append(points[j] + (points[j + 1] - points[j]) * k)
        pieces.append(np.full(hold, points[j + 1]))
        n += m
        turning["index"][j + 1] = n - 1
        n += hold
    return np.concatenate(pieces), turning
