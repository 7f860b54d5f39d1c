"""AFRF: absolute frequency response of the 1st-3rd harmonic under stepped-sine excitation.

science.md §5 (Tjahjowidodo 2012, Fig 13): drive ``u(t) = G*sin(2*pi*f*t)``, discard the transient, and over
whole periods of the steady state take the magnitude of the displacement at f, 2f and 3f. The AFRF is not
divided by G, so curves at different G show the level directly.

Harmonic phasor convention (used everywhere here): over P whole periods of n samples,

    c_k = (2/n) * sum_i x_i * exp(-1j*k*2*pi*f*t_i),   t_i = i/fs,

so ``x`` contains ``|c_k|*cos(k*2*pi*f*t + angle(c_k))``; ``|c_k|`` is the peak amplitude of harmonic k. With
P integer this is exactly rFFT bin k*P, so whole periods of other harmonics leak nothing.

Sources of an AFRF:

- :func:`simulate_afrf`: stepped sine on a :class:`firmware_sim.engine.plant.PlantParams` model with the C engine,
  one independent simulation per (amplitude, frequency) cell, parallel over processes. The sample rate is
  chosen per frequency (``samples_per_period``), since the plant's dt is free.
- :func:`afrf_from_run`: a measured stepped-sine run file (``hilbench run`` with the ``stepped_sine``
  protocol; its ``/protocol/step_windows`` table gives each step's played frequency, amplitude and the
  settle/measure sample windows).

:func:`afrf_error` compares two AFRFs per amplitude and harmonic order; :func:`plot_afrf` draws the
paper-style figure. Model builders: :func:`coulomb_system` and :func:`closed_form_equivalent` (the
equivalent m*x'' + F_k(x) + F_d(x') (+ k*x) = F with tabulated curves from the closed forms of science.md §3).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.firmware_sim.engine.plant import PlantParameterError, PlantParams, simulate, stiffest_eigenvalue

#: Relative tolerance on "the window holds a whole number of periods" (n*f/fs within this of an integer).
WHOLE_PERIOD_TOL = 1e-6
#: |lambda|*h that the automatic sub-step choice keeps below (accuracy, well inside RK4's stability limit).
SUBSTEP_LAMBDA_H = 0.5


# ---- harmonics over whole periods ----------------------------------------------------------------------


def whole_periods(n_samples: int, fs: float, f: float) -> int:
    """Number of whole periods of ``f`` (Hz) in ``n_samples`` at ``fs`` (Hz).

    Raises:
        AnalysisError: the window holds fewer than one period, or not a whole number of periods (relative
            tolerance :data:`WHOLE_PERIOD_TOL`).
    """
    if not (math.isfinite(fs) and fs > 0 and math.isfinite(f) and f > 0):
        raise AnalysisError(f"sample rate and frequency must be > 0 and finite, got fs={fs}, f={f}")
    p = n_samples * f / fs
    whole = round(p)
    if p < 1.0 - WHOLE_PERIOD_TOL:
        raise AnalysisError(f"{n_samples} samples at {fs:g} Hz hold {p:.3g} periods of {f:g} Hz; "
                            "need at least one whole period")
    if abs(p - whole) > WHOLE_PERIOD_TOL * max(p, 1.0):
        raise AnalysisError(f"{n_samples} samples at {fs:g} Hz hold {p:.6f} periods of {f:g} Hz, not a whole "
                            f"number; cut the window to {round(whole * fs / f)} samples")
    return whole


def _drift_slope(x: np.ndarray, periods: int) -> float:
    """Drift per sample c of ``x = periodic + c*i``, exactly, from the means of the first and last
    whole-period blocks (needs a block length that is an integer number of samples); 0 if impossible."""
    n = x.size
    q = _block_periods(n, periods)
    nb = periods // q
    if nb < 2:
        return 0.0
    m = n // nb
    return float((x[-m:].mean() - x[:m].mean()) / (n - m))


def _block_periods(n: int, periods: int) -> int:
    """Smallest q dividing ``periods`` such that q periods are a whole number of samples."""
    for q in range(1, periods + 1):
        if periods % q == 0 and (n * q) % periods == 0:
            return q
    return periods


def harmonic_phasors(x: np.ndarray, fs: float, f: float, n_harmonics: int = 3,
                     detrend: bool = True) -> np.ndarray:
    """Complex amplitudes c_k of harmonics k = 1..n_harmonics of ``f`` over a whole-period window.

    ``c_k = (2/n)*sum_i x_i*exp(-1j*2*pi*k*f*i/fs)`` (module docstring), computed as rFFT bin ``k*P`` with
    P = n*f/fs whole periods, which is exact.

    Args:
        x: samples, shape (n,) (or (..., n): the last axis is time), any unit (rad, m, N*m).
        fs: sample rate, Hz.
        f: fundamental, Hz; the window must hold P >= 1 whole periods.
        n_harmonics: number of harmonics; k*f must stay below fs/2.
        detrend: remove a constant drift ``c*t`` (a free mass creeping under friction) first. c is
            estimated exactly for ``periodic + c*t`` from the means of the first and last whole-period
            blocks; with a single block there is nothing to compare and no drift is removed.
    Returns:
        complex array (..., n_harmonics), unit of ``x``.
    Raises:
        AnalysisError: not whole periods, fewer than one period, a harmonic at or above Nyquist, NaN/inf.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim < 1 or x.shape[-1] < 2:
        raise AnalysisError("harmonics need at least 2 samples")
    if not np.all(np.isfinite(x)):
        raise AnalysisError("harmonics: signal contains NaN or inf")
    if int(n_harmonics) != n_harmonics or n_harmonics < 1:
        raise AnalysisError(f"n_harmonics must be an integer >= 1, got {n_harmonics!r}")
    n = x.shape[-1]
    periods = whole_periods(n, fs, f)
    if n_harmonics * periods >= n / 2:
        raise AnalysisError(f"harmonic {n_harmonics} of {f:g} Hz is at or above Nyquist ({fs / 2:g} Hz)")
    if detrend:
        flat = x.reshape(-1, n)
        slopes = np.array([_drift_slope(row, periods) for row in flat]).reshape(x.shape[:-1] + (1,))
        x = x - slopes * np.arange(n)
    bins = periods * np.arange(1, n_harmonics + 1)
    return dft_bins(x, bins) * (2.0 / n)


#: samples per block of :func:`dft_bins`
DFT_BLOCK = 1 << 16


def dft_bins(x: np.ndarray, bins: np.ndarray, block: int = DFT_BLOCK) -> np.ndarray:
    """DFT of ``x`` (last axis, n samples) at the integer ``bins`` only: ``X_k = sum_i x_i*exp(-2j*pi*k*i/n)``.

    The same numbers as ``np.fft.rfft(x)[..., bins]`` to rounding, in O(n*len(bins)) time and one block of
    memory: the twiddles of one block, exp(-2j*pi*(k*b mod n)/n) for b < block, are the same for every block
    up to the factor exp(-2j*pi*(k*i0 mod n)/n) of the block's first sample i0 (exact integer phases, so
    nothing accumulates). A whole-window rFFT cost n*log(n) and n/2 complex values for three bins: on a
    one-hour stepped sine its windows of 12 M samples made the analysis's cost per sample 1.4x a minute's.

    Args:
        x: real samples, shape (..., n).
        bins: integer frequency bins, shape (K,), each in [0, n).
    Returns:
        complex array (..., K).
    """
    x = np.asarray(x, dtype=float)
    bins = np.asarray(bins, dtype=np.int64)
    n = x.shape[-1]
    b = np.arange(min(block, n), dtype=np.int64)
    base = np.exp((-2j * np.pi / n) * ((bins[:, None] * b[None, :]) % n))  # (K, block)
    out = np.zeros(x.shape[:-1] + (bins.size,), dtype=complex)
    for i0 in range(0, n, block):
        seg = x[..., i0:i0 + block]
        start = np.exp((-2j * np.pi / n) * ((bins * i0) % n))  # (K,)
        out += (seg @ base[:, :seg.shape[-1]].T) * start
    return out


def harmonics(x: np.ndarray, fs: float, f: float, n_harmonics: int = 3, detrend: bool = True) -> np.ndarray:
    """Magnitudes |c_k| (peak amplitude, unit of ``x``) of harmonics 1..n_harmonics of ``f`` over whole
    periods; shape (..., n_harmonics). See :func:`harmonic_phasors`."""
    return np.abs(harmonic_phasors(x, fs, f, n_harmonics, detrend))


def period_convergence(x: np.ndarray, fs: float, f: float, n_harmonics: int = 3) -> float:
    """Steady-state check: max over consecutive whole-period blocks and harmonics of
    ``| |c_k(block j+1)| - |c_k(block j)| | / |c_1(window)|`` (dimensionless).

    Blocks are single periods when a period is a whole number of samples, otherwise the smallest whole
    number of periods that is. NaN when the window holds a single block. A drift removed over the whole
    window first (as :func:`harmonic_phasors`)."""
    x = np.asarray(x, dtype=float)
    n = x.size
    periods = whole_periods(n, fs, f)
    q = _block_periods(n, periods)
    nb = periods // q
    if nb < 2:
        return math.nan
    x = x - _drift_slope(x, periods) * np.arange(n)
    blocks = x.reshape(nb, n // nb)
    mags = harmonics(blocks, fs, f, n_harmonics, detrend=False)
    ref = float(np.abs(harmonic_phasors(x, fs, f, 1, detrend=False))[0])
    if ref == 0.0:
        return 0.0 if np.all(mags == mags[0]) else math.inf
    return float(np.max(np.abs(np.diff(mags, axis=0))) / ref)


# ---- result and comparison ------------------------------------------------------------------------------


@dataclass
class AfrfResult:
    """An AFRF on an amplitude x frequency grid.

    Attributes:
        amplitudes: drive amplitudes G, shape (n_amp,), in ``amplitude_unit`` (N*m or N for a simulated
            torque/force; the setpoint unit A or rad/s for a measured run).
        frequencies: played frequencies, Hz, shape (n_freq,).
        response: complex harmonic phasors c_k of the displacement, shape (n_amp, n_freq, n_harmonics), in
            ``displacement_unit``; NaN where a step is missing (an aborted run).
        drive: complex first-harmonic phasor of the applied torque/force, shape (n_amp, n_freq), N*m (N);
            ``response[..., 0]/drive`` is the first-harmonic FRF. NaN if the run has no torque channel.
        convergence: :func:`period_convergence` of each cell, shape (n_amp, n_freq).
        amplitude_unit, displacement_unit, drive_unit: unit strings.
        label: what was measured or simulated.
        settings: how (JSON-able).
        warnings: one line per thing the input cannot support (e.g. no amplitude reaches break-away).
    """

    amplitudes: np.ndarray
    frequencies: np.ndarray
    response: np.ndarray
    drive: np.ndarray
    convergence: np.ndarray
    amplitude_unit: str = "N*m"
    displacement_unit: str = "rad"
    drive_unit: str = "N*m"
    label: str = ""
    settings: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)  # what the input cannot support (one line each)

    @property
    def magnitudes(self) -> np.ndarray:
        """|c_k|, shape (n_amp, n_freq, n_harmonics), ``displacement_unit`` (peak amplitude)."""
        return np.abs(self.response)

    @property
    def n_harmonics(self) -> int:
        return int(self.response.shape[-1])

    def to_dict(self) -> dict:
        """JSON-friendly dict (magnitudes and phases in rad, NaN as None)."""

        def clean(a):
            a = np.asarray(a, dtype=float)
            return [clean(v) for v in a] if a.ndim else (None if not math.isfinite(a) else float(a))

        return {
            "label": self.label,
            "amplitudes": clean(self.amplitudes),
            "amplitude_unit": self.amplitude_unit,
            "frequencies": clean(self.frequencies),
            "frequency_unit": "Hz",
            "magnitude": clean(self.magnitudes),
            "magnitude_unit": self.displacement_unit,
            "phase": clean(np.angle(self.response)),
            "phase_unit": "rad",
            "drive_magnitude": clean(np.abs(self.drive)),
            "drive_unit": self.drive_unit,
            "convergence": clean(self.convergence),
            "settings": self.settings,
            "warnings": list(self.warnings),
            "shape": "magnitude[amplitude][frequency][harmonic-1]",
        }


ERROR_DTYPE = np.dtype([("amplitude", "f8"), ("harmonic", "i8"), ("relative_rms", "f8"), ("rms_db", "f8")])


def afrf_error(reference: AfrfResult, other: AfrfResult) -> np.ndarray:
    """Error of ``other`` against ``reference``, one row per amplitude and harmonic order.

    For amplitude a and harmonic k, over the frequencies where both are finite:

    - ``relative_rms = ||(|O_k| - |R_k|)||_2 / ||R_k||_2`` (dimensionless),
    - ``rms_db = sqrt(mean((20*log10(|O_k|/|R_k|))^2))`` (dB; the distance on the log-log AFRF plot).

    A harmonic the reference does not have (2f of a symmetric loop) has both dominated by numerical noise.

    Returns:
        structured array of :data:`ERROR_DTYPE`, shape (n_amp*n_harmonics,), amplitude-major.
    Raises:
        AnalysisError: different amplitude or frequency grids (relative 1e-6) or harmonic counts.
    """
    r, o = reference, other
    for name in ("amplitudes", "frequencies"):
        a, b = np.asarray(getattr(r, name)), np.asarray(getattr(o, name))
        if a.shape != b.shape or not np.allclose(a, b, rtol=1e-6, atol=0):
            raise AnalysisError(f"afrf_error: the two AFRFs have different {name} ({a.tolist()} vs {b.tolist()})")
    if r.n_harmonics != o.n_harmonics:
        raise AnalysisError(f"afrf_error: {r.n_harmonics} vs {o.n_harmonics} harmonics")
    rm, om = r.magnitudes, o.magnitudes
    rows = []
    for i, amp in enumerate(r.amplitudes):
        for k in range(r.n_harmonics):
            a, b = rm[i, :, k], om[i, :, k]
            ok = np.isfinite(a) & np.isfinite(b)
            if not ok.any():
                rows.append((amp, k + 1, math.nan, math.nan))
                continue
            a, b = a[ok], b[ok]
            norm = float(np.linalg.norm(a))
            rel = float(np.linalg.norm(b - a)) / norm if norm > 0 else math.inf
            pos = (a > 0) & (b > 0)
            db = float(np.sqrt(np.mean((20 * np.log10(b[pos] / a[pos])) ** 2))) if pos.any() else math.nan
            rows.append((amp, k + 1, rel, db))
    return np.array(rows, dtype=ERROR_DTYPE)


# ---- simulation -----------------------------------------------------------------------------------------


def coulomb_system(coulomb: float = 1.5, inertia: float = 1.0, spring: float = 0.0) -> PlantParams:
    """Mass + Coulomb (+ spring): J*x'' + Fc*sign(x') (+ k*x) = F. The paper's Coulomb comparison has a
    break-away of about 1.5 N (science.md §5)."""
    return PlantParams(inertia=inertia, coulomb=coulomb, spring=spring)


def closed_form_equivalent(h: float, d: float, inertia: float = 1.0, spring: float = 0.0,
                           x_max: float = 1e3, n: int = 400) -> PlantParams:
    """Equivalent (skeleton) system of a rolling-friction Masing loop, from the closed forms of science.md §3.

    m*x'' + F_k(x) + F_d(x') (+ k*x) = F with

    - ``F_k(x) = k_eq(|x|)*x``, ``k_eq(A) = 2h*sqrt(d)/(d + A)^(3/2)`` (first-harmonic in-phase stiffness),
    - ``F_d(V) = c_eq*V = E(A)/(pi*A) = 4h*A^2/(pi*(d + A)^2)`` with ``E(A) = 4h*A^3/(d + A)^2``, taken on
      the skeleton ``V = A*omega_n(A)``, ``omega_n(A)^2 = (k + k_eq(A))/m``; V(A) is increasing, so A(V) is
      found by interpolation.

    This is a placeholder for a fitted equivalent (hilbench.analysis.skeleton.skeleton_fit): it has the same amplitude
    dependence by construction. Tables run on a grid 0, geomspace(1e-4*d, x_max, n-1) (rad or m) and the
    matching velocities; the engine holds them constant beyond the end.

    Args:
        h: limit friction force, N (N*m); d: characteristic presliding displacement, m (rad).
        inertia: m, kg (kg*m^2); spring: k, N/m (N*m/rad).
    """
    if not (h > 0 and d > 0 and inertia > 0 and spring >= 0 and x_max > 0 and n >= 3):
        raise AnalysisError("closed_form_equivalent needs h, d, inertia, x_max > 0, spring >= 0 and n >= 3")
    amp = np.concatenate([[0.0], np.geomspace(1e-4 * d, x_max, n - 1)])
    k_eq = 2 * h * math.sqrt(d) / (d + amp) ** 1.5
    restoring = k_eq * amp
    velocity = amp * np.sqrt((spring + k_eq) / inertia)
    damping = 4 * h * amp**2 / (math.pi * (d + amp) ** 2)
    return PlantParams(inertia=inertia, spring=spring, restoring_table=(amp, restoring),
                       damping_table=(velocity, damping))


def _substeps(params: PlantParams, dt: float) -> int:
    return max(1, math.ceil(stiffest_eigenvalue(params) * dt / SUBSTEP_LAMBDA_H))


def _ramp(n_ramp: int, n: int) -> np.ndarray:
    """Onset envelope: w = sin^2(pi/2*s) smoothed once more (w = s - sin(2*pi*s)/(2*pi)), s in [0, 1) over
    n_ramp samples, then 1. Both w and w' are continuous, so a slow mode is hardly excited."""
    w = np.ones(n)
    if n_ramp > 0:
        s = np.arange(n_ramp) / n_ramp
        w[:n_ramp] = s - np.sin(2 * np.pi * s) / (2 * np.pi)
    return w


@dataclass(frozen=True)
class _Cell:
    params: PlantParams
    amplitude: float
    frequency: float
    samples_per_period: int
    settle_periods: int
    measure_periods: int
    ramp_periods: int
    n_harmonics: int


def _run_cell(cell: _Cell) -> tuple[np.ndarray, complex, float]:
    n_per = cell.samples_per_period
    n_settle = cell.settle_periods * n_per
    n = n_settle + cell.measure_periods * n_per
    k = np.arange(n)
    u = cell.amplitude * np.sin(2 * np.pi * (k % n_per) / n_per) * _ramp(cell.ramp_periods * n_per, n)
    fs = cell.frequency * n_per
    dt = 1.0 / fs
    out = simulate(cell.params, u, dt, substeps=_substeps(cell.params, dt))
    # torque u[k] is held over [t_k, t_k+1): the response over [t_k, t_k+1) is measured with it.
    x = out.theta[n_settle:]
    resp = harmonic_phasors(x, fs, cell.frequency, cell.n_harmonics)
    drive = harmonic_phasors(out.torque[n_settle:], fs, cell.frequency, 1, detrend=False)[0]
    return resp, complex(drive), period_convergence(x, fs, cell.frequency, cell.n_harmonics)


def settle_schedule(frequencies: Sequence[float], min_periods: int = 20, min_time: float = 0.0) -> np.ndarray:
    """Settle periods per frequency: ``max(min_periods, ceil(min_time*f))``, shape (n_freq,).

    A fixed number of periods settles modes whose decay scales with the drive period (hysteretic damping);
    ``min_time`` (s) covers a slow mode of fixed period, e.g. the presliding resonance of a system without
    linear spring, that a short ramp at high frequency would leave ringing."""
    f = np.asarray(frequencies, dtype=float)
    return np.maximum(int(min_periods), np.ceil(min_time * f)).astype(int)


def _check_grid(amplitudes, frequencies) -> tuple[np.ndarray, np.ndarray]:
    a = np.atleast_1d(np.asarray(amplitudes, dtype=float))
    f = np.atleast_1d(np.asarray(frequencies, dtype=float))
    if a.ndim != 1 or f.ndim != 1 or a.size == 0 or f.size == 0:
        raise AnalysisError("amplitudes and frequencies must be non-empty 1-D lists")
    if not (np.all(np.isfinite(a)) and np.all(a > 0)):
        raise AnalysisError(f"amplitudes must be > 0 and finite, got {a.tolist()}")
    if not (np.all(np.isfinite(f)) and np.all(f > 0)):
        raise AnalysisError(f"frequencies must be > 0 Hz and finite, got {f.tolist()}")
    return a, f


def _cells(params, a, f, samples_per_period, settle, measure_periods, ramp, n_harmonics) -> list[_Cell]:
    settle = np.broadcast_to(np.asarray(settle), f.shape)
    if np.any(settle < 0) or np.any(settle != np.round(settle)):
        raise AnalysisError("settle_periods must be whole numbers >= 0")
    if int(measure_periods) != measure_periods or measure_periods < 1:
        raise AnalysisError(f"measure_periods must be a whole number >= 1, got {measure_periods!r}")
    if int(samples_per_period) != samples_per_period or samples_per_period <= 2 * n_harmonics:
        raise AnalysisError(f"samples_per_period must be an integer > 2*n_harmonics, got {samples_per_period!r}")
    if not 0.0 <= ramp <= 1.0:
        raise AnalysisError(f"ramp must be a fraction of the settle window in [0, 1], got {ramp}")
    return [_Cell(params, float(ai), float(fj), int(samples_per_period), int(settle[j]), int(measure_periods),
                  int(math.floor(ramp * settle[j])), int(n_harmonics))
            for ai in a for j, fj in enumerate(f)]


def _run_cells(cells: list[_Cell], workers: int | None) -> list[tuple[np.ndarray, complex, float]]:
    if workers is None:
        workers = os.cpu_count() or 1
    workers = max(1, min(int(workers), len(cells)))
    try:
        if workers == 1:
            return [_run_cell(c) for c in cells]
        # Expensive cells (high frequency with a settle time) are spread by a small chunk size.
        chunk = max(1, len(cells) // (workers * 16))
        with ProcessPoolExecutor(max_workers=workers) as pool:
            return list(pool.map(_run_cell, cells, chunksize=chunk))
    except PlantParameterError as exc:
        raise AnalysisError(f"the model cannot be simulated: {exc}") from None


def simulate_afrf_models(models: Mapping[str, PlantParams], amplitudes: Sequence[float],
                         frequencies: Sequence[float], *, samples_per_period: int = 400,
                         settle_periods: int | Sequence[int] = 20, measure_periods: int = 10,
                         ramp: float = 0.5, n_harmonics: int = 3, workers: int | None = None,
                         axis: str = "rotary") -> dict[str, AfrfResult]:
    """:func:`simulate_afrf` for several models in one process pool (all cells of all models are jobs).
    Returns name -> AfrfResult, in the order of ``models``."""
    if axis not in ("rotary", "linear"):
        raise AnalysisError(f"axis must be 'rotary' or 'linear', got {axis!r}")
    a, f = _check_grid(amplitudes, frequencies)
    per_model = {name: _cells(p, a, f, samples_per_period, settle_periods, measure_periods, ramp, n_harmonics)
                 for name, p in models.items()}
    flat = [c for cells in per_model.values() for c in cells]
    done = _run_cells(flat, workers)
    results, i = {}, 0
    settings = {"samples_per_period": int(samples_per_period), "measure_periods": int(measure_periods),
                "settle_periods": np.broadcast_to(np.asarray(settle_periods), f.shape).astype(int).tolist(),
                "ramp": float(ramp), "drive": "G*sin(2*pi*f*t), zero-order hold, from rest"}
    force, disp = ("N", "m") if axis == "linear" else ("N*m", "rad")
    for name, cells in per_model.items():
        part = done[i:i + len(cells)]
        i += len(cells)
        shape = (a.size, f.size)
        results[name] = AfrfResult(
            amplitudes=a, frequencies=f,
            response=np.array([p[0] for p in part]).reshape(shape + (n_harmonics,)),
            drive=np.array([p[1] for p in part]).reshape(shape),
            convergence=np.array([p[2] for p in part]).reshape(shape),
            amplitude_unit=force, displacement_unit=disp, drive_unit=force, label=name,
            settings={**settings, "model": models[name].to_dict()},
        )
    return results


def simulate_afrf(params: PlantParams, amplitudes: Sequence[float], frequencies: Sequence[float], *,
                  samples_per_period: int = 400, settle_periods: int | Sequence[int] = 20,
                  measure_periods: int = 10, ramp: float = 0.5, n_harmonics: int = 3,
                  workers: int | None = None, label: str = "simulated", axis: str = "rotary") -> AfrfResult:
    """Stepped-sine AFRF of a plant model, simulated with the C engine.

    Each (amplitude G, frequency f) cell starts from rest and plays ``u = G*w(t)*sin(2*pi*f*t)`` (N*m, or N
    on a linear axis; ``torque_constant`` applies as usual) at ``fs = samples_per_period*f``, held over each
    sample. ``w`` rises smoothly from 0 to 1 over the first ``floor(ramp*settle)`` periods (see
    :func:`_ramp`; ``ramp=0`` starts abruptly like the bench). After ``settle`` periods, ``measure_periods``
    periods of theta are analysed with :func:`harmonic_phasors` (drift removed) and
    :func:`period_convergence`. RK4 sub-steps are chosen so that ``|lambda|*h <= 0.5``.

    Args:
        params: the model.
        amplitudes: G, shape (n_amp,), N*m (N).
        frequencies: f, shape (n_freq,), Hz.
        samples_per_period: samples per drive period (> 2*n_harmonics; 200-1000 is typical).
        settle_periods: periods discarded, one number or one per frequency (:func:`settle_schedule`).
        measure_periods: whole periods analysed (>= 2 for the drift removal and the convergence check).
        ramp: fraction of the settle window used for the smooth onset, in [0, 1].
        n_harmonics: harmonics 1..n_harmonics.
        workers: processes; None = all cores, 1 = in this process.
        label: name of the result. axis: ``rotary`` (N*m, rad) or ``linear`` (N, m): units only.
    Returns:
        :class:`AfrfResult` with ``response`` of shape (n_amp, n_freq, n_harmonics) in rad (m).
    """
    return simulate_afrf_models({label: params}, amplitudes, frequencies, samples_per_period=samples_per_period,
                                settle_periods=settle_periods, measure_periods=measure_periods, ramp=ramp,
                                n_harmonics=n_harmonics, workers=workers, axis=axis)[label]


# ---- measured runs ---------------------------------------------------------------------------------------


def afrf_from_run(path: str | Path, n_harmonics: int = 3, allow_incomplete: bool = False) -> AfrfResult:
    """AFRF of a measured stepped-sine run file (:func:`hilbench.analysis.afrf.analyse` on the record read whole;
    :mod:`hilbench.analysis.afrf.steps` documents the grid, the units and the errors)."""
    from hilbench.analysis.afrf import AfrfSettings, analyse, load

    return analyse(load(path, allow_incomplete=allow_incomplete), AfrfSettings(n_harmonics=n_harmonics))


# ---- figure ----------------------------------------------------------------------------------------------


def plot_afrf(results: AfrfResult | Sequence[AfrfResult], path: str | Path | None = None,
              title: str | None = None, measured: bool = False):
    """Paper-style AFRF figure (Fig 13): one log-log panel per harmonic, |c_k| against frequency, one colour
    per amplitude, one line style per result (solid, dashed, dotted, dash-dot), one legend for the figure.
    Magnitudes below 1e-12 of a result's largest are numerical zeros (a Coulomb system that sticks) and are
    left out. ``measured``: the points are discrete steps of a run, drawn as markers; the first harmonic is
    joined by lines, the higher ones are not (at most steps they are the noise floor, not a response curve).
    Frequency ticks at 1, 2, 5 per decade, labelled in plain numbers. Saves a PNG when ``path`` is given.
    Uses the Agg canvas directly (no pyplot state). Returns the Figure."""
    from matplotlib import colormaps
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    results = [results] if isinstance(results, AfrfResult) else list(results)
    if not results:
        raise AnalysisError("plot_afrf: nothing to plot")
    n_h = max(r.n_harmonics for r in results)
    fig = Figure(figsize=(4.0 * n_h + 1.8, 4.2))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, n_h, sharex=True, squeeze=False)[0]
    styles = ("-", "--", ":", "-.")
    cmap = colormaps["viridis"]
    handles: dict[str, Line2D] = {}
    for r_i, r in enumerate(results):
        mags = r.magnitudes
        floor = 1e-12 * float(np.nanmax(mags)) if np.any(np.isfinite(mags)) else 0.0
        for a_i, amp in enumerate(r.amplitudes):
            colour = cmap(0.9 * a_i / max(1, r.amplitudes.size - 1))
            for k in range(r.n_harmonics):
                y = mags[a_i, :, k]
                ok = np.isfinite(y) & (y > floor)
                ls = styles[r_i % len(styles)] if not measured or k == 0 else "none"
                axes[k].loglog(r.frequencies[ok], y[ok], ls=ls, marker="o" if measured else None, ms=4,
                               color=colour, lw=1.2)
            handles.setdefault(f"G = {amp:g} {r.amplitude_unit}",
                               Line2D([], [], color=colour, lw=1.2, marker="o" if measured else None, ms=4))
        if len(results) > 1:
            handles[r.label or f"result {r_i + 1}"] = Line2D([], [], color="0.3", lw=1.2,
                                                            ls=styles[r_i % len(styles)])
    for k in range(n_h):
        axes[k].set_title(f"harmonic {k + 1} ({k + 1}f)")
        axes[k].set_xlabel("frequency f (Hz)")
        axes[k].set_ylabel(f"|X({k + 1}f)| ({results[0].displacement_unit})")
        axes[k].grid(True, which="both", alpha=0.3)
        axes[k].xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        axes[k].xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        axes[k].xaxis.set_minor_formatter(NullFormatter())
    fig.legend(list(handles.values()), list(handles), loc="center right", fontsize=9,
               title="drive amplitude" if len(results) == 1 else None, frameon=False)
    if title:
        fig.suptitle(title)
    fig.tight_layout(rect=(0, 0, 1 - 1.7 / fig.get_figwidth(), 1))
    if path is not None:
        fig.savefig(path, dpi=120)
    return fig
