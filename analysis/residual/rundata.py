"""One measured run prepared for the residual loop: the filtered rows of the equation-error regression
and the full-rate signals the candidate columns are built from.

Every column of the residual loop is ``L[g(theta, theta', t)]`` at the kept rows, where L is the one
zero-phase low-pass of :mod:`analysis.identification.regressors` (the same filter as the torque and the inertia and
Maxwell-slip columns) followed by the same triangle average. Nonlinear functions of the velocity
(sign, Stribeck, direction) are evaluated on a lightly filtered velocity ``velocity_fast`` (cutoff
4x the regression cutoff), then filtered by L: evaluating them on L's own velocity would smear the
low-speed region the Stribeck term lives in.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.regressors import (
    FilteredData,
    filtered_data,
    position_resolution,
    stop_columns,
    torque_at_samples,
    triangle_average,
    zero_phase_lowpass,
)
from hilbench.analysis.record import block_average  # noqa: F401 (re-exported: the loop's reduction)

FAST_VELOCITY_FACTOR = 8.0  # cutoff of ``velocity_fast`` relative to the regression cutoff (capped at 0.4 fs)
REST_SPREAD = 0.1  # rows within this fraction of a filter period (1/cutoff) of a rest phase are "at rest"
MAX_RATE = 2000.0  # Hz, see prepare_run
REST_WINDOW = 0.002  # s, half-width of the rest test (+-2 samples at 1 kHz, where the loop was tuned)


@dataclass
class RunData:
    """A run (position, torque) with its filtered regression rows.

    Attributes:
        position: measured path, shape (n,), rad (rotary) or m (linear).
        torque: motor torque / force, shape (n,), N*m or N, timing ``timing``.
        fs: sampling rate, Hz.
        data: :class:`hilbench.analysis.identification.regressors.FilteredData` at the kept rows.
        torque_filtered: L[torque aligned at samples] at full rate, shape (n,) (shifted for a delay).
        velocity_fast: lightly filtered velocity at full rate, shape (n,), rad/s or m/s.
        time: t_k - t_0 at full rate, shape (n,), s.
        timing: sample timing of ``torque`` (see :func:`hilbench.analysis.identification.regressors.held_torque`).
        rest: rows whose filter window touches a rest phase (:func:`rest_rows`): there Coulomb/Stribeck
            friction is a set-valued reaction, not a function of the state (``analysis.residual.design``).
    """

    position: np.ndarray
    torque: np.ndarray
    fs: float
    axis: str
    name: str
    data: FilteredData
    torque_filtered: np.ndarray
    velocity_fast: np.ndarray
    time: np.ndarray
    timing: str = "hold_next"
    rest: np.ndarray | None = None  # (r,) bool: the rotor is at rest around the row
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def rows(self) -> np.ndarray:
        return self.data.rows

    @property
    def n_rows(self) -> int:
        return int(self.data.rows.size)

    @property
    def t_rows(self) -> np.ndarray:
        """Time of the kept rows, s."""
        return self.time[self.data.rows]

    def filt(self, signal: np.ndarray) -> np.ndarray:
        """L[signal] triangle-averaged at the rows, shape (r,) (or (r, m) for signal (n, m))."""
        s = np.asarray(signal, float)
        if s.ndim == 1:
            return triangle_average(zero_phase_lowpass(s, self.fs, self.data.cutoff, self.data.order),
                                    self.data.rows)
        f = zero_phase_lowpass(np.ascontiguousarray(s.T), self.fs, self.data.cutoff, self.data.order)
        return np.ascontiguousarray(triangle_average(f, self.data.rows).T)

    def cached(self, key: tuple, make) -> np.ndarray:
        """Memoise a column block built by ``make()`` under ``key``."""
        if key not in self._cache:
            self._cache[key] = make()
        return self._cache[key]

    def stop(self, deltas: np.ndarray) -> np.ndarray:
        """Filtered stop-operator columns for the thresholds ``deltas``, shape (r, m)."""
        d = np.asarray(deltas, float)
        return self.cached(("stop", d.tobytes()), lambda: stop_columns(self.position, d, self.data))

    def stop_raw(self, deltas: np.ndarray) -> np.ndarray:
        """Unfiltered stop-operator deflections at full rate for the thresholds ``deltas``, shape (n, m)."""
        from hilbench.firmware_sim.engine.plant import stop_operator

        d = np.asarray(deltas, float)
        return self.cached(("stop_raw", d.tobytes()), lambda: stop_operator(self.position, d))

    def torque_rows(self, delay: float = 0.0) -> np.ndarray:
        """L[tau](t_k - delay*T) at the rows (linear interpolation for a fractional delay), shape (r,)."""
        if delay == 0:
            return self.data.torque
        idx = np.arange(self.torque_filtered.size, dtype=float)
        return np.interp(self.data.rows - float(delay), idx, self.torque_filtered)


def prepare_run(
    position: np.ndarray,
    torque: np.ndarray,
    fs: float,
    *,
    axis: str = "rotary",
    name: str = "run",
    cutoff: float | None = None,
    order: int = 4,
    decimation: int | None = None,
    timing: str = "hold_next",
    max_rate: float | None = MAX_RATE,
) -> RunData:
    """Filter a run for the residual loop.

    Args:
        position: measured path, shape (n,), rad or m.
        torque: torque or force, shape (n,), N*m or N; ``timing`` as in
            :func:`analysis.identification.regressors.held_torque` (``hold_next`` for a command held over a sample).
        fs: sampling rate, Hz. ``cutoff`` (Hz) default fs/20; ``decimation`` default fs/(2.5*cutoff)
            (the defaults of :class:`hilbench.analysis.identification.maxwell_fit.LipSettings`).
        max_rate: a faster run is first reduced to at most this rate (Hz) by :func:`block_average`, exact
            for a held torque. The loop was tuned and verified at 1-2 kHz; on 10 kHz runs of the same
            plant it under-detected velocity-dependent terms (the root cause is not established; the rest
            test's sample-count window was one part, now a time span). None keeps the full rate.
    """
    x = np.asarray(position, float).ravel()
    tau = np.asarray(torque, float).ravel()
    if x.shape != tau.shape:
        raise AnalysisError(f"position and torque differ in length: {x.size} and {tau.size}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(tau))):
        raise AnalysisError(f"{name}: position or torque contains NaN or inf")
    if not (np.isfinite(fs) and fs > 0):
        raise AnalysisError(f"sampling rate must be > 0, got {fs}")
    if max_rate is not None and fs > max_rate:
        x, tau, fs = block_average(x, tau, fs, int(np.ceil(fs / max_rate)), timing)
    cutoff = float(cutoff) if cutoff is not None else fs / 20.0
    dec = int(decimation) if decimation is not None else max(1, int(fs / (2.5 * cutoff)))
    data = filtered_data(x, tau, fs, cutoff, order=order, decimation=dec, timing=timing)
    tauf = zero_phase_lowpass(torque_at_samples(tau, timing), fs, cutoff, order)
    fast = min(FAST_VELOCITY_FACTOR * cutoff, 0.4 * fs)
    v_fast = np.gradient(zero_phase_lowpass(x, fs, fast, order), 1.0 / fs)
    return RunData(x, tau, float(fs), axis, name, data, tauf, v_fast, np.arange(x.size) / fs, timing,
                   rest_rows(x, data.rows, fs, cutoff))


def rest_rows(position: np.ndarray, rows: np.ndarray, fs: float, cutoff: float) -> np.ndarray:
    """Rows whose filter window touches a rest phase, shape (r,) bool.

    A sample is at rest when the measured path stays within 1.5 resolution steps over +-REST_WINDOW s; a
    row is flagged when any sample within +-REST_SPREAD/cutoff of it (at least 2 samples) is at rest:
    the low-pass spreads the set-valued reaction of a stick phase over that neighbourhood."""
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    width = 2 * max(2, int(round(REST_WINDOW * fs))) + 1  # a time span, so the speed threshold is rate-independent
    span = maximum_filter1d(position, width) - minimum_filter1d(position, width)
    still = (span <= 1.5 * position_resolution(position)).astype(np.uint8)
    half = max(2, int(round(REST_SPREAD * fs / cutoff)))
    return maximum_filter1d(still, 2 * half + 1)[rows].astype(bool)
