"""Diagnostics that locate structure in an equation-error residual, each with a statistic and a test.

Most diagnostics are a partial F-test: regress the residual e on nuisance columns N, then on [N, X];

    F = ((SS_N - SS_NX)/q) / (SS_NX/(n_eff - p)),    p-value = F_{q, n_eff - p}.sf(F)

with n_eff the residual's effective sample count (:func:`analysis.identification.regressors.effective_sample_count`;
the filtered residual is coloured). The *effect* is the fraction of the residual variance X explains,
(SS_N - SS_NX)/SS_total. A diagnostic is significant when its (Bonferroni-adjusted) p-value is below
``alpha`` AND its effect is at least ``min_effect``: with thousands of rows a negligible but consistent
pattern is always "significant", so the effect size keeps the verdict physical.

| diagnostic | X (nuisance N) | points to |
|---|---|---|
| mean_trend | 1, t | offset_drift |
| velocity | v (1) | viscous |
| low_speed | sign(v)*exp(-(v/v_j)^2), 3 scales v_j (1, v) | stribeck |
| direction | [v>0], abs(v) (1, v) | asymmetric_friction |
| position | theta (1) | maxwell_slip |
| acceleration | theta'' (1) | torque_gain |
| command | tau (1) | torque_gain |
| input_rate | d tau/dt (1) | delay |
| input_xcorr | max_l corr(e, tau(t - l)), Fisher z, Bonferroni over lags | delay |
| angle_spectrum | sin/cos(k*theta) per wavenumber k, Bonferroni | position_periodic (+ preload_variation, note 1) |
| angle_spectrum_direction | sign(v)*sin/cos(k*theta) | position_dependent_friction (+ preload_variation, note 1) |
| position_level | sign(v)*(sin, cos)(theta); linear: sign(v)*P_1,2(travel) (1, sign v) | preload_variation |
| time_spectrum | multitaper harmonic F-test per run (a line coherent over the record), Bonferroni | (none: reported) |

Note 1: when a line's period exceeds the travel (orders <= 3 over less than a revolution; a wavelength longer than a
linear axis' travel): :func:`_slow_lines`.

Not a diagnostic of the loop's rounds: :func:`hysteresis_law_check` asks, of whatever structure the loop leaves, whether
it is the start model's presliding law (Masing's branches) failing to follow the data's (a single-state or Bouc-Wen
law), by regressing the residual on the branch state (:func:`branch_columns`) and running the diagnostics again.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace

import numpy as np

from hilbench.analysis.identification.regressors import effective_sample_count, position_resolution
from hilbench.analysis.residual.candidates import stribeck_top
from hilbench.analysis.residual.rundata import RunData

ALPHA = 1e-3
MIN_EFFECT = 0.03


@dataclass
class Diagnostic:
    name: str
    statistic: float
    statistic_name: str
    p_value: float
    effect: float  # fraction of the residual variance explained
    significant: bool
    points_to: tuple[str, ...]
    description: str
    detail: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"name": self.name, "statistic": _num(self.statistic), "statistic_name": self.statistic_name,
                "p_value": _num(self.p_value), "effect": _num(self.effect), "significant": bool(self.significant),
                "points_to": list(self.points_to), "description": self.description,
                "detail": _jsonable(self.detail)}


def _num(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _jsonable(obj):
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        return _num(float(obj))
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


@dataclass
class Signals:
    """Residual and regressors at the stacked rows of the runs (all shape (N,))."""

    residual: np.ndarray  # N*m or N
    time: np.ndarray  # s (per run)
    position: np.ndarray  # rad or m
    velocity: np.ndarray  # rad/s or m/s (regression velocity D L[theta])
    velocity_fast: np.ndarray  # lightly filtered velocity at the rows
    acceleration: np.ndarray
    command: np.ndarray  # L[tau], N*m or N
    command_rate: np.ndarray  # d L[tau]/dt, N*m/s
    run_rows: list  # (start, stop) per run
    row_rate: float  # rows per second (fs/decimation)
    axis: str
    resolution: float  # position resolution, rad or m
    cutoff: float  # Hz

    @classmethod
    def from_runs(cls, runs: list[RunData], residual: np.ndarray) -> Signals:
        cat = np.concatenate
        rr, start = [], 0
        for r in runs:
            rr.append((start, start + r.n_rows))
            start += r.n_rows
        return cls(
            residual=np.asarray(residual, float),
            time=cat([r.t_rows for r in runs]),
            position=cat([r.data.position for r in runs]),
            velocity=cat([r.data.velocity for r in runs]),
            velocity_fast=cat([r.velocity_fast[r.rows] for r in runs]),
            acceleration=cat([r.data.acceleration for r in runs]),
            command=cat([r.data.torque for r in runs]),
            command_rate=cat([np.gradient(r.torque_filtered, 1 / r.fs)[r.rows] for r in runs]),
            run_rows=rr,
            row_rate=runs[0].fs / runs[0].data.decimation,
            axis=runs[0].axis,
            resolution=max(position_resolution(r.position) for r in runs),
            cutoff=runs[0].data.cutoff,
        )


def partial_f(e: np.ndarray, x: np.ndarray, nuisance: np.ndarray | None, n_eff: float) -> tuple[float, float, float]:
    """(F, p-value, effect) of adding columns ``x`` (N, q) to ``nuisance`` (N, p0) in a regression of e."""
    from scipy import stats

    x = np.atleast_2d(x.T).T
    base = np.ones((e.size, 1)) if nuisance is None else np.atleast_2d(nuisance.T).T
    ss_tot = float(e @ e)
    if ss_tot == 0:
        return 0.0, 1.0, 0.0

    def rss(a):
        c, *_ = np.linalg.lstsq(a, e, rcond=None)
        r = e - a @ c
        return float(r @ r)

    ss0 = rss(base)
    full = np.column_stack([base, x])
    ss1 = rss(full)
    q = x.shape[1]
    dof = max(n_eff - full.shape[1], 1.0)
    f = max(ss0 - ss1, 0.0) / q / max(ss1 / dof, 1e-300)
    return float(f), float(stats.f.sf(f, q, dof)), float(max(ss0 - ss1, 0.0) / ss_tot)


def _make(name, stat, stat_name, p, effect, points, desc, alpha, min_effect, **detail) -> Diagnostic:
    sig = bool(p < alpha and effect >= min_effect)
    return Diagnostic(name, stat, stat_name, p, effect, sig, points, desc, detail)


def _one(s: Signals) -> np.ndarray:
    return np.ones_like(s.residual)


def wavenumber_grid(s: Signals) -> tuple[np.ndarray, str]:
    """Spatial angular frequencies k (rad per unit position) to scan, and their unit label.

    Rotary: integer orders 1..M (cycles/rev). Linear: spatial frequencies from 1/travel, step
    1/(2*travel). The top is where the cogging torque at the median moving speed reaches 2x the
    filter cutoff (k*|v|/2pi = 2*cutoff), and at most 1/8 of the encoder's Nyquist.
    """
    moving = np.abs(s.velocity) > 10 * s.resolution * s.row_rate
    speed = float(np.median(np.abs(s.velocity[moving]))) if moving.any() else 0.0
    k_speed = 2 * np.pi * 2 * s.cutoff / speed if speed > 0 else 0.0
    k_enc = np.pi / (8 * max(s.resolution, 1e-12))
    k_max = min(k_speed, k_enc)
    if s.axis == "rotary":
        m = int(np.clip(k_max, 8, 300))
        return np.arange(1, m + 1, dtype=float), "cycles/rev"
    travel = float(np.ptp(s.position))
    if travel <= 0:
        return np.zeros(0), "1/m"
    f = np.arange(1.0 / travel, k_max / (2 * np.pi), 0.5 / travel)[:2000]
    return 2 * np.pi * f, "1/m"


def angle_periodogram(e: np.ndarray, theta: np.ndarray, ks: np.ndarray, weight: np.ndarray | None = None
                      ) -> np.ndarray:
    """Fraction of the (mean-removed) residual variance explained by [w*sin(k theta), w*cos(k theta)] for
    each k: the least-squares (Lomb-Scargle) periodogram in the angle domain, shape (len(ks),)."""
    e = e - e.mean()
    w = np.ones_like(e) if weight is None else weight
    out = np.empty(ks.size)
    tot = float(e @ e)
    for i0 in range(0, ks.size, 64):
        k = ks[i0: i0 + 64]
        ph = np.outer(theta, k)
        sn, cs = w[:, None] * np.sin(ph), w[:, None] * np.cos(ph)
        sn -= sn.mean(0)
        cs -= cs.mean(0)
        a11, a22, a12 = (sn * sn).sum(0), (cs * cs).sum(0), (sn * cs).sum(0)
        b1, b2 = e @ sn, e @ cs
        det = a11 * a22 - a12**2
        det[det <= 0] = np.inf
        out[i0: i0 + 64] = (a22 * b1**2 - 2 * a12 * b1 * b2 + a11 * b2**2) / det / tot
    return out


def _spectrum_peaks(r2: np.ndarray, ks: np.ndarray, n_eff: float, alpha: float, min_effect: float,
                    axis: str, max_peaks: int = 6) -> tuple[list, float, float]:
    from scipy import stats

    dof = max(n_eff - 3, 1.0)
    f = (r2 / 2) / np.maximum((1 - r2) / dof, 1e-300)
    p = np.minimum(1.0, stats.f.sf(f, 2, dof) * ks.size)
    peaks = []
    order = np.argsort(r2)[::-1]
    taken = np.zeros(ks.size, bool)
    for i in order:
        if p[i] >= alpha or r2[i] < min_effect / 2 or len(peaks) >= max_peaks:
            break
        if taken[max(0, i - 1): i + 2].any():
            continue
        taken[i] = True
        k = float(ks[i])
        if axis != "rotary" and 0 < i < ks.size - 1:  # parabolic refinement of a continuous frequency
            y0, y1, y2 = r2[i - 1], r2[i], r2[i + 1]
            den = y0 - 2 * y1 + y2
            if den < 0:
                k += 0.5 * (y0 - y2) / den * (ks[1] - ks[0])
        pk = {"wavenumber": k, "effect": float(r2[i]), "p_value": float(p[i])}
        pk["order" if axis == "rotary" else "wavelength"] = k if axis == "rotary" else 2 * np.pi / k
        peaks.append(pk)
    i = int(np.argmax(r2)) if r2.size else 0
    return peaks, (float(f[i]) if r2.size else 0.0), (float(p[i]) if r2.size else 1.0)


def _spectrum_diag(name, s, n_eff, alpha, min_effect, weight, points, what) -> Diagnostic:
    ks, unit = wavenumber_grid(s)
    if ks.size == 0:
        return Diagnostic(name, 0.0, "F", 1.0, 0.0, False, points, "position does not move", {})
    r2 = angle_periodogram(s.residual, s.position, ks, weight)
    peaks, fmax, pmin = _spectrum_peaks(r2, ks, n_eff, alpha, min_effect, s.axis)
    total = float(sum(pk["effect"] for pk in peaks))
    if peaks:
        at = ", ".join(f"{pk['order']:.0f} cycles/rev" if s.axis == "rotary" else f"wavelength {pk['wavelength']:.4g} m"
                       for pk in peaks)
        desc = f"{what} periodic in position at {at}"
    else:
        desc = f"no {what} periodic in position"
    spectrum = {"wavenumber": ks, "effect": r2, "unit": unit}
    return _make(name, fmax, "F", pmin, total, points, desc, alpha, min_effect, peaks=peaks, spectrum=spectrum)


def _xcorr_diag(s: Signals, n_eff: float, alpha: float, min_effect: float, max_lag: int = 30) -> Diagnostic:
    from scipy import stats

    e = s.residual - s.residual.mean()
    u = s.command - s.command.mean()
    lags = np.arange(-max_lag, max_lag + 1)
    rho = np.zeros(lags.size)
    for i, lag in enumerate(lags):
        if lag >= 0:
            a, b = e[lag:], u[: u.size - lag]
        else:
            a, b = e[: e.size + lag], u[-lag:]
        den = np.sqrt((a @ a) * (b @ b))
        rho[i] = (a @ b) / den if den > 0 else 0.0
    i = int(np.argmax(np.abs(rho)))
    z = np.arctanh(np.clip(abs(rho[i]), 0, 0.999999)) * np.sqrt(max(n_eff - 3, 1.0))
    p = min(1.0, 2 * stats.norm.sf(z) * lags.size)
    lag_s = float(lags[i]) / s.row_rate
    if lags[i] >= 0:
        desc = f"residual correlates with the input {lag_s * 1e3:.1f} ms earlier (rho {rho[i]:+.2f})"
    else:  # the input follows the residual: feedback (a controller reacting), not a delay
        desc = f"residual correlates with the input {-lag_s * 1e3:.1f} ms later (rho {rho[i]:+.2f}; feedback)"
    return _make("input_xcorr", float(rho[i]), "rho", p, float(rho[i] ** 2), ("delay",), desc, alpha, min_effect,
                 lag_s=lag_s, lags_s=lags / s.row_rate, rho=rho)


MT_NW = 4.0  # time-bandwidth product of the line test's Slepian tapers (half-bandwidth W = NW/T)
MT_TAPERS = 7  # 2*NW - 1 tapers


@functools.lru_cache(maxsize=8)
def _slepian(n: int, nw: float, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Slepian tapers (k, n) of unit energy and their sums (k,); read-only (cached: each run asks twice)."""
    from scipy.signal.windows import dpss

    tapers = dpss(n, nw, k)
    tapers.setflags(write=False)
    u0 = tapers.sum(axis=1)
    u0.setflags(write=False)
    return tapers, u0


def _harmonic_f(y: np.ndarray, u0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F, mu) from eigencoefficients y (k, m) and the tapers' sums u0 (k,)."""
    k = u0.size
    mu = (u0 @ y) / float(u0 @ u0)
    resid = np.sum(np.abs(y - np.outer(u0, mu)) ** 2, axis=0)
    return (k - 1) * np.abs(mu) ** 2 * float(u0 @ u0) / np.maximum(resid, 1e-300), mu


def harmonic_f_test(e: np.ndarray, fs: float, nw: float = MT_NW, k: int = MT_TAPERS, pad: int = 2
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Thomson's multitaper harmonic F-test for a line in a coloured residual.

    With Slepian tapers v_j (sum_t v_j^2 = 1), eigencoefficients y_j(f) = sum_t v_j(t) e_t exp(-i 2 pi f t),
    U_j = sum_t v_j(t) and mu(f) = sum_j U_j y_j(f) / sum_j U_j^2 (the complex amplitude A/2*exp(i phi) of a
    line A*cos(2 pi f t + phi)),

        F(f) = (K - 1) |mu|^2 sum_j U_j^2 / sum_j |y_j - mu U_j|^2   ~ F(2, 2K - 2) without a line.

    The denominator is the residual's own spectrum within +-W of f (W = NW/T), so a coloured or red continuum is
    not a line: only a component coherent across the tapers (constant amplitude and phase over the record) is.
    Returns (frequencies Hz, F, 2|mu|^2 (the line variance A^2/2 at a grid frequency on the line), number of
    frequencies tested), on the frequencies more than W from 0 and from fs/2, grid ``pad`` x finer than 1/T."""
    x = np.asarray(e, float) - np.mean(e)
    n = x.size
    tapers, u0 = _slepian(n, nw, k)
    nfft = int(2 ** np.ceil(np.log2(pad * n)))
    fstat, mu = _harmonic_f(np.fft.rfft(tapers * x, nfft, axis=1), u0)
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    w = nw * fs / n
    keep = (f > w) & (f < fs / 2 - w)
    return f[keep], fstat[keep], 2.0 * np.abs(mu[keep]) ** 2, int(np.sum(keep))


def line_test(e: np.ndarray, fs: float) -> tuple[float, float, float, float]:
    """The strongest line of a residual: (frequency Hz, harmonic F, Bonferroni-adjusted p-value, share of the
    variance).

    The grid maximum of :func:`harmonic_f_test` is refined to the frequency whose least-squares sinusoid explains
    the most (within one grid step), and F is taken there: half a grid step off a strong line, the line's own
    leakage fills the F-test's denominator and caps F (an A = 2 sigma line in white noise reached only
    p = 6e-5). The p-value is Bonferroni-adjusted over a grid 4x finer than 1/T (about 4x the n/2 independent
    frequencies), which bounds the maximum over a continuous frequency: measured false-alarm rate at a nominal
    0.05 of 0.017-0.047 on white and red (AR(1), phi 0.98) residuals of 1000 and 5000 rows (0.04-0.09 with the
    pad-2 grid count alone)."""
    from scipy import stats
    from scipy.optimize import minimize_scalar

    x = np.asarray(e, float) - np.mean(e)
    f, fstat, _, n_tested = harmonic_f_test(x, fs)
    if f.size == 0:
        return 0.0, 0.0, 1.0, 0.0
    i = int(np.argmax(fstat))
    tapers, u0 = _slepian(x.size, MT_NW, MT_TAPERS)
    t = np.arange(x.size) / fs
    tot = float(x @ x)

    def neg_share(fr: float) -> float:
        a = np.column_stack([np.cos(2 * np.pi * fr * t), np.sin(2 * np.pi * fr * t)])
        c, *_ = np.linalg.lstsq(a, x, rcond=None)
        r = x - a @ c
        return -(1.0 - float(r @ r) / tot) if tot > 0 else 0.0

    step = float(f[1] - f[0]) if f.size > 1 else fs / x.size
    opt = minimize_scalar(neg_share, bounds=(f[i] - step, f[i] + step), method="bounded",
                          options={"xatol": step * 1e-3})
    f_line = float(opt.x)
    y = (tapers * x) @ np.exp(-2j * np.pi * f_line * t)
    f_ref = float(_harmonic_f(y[:, None], u0)[0][0])
    fmax = max(f_ref, float(fstat[i]))
    # the maximum over a continuous frequency: Bonferroni over a grid 4x finer than 1/T (2 x the pad-2 grid)
    p = min(1.0, float(stats.f.sf(fmax, 2, 2 * MT_TAPERS - 2)) * 2 * n_tested)
    return f_line, fmax, p, float(-opt.fun)


def _time_spectrum(s: Signals, alpha: float, min_effect: float) -> Diagnostic:
    """A line in time: the multitaper harmonic F-test (:func:`harmonic_f_test`) per run, Bonferroni over the
    independent frequencies and the runs; effect = the line's variance / the run's residual variance.

    It replaced a Welch-PSD-against-running-median test that took the broad low-frequency continuum of a clean
    record's residual (the Maxwell-slip grid's slow, path-dependent approximation error) for a line: its
    background at the first bin came from the mean-removed DC bin, so bin 1 of any red spectrum stood out
    (0.977 Hz = 250 rows/s / 256, 7.6x "the background", p = 6e-66 on the default simulated bench)."""
    from scipy import ndimage, signal

    runs = [(lo, hi) for lo, hi in s.run_rows if hi - lo >= 64]
    if not runs:
        return Diagnostic("time_spectrum", 0.0, "F", 1.0, 0.0, False, (), "run too short for a spectrum", {})
    best = None
    for lo, hi in runs:
        f_line, fmax, p, share = line_test(s.residual[lo:hi], s.row_rate)
        p = min(1.0, p * len(runs))
        if best is None or p < best[0]:
            best = (p, fmax, f_line, share)
    if best is None:
        return Diagnostic("time_spectrum", 0.0, "F", 1.0, 0.0, False, (), "run too short for a spectrum", {})
    p, fmax, f0, effect = best
    # the Welch PSD and its running median are kept for the report's figure only
    nper = min(256, min(hi - lo for lo, hi in runs))
    psds = [signal.welch(s.residual[lo:hi] - s.residual[lo:hi].mean(), fs=s.row_rate, nperseg=nper)
            for lo, hi in runs]
    freq, pxx = psds[0][0], np.mean([q for _, q in psds], axis=0)
    bg = ndimage.median_filter(pxx, size=17, mode="nearest")
    desc = (f"strongest line at {f0:.3g} Hz (harmonic F {fmax:.3g}, {100 * effect:.1f} % of the residual "
            "variance)")
    return _make("time_spectrum", fmax, "F", p, effect, (), desc, alpha, min_effect, frequency_hz=f0,
                 spectrum={"frequency_hz": freq, "psd": pxx, "background": bg})


SLOW_ORDERS = 3.0  # cycles/rev: a line at this order or below, over less than a revolution, is a slow level too


def _slow_lines(d: Diagnostic, s: Signals) -> bool:
    """Whether a significant angle-spectrum diagnostic has a line whose period the travel does not cover: on a
    rotary axis an order of at most SLOW_ORDERS over less than a revolution of travel, on a linear axis a wavelength
    longer than the travel. Such a line is as much a friction level that varies slowly along the travel as a
    periodic one (issue 39: lines at 1 and 3 cycles/rev over 0.2-0.4 rev of an eccentric preload sent the loop to
    ``position_periodic`` alone, rejected at +150 000 % held-out MSE, and never to ``preload_variation``)."""
    if not d.significant:
        return False
    # the longest single run's travel, as preload_variation's own rule (candidates.PreloadVariation.unfit_reason)
    travel = max(float(np.ptp(s.position[lo:hi])) for lo, hi in s.run_rows if hi > lo)
    ks = [float(p["wavenumber"]) for p in d.detail.get("peaks", [])]
    if s.axis == "rotary":
        return travel < 2 * np.pi and any(k <= SLOW_ORDERS for k in ks)
    return any(2 * np.pi / k > travel for k in ks if k > 0)


def run_diagnostics(s: Signals, alpha: float = ALPHA, min_effect: float = MIN_EFFECT) -> dict[str, Diagnostic]:
    """Every diagnostic of the residual in ``s``; dict name -> :class:`Diagnostic`."""
    e = s.residual
    n_eff = effective_sample_count(e)
    one = _one(s)
    v = s.velocity
    out: dict[str, Diagnostic] = {}

    def reg(name, x, nuisance, points, desc_fn):
        f, p, eff = partial_f(e, x, nuisance, n_eff)
        out[name] = _make(name, f, "F", p, eff, points, desc_fn(), alpha, min_effect)

    t_rel = s.time - s.time.mean()
    c, *_ = np.linalg.lstsq(np.column_stack([one, t_rel]), e, rcond=None)
    reg("mean_trend", np.column_stack([one, t_rel]), np.zeros((e.size, 0)), ("offset_drift",),
        lambda: f"mean {c[0]:+.3g}, trend {c[1]:+.3g} per s")
    slope = np.polyfit(v, e, 1)[0] if np.ptp(v) > 0 else 0.0
    reg("velocity", v, one, ("viscous",), lambda: f"residual grows with velocity ({slope:+.3g} per unit velocity)")
    speed = np.abs(s.velocity_fast)
    # the scales stop where the Stribeck candidate's grid does (candidates.stribeck_top): a record that cruises
    # (a stroke-limited sweep, median speed 3.5 rad/s) has no "low speed" at its median
    scales = np.minimum(np.percentile(speed, [10, 25, 50]), stribeck_top(speed)) + 1e-12
    sgn = np.sign(s.velocity_fast)
    low = np.column_stack([sgn * np.exp(-((speed / vs) ** 2)) for vs in scales])
    reg("low_speed", low, np.column_stack([one, v]), ("stribeck",),
        lambda: "residual concentrated at low sliding speed, odd in velocity")
    pos, neg = s.velocity_fast > 0, s.velocity_fast < 0
    gap = (e[pos].mean() if pos.any() else 0.0) - (e[neg].mean() if neg.any() else 0.0)
    reg("direction", np.column_stack([pos * 1.0, np.abs(v)]), np.column_stack([one, v]), ("asymmetric_friction",),
        lambda: f"residual differs between directions (mean + minus -: {gap:+.3g})")
    reg("position", s.position - s.position.mean(), one, ("maxwell_slip",),
        lambda: "residual correlates with position (a spring-like load)")
    reg("acceleration", s.acceleration, one, ("torque_gain",), lambda: "residual proportional to the acceleration")
    reg("command", s.command, one, ("torque_gain",), lambda: "residual proportional to the command")
    reg("input_rate", s.command_rate, one, ("delay",), lambda: "residual largest where the torque changes fast")
    if s.axis == "rotary":
        slow = np.column_stack([np.sin(s.position), np.cos(s.position)])
    else:
        xi = (s.position - 0.5 * (s.position.max() + s.position.min())) / max(0.5 * float(np.ptp(s.position)), 1e-300)
        slow = np.column_stack([xi, 1.5 * xi**2 - 0.5])
    reg("position_level", sgn[:, None] * slow, np.column_stack([one, sgn]), ("preload_variation",),
        lambda: "direction-odd residual that changes slowly along the travel (a friction level following position)")
    out["input_xcorr"] = _xcorr_diag(s, n_eff, alpha, min_effect)
    out["angle_spectrum"] = _spectrum_diag("angle_spectrum", s, n_eff, alpha, min_effect, None,
                                           ("position_periodic",), "residual")
    out["angle_spectrum_direction"] = _spectrum_diag("angle_spectrum_direction", s, n_eff, alpha, min_effect,
                                                     np.sign(s.velocity_fast), ("position_dependent_friction",),
                                                     "direction-odd residual")
    out["time_spectrum"] = _time_spectrum(s, alpha, min_effect)
    for key in ("angle_spectrum", "angle_spectrum_direction"):
        if _slow_lines(out[key], s):
            out[key].points_to = out[key].points_to + ("preload_variation",)
    for d in out.values():
        d.detail.setdefault("n_eff", n_eff)
    return out


#: scales of the branch columns: geometric from the larger of 4 position steps and 1 % of the median branch travel
#: to the median branch travel
BRANCH_SCALES = 4
BRANCH_HYSTERESIS_STEPS = 3  # a turning point is a move back by more than this many position steps


def branch_state(x: np.ndarray, hysteresis: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per sample of a path x (rad or m): the travel since the last turning point s (>= 0), the branch's direction
    d (+1, -1; 0 before the first move by more than ``hysteresis``) and the travel of the branch before it a (the
    distance between the last two turning points; 0 before the second)."""
    n = x.size
    s, d, a = np.zeros(n), np.zeros(n), np.zeros(n)
    last = prev = ext = float(x[0])
    direction = 0.0
    for i in range(n):
        xi = float(x[i])
        if direction == 0.0:
            if abs(xi - x[0]) > hysteresis:
                direction, ext = float(np.sign(xi - x[0])), xi
        elif (xi - ext) * direction > 0:
            ext = xi
        elif (ext - xi) * direction > hysteresis:
            prev, last, direction, ext = last, ext, -direction, xi
        s[i], d[i], a[i] = abs(xi - last), direction, abs(last - prev)
    return s, d, a


def branch_columns(s: Signals) -> np.ndarray:
    """Columns of a presliding law's branch state at the stacked rows, shape (N, 2*BRANCH_SCALES + 1):
    d*(1 - exp(-s/s_j)) and d*(1 - exp(-s/s_j))*min(a/a_med, 3) and d*min(a/a_med, 3) (s, d, a of
    :func:`branch_state`, a_med the median branch travel).

    Why: Maxwell-slip obeys Masing's rule (every branch is F_r + 2*d*V(s/2), a function of s alone after the reversal
    force F_r), so what its fit leaves of another hysteresis law is a branch shape that depends on how far the
    previous branch went (a Dahl branch after a partial reversal starts at sigma*(1 + F_r/F_c); a Bouc-Wen branch
    with n = 2 turns sharper than Masing's). The products with a carry that dependence."""
    hyst = BRANCH_HYSTERESIS_STEPS * s.resolution
    parts = [branch_state(s.position[lo:hi], hyst) for lo, hi in s.run_rows]
    trav, d, a = (np.concatenate([p[i] for p in parts]) for i in range(3))
    a_med = float(np.median(a[a > 0])) if np.any(a > 0) else float(np.ptp(s.position)) or 1.0
    scales = np.geomspace(max(4 * s.resolution, 0.01 * a_med), a_med, BRANCH_SCALES)
    amp = np.minimum(a / a_med, 3.0)
    shapes = [d * (1.0 - np.exp(-trav / sc)) for sc in scales]
    return np.column_stack(shapes + [b * amp for b in shapes] + [d * amp])


def hysteresis_law_check(s: Signals, diags: dict[str, Diagnostic], alpha: float = ALPHA,
                         min_effect: float = MIN_EFFECT) -> dict | None:
    """Whether the significant diagnostics in ``diags`` are the presliding law's: the residual regressed on the
    branch state (:func:`branch_columns`, with a constant) and the diagnostics run again on what is left. When none
    is still significant, returns {"explains": names, "effect": share of the residual variance the branch state
    explains, "p_value": its partial F-test, "description"}; else None (the structure is something else)."""
    names = [k for k, d in diags.items() if d.significant]
    if not names:
        return None
    e = s.residual
    h = np.column_stack([_one(s), branch_columns(s)])
    c, *_ = np.linalg.lstsq(h, e, rcond=None)
    after = run_diagnostics(replace(s, residual=e - h @ c), alpha, min_effect)
    if any(d.significant for d in after.values()):
        return None
    _, p, effect = partial_f(e, h[:, 1:], h[:, :1], effective_sample_count(e))
    return {"explains": names, "effect": effect, "p_value": p, "description": (
        f"the hysteresis law differs from the start model's: the branch state after each reversal (travel since "
        f"the reversal and the previous branch's travel) explains {100 * effect:.0f} % of the residual variance and "
        f"every structure left ({', '.join(names)}); Masing's rule (Maxwell-slip) does not hold on this record")}
