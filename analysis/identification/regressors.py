"""Regressors of the linear-in-parameters friction model, filtered equally and zero-phase.

Model (rotary: rad, N*m; linear: m, N):

    J*theta'' + sum_i k_i*S_Delta_i[theta] + b*theta' + Fc*sign(theta') + c0 + K*theta = tau

S_Delta is the stop operator (science.md §1), computed by the C engine (firmware_sim.engine.plant).

Filtering (documented choice: *filtered formulation*, not integrated): one zero-phase low-pass L
(Butterworth, forward-backward) is applied to tau and to every regressor column. Because L is linear
and time-invariant, L[theta''] = D^2 L[theta], so the derivatives are central differences D of the
filtered position; raw double differences of the quantised encoder signal are never used. The
nonlinear columns (stop operator, sign) are computed on the measured path and then filtered by the
same L. Samples within ``edge`` of either end (filter start-up, where L of the truncated record
no longer commutes with D) are dropped, and the rows are then thinned by ``decimation``: the
equation holds at every row, so thinning only reduces the coupling between neighbouring residuals
(see ``effective_sample_count``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from hilbench.analysis.errors import AnalysisError

TORQUE_TIMINGS = ("hold_next", "hold_previous", "instant")


def held_torque(torque: np.ndarray, timing: str) -> np.ndarray:
    """Torque held over [t_k, t_k+1) (the plant's input convention), shape (n,), from a record whose
    sample k is: ``hold_next`` the torque held over [t_k, t_k+1) (a command); ``hold_previous`` the
    mean over [t_k-1, t_k) (a current sampled at t_k); ``instant`` the torque at t_k."""
    tau = np.asarray(torque, float)
    if timing == "hold_next":
        return tau.copy()
    if timing == "hold_previous":
        return np.append(tau[1:], tau[-1])
    if timing == "instant":
        return np.append(0.5 * (tau[:-1] + tau[1:]), tau[-1])
    raise AnalysisError(f"torque timing must be one of {', '.join(TORQUE_TIMINGS)}, got {timing!r}")


def torque_at_samples(torque: np.ndarray, timing: str) -> np.ndarray:
    """Torque aligned with the central second difference at t_k, shape (n,).

    For a held input, theta[k+1] - 2 theta[k] + theta[k-1] = T^2/(2J) (tau_h[k-1] + tau_h[k]) for a
    pure inertia, so the aligned torque is the mean of the two held values around t_k. Without this
    half-sample shift, J is biased at the excitation's upper frequencies.
    """
    h = held_torque(torque, timing)
    return np.concatenate([h[:1], 0.5 * (h[:-1] + h[1:])])


def zero_phase_lowpass(x: np.ndarray, fs: float, cutoff: float, order: int = 4) -> np.ndarray:
    """Butterworth low-pass of ``order`` at ``cutoff`` (Hz), applied forward and backward along the
    last axis (zero phase, magnitude |H|^2), on an odd extension of ``edge_samples`` at each end
    (built here: scipy's own padding is several times slower on many columns)."""
    from scipy import signal

    if not 0 < cutoff < fs / 2:
        raise AnalysisError(f"filter cutoff {cutoff} Hz must be in (0, {fs / 2}) Hz (Nyquist)")
    x = np.asarray(x, float)
    pad = min(edge_samples(fs, cutoff), x.shape[-1] - 1)
    first, last = x[..., :1], x[..., -1:]
    ext = np.concatenate([2 * first - x[..., pad:0:-1], x, 2 * last - x[..., -2 : -pad - 2 : -1]], axis=-1)
    sos, zi = lowpass_design(order, cutoff, fs)
    sos = sos.copy()  # sosfilt's typed memoryview needs a writable buffer; the cached design stays read-only
    # scipy.signal.sosfiltfilt(sos, ext, axis=-1, padtype=None), less its design of zi on every call: the same
    # arithmetic, bit for bit (tests/analysis/identification/test_lowpass_design.py)
    zi = zi.reshape(zi.shape[0], *([1] * (ext.ndim - 1)), 2)
    y, _ = signal.sosfilt(sos, ext, axis=-1, zi=zi * ext[..., :1])
    y, _ = signal.sosfilt(sos, y[..., ::-1], axis=-1, zi=zi * y[..., -1:])
    return y[..., ::-1][..., pad : pad + x.shape[-1]]


@lru_cache(maxsize=64)
def lowpass_design(order: int, cutoff: float, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """(sos, zi): the Butterworth low-pass of ``order`` at ``cutoff`` Hz for ``fs`` Hz and its steady-state initial
    conditions (scipy.signal.sosfilt_zi), read-only. Cached: designing them took 3.4 + 0.9 ms against 0.4 ms for
    filtering a 2 s record at 1 kHz, and an identification filters about 24 times with the same few designs."""
    from scipy import signal

    sos = signal.butter(order, cutoff, fs=fs, output="sos")
    zi = signal.sosfilt_zi(sos)
    sos.setflags(write=False)
    zi.setflags(write=False)
    return sos, zi


def edge_samples(fs: float, cutoff: float) -> int:
    """Filter start-up length: 10 time constants of the Butterworth's slowest pole, 1/(0.38*2*pi*fc)."""
    return int(np.ceil(10.0 * fs / (0.38 * 2 * np.pi * cutoff))) + 2


def position_resolution(position: np.ndarray) -> float:
    """Resolution of a measured path (rad or m): the larger of the quantisation step (smallest nonzero
    increment) and the white-noise level from second differences, 1.4826*MAD(D^2 x)/sqrt(6)."""
    x = np.asarray(position, float)
    dx = np.abs(np.diff(x))
    nz = dx[dx > 0]
    quantum = float(nz.min()) if nz.size else 0.0
    d2 = np.diff(x, 2)
    noise = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / np.sqrt(6.0)
    return max(quantum, noise)


def reversal_travels(position: np.ndarray, hysteresis: float, max_points: int = 20_000) -> np.ndarray:
    """Travels between successive turning points of a path (same unit), ignoring reversals smaller
    than ``hysteresis``. The last entry is the travel since the last turning point. The path is
    thinned to at most ``max_points`` (only the large travels matter here)."""
    x = np.asarray(position, float)
    x = x[:: max(1, x.size // max_points)]
    travels = []
    anchor = extreme = x[0]
    direction = 0
    for v in x.tolist():
        if direction == 0:
            if abs(v - anchor) > hysteresis:
                direction = 1 if v > anchor else -1
                extreme = v
        elif (v - extreme) * direction > 0:
            extreme = v
        elif (extreme - v) * direction > hysteresis:
            travels.append(abs(extreme - anchor))
            anchor, extreme, direction = extreme, v, -direction
    travels.append(abs(extreme - anchor))
    return np.asarray(travels)


def threshold_grid(
    position: np.ndarray, n: int, delta_range: tuple[float, float] | None = None
) -> np.ndarray:
    """``n`` log-spaced candidate thresholds Delta (rad or m), shape (n,).

    Automatic range: from 2x the position resolution to half the largest travel between reversals
    (an element with 2*Delta above every travel never slips after a reversal, so it is only seen as
    a linear spring).
    """
    if n < 1:
        raise AnalysisError(f"need at least one candidate threshold, got {n}")
    if delta_range is None:
        res = position_resolution(position)
        travels = reversal_travels(position, hysteresis=max(4 * res, 1e-15))
        hi = 0.5 * float(travels.max()) if travels.size else 0.0
        lo = max(2.0 * res, hi * 1e-5)
        if not hi > lo:
            raise AnalysisError(
                f"the position hardly moves (largest travel {2 * hi:.3g}, resolution {res:.3g}): "
                "the friction thresholds are unidentifiable; excite a larger displacement"
            )
    else:
        lo, hi = map(float, delta_range)
        if not (0 < lo < hi and np.isfinite(hi)):
            raise AnalysisError(f"delta_range must satisfy 0 < low < high, got {delta_range}")
    return np.geomspace(lo, hi, n)


@dataclass
class FilteredData:
    """Filtered, edge-trimmed and thinned signals (rows r), each shape (r,), and the filter settings."""

    torque: np.ndarray  # L[tau], N*m or N
    acceleration: np.ndarray  # D^2 L[theta], rad/s^2 or m/s^2
    velocity: np.ndarray  # D L[theta], rad/s or m/s
    position: np.ndarray  # L[theta] (triangle-averaged), rad or m
    sign: np.ndarray  # L[sign(D L[theta])] (triangle-averaged)
    rows: np.ndarray  # indices of the kept samples in the original record
    fs: float
    cutoff: float
    order: int
    decimation: int


def filtered_data(
    position: np.ndarray,
    torque: np.ndarray,
    fs: float,
    cutoff: float,
    *,
    order: int = 4,
    decimation: int = 1,
    timing: str = "hold_next",
) -> FilteredData:
    """Filter tau and the linear regressors with the same zero-phase L; see the module docstring."""
    x = np.asarray(position, float)
    tau = torque_at_samples(torque, timing)
    dt = 1.0 / fs
    both = zero_phase_lowpass(np.vstack([x, tau]), fs, cutoff, order)
    xf, tauf = both[0], both[1]
    v = np.gradient(xf, dt)  # (x[k+1] - x[k-1])/(2T) inside
    a = np.zeros_like(xf)
    a[1:-1] = (xf[2:] - 2.0 * xf[1:-1] + xf[:-2]) / dt**2  # 3-point, not gradient twice (5-point)
    sgn = zero_phase_lowpass(np.sign(v), fs, cutoff, order)
    edge = edge_samples(fs, cutoff)
    rows = np.arange(edge, x.size - edge, max(1, int(decimation)))
    if rows.size < 10:
        raise AnalysisError(
            f"run too short: {x.size} samples leave {rows.size} rows after dropping {edge} filter start-up "
            f"samples at each end (cutoff {cutoff:g} Hz); record longer or raise the cutoff"
        )
    return FilteredData(
        tauf[rows],
        a[rows],
        v[rows],
        triangle_average(xf, rows),
        triangle_average(sgn, rows),
        rows,
        fs,
        cutoff,
        order,
        max(1, int(decimation)),
    )


def triangle_average(x: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(x[k-1] + 10 x[k] + x[k+1])/12 at ``rows`` along the last axis.

    The central second difference of the position equals the triangle-weighted mean (width 2T) of
    the acceleration, hence of (tau - friction)/J. A force sampled at t_k must be averaged the same
    way; this 3-tap rule has the triangle's response 1 - (wT)^2/12 + O((wT)^4). Without it the
    presliding stiffness K leaks into the inertia as K*T^2/12 (+11 % on the DC motor at 1 kHz).
    """
    return (x[..., rows - 1] + 10.0 * x[..., rows] + x[..., rows + 1]) / 12.0


def stop_columns(position: np.ndarray, deltas: np.ndarray, data: FilteredData) -> np.ndarray:
    """Filtered, triangle-averaged stop-operator regressors L[S_Delta_j[theta]] at the rows, (r, m)."""
    from hilbench.firmware_sim.engine.plant import stop_operator

    if np.size(deltas) == 0:
        return np.empty((data.rows.size, 0))
    s = stop_operator(np.asarray(position, float), np.asarray(deltas, float))
    sf = zero_phase_lowpass(np.ascontiguousarray(s.T), data.fs, data.cutoff, data.order)
    return np.ascontiguousarray(triangle_average(sf, data.rows).T)


def effective_sample_count(residual: np.ndarray, max_lag: int = 200) -> float:
    """n_eff = n / (1 + 2*sum_k rho_k) from the residual autocorrelation rho_k, summed up to the first
    lag where rho_k <= 0 (initial-positive-sequence rule). Never above n."""
    r = np.asarray(residual, float) - np.mean(residual)
    n = r.size
    denom = float(r @ r)
    if n < 3 or denom == 0:
        return float(n)
    total = 0.0
    for k in range(1, min(max_lag, n - 1)):
        rho = float(r[:-k] @ r[k:]) / denom
        if rho <= 0:
            break
        total += rho
    return float(n / (1.0 + 2.0 * total))
