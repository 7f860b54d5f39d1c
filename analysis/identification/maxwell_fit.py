"""Default identification: linear in parameters, non-negative least squares on filtered regressors.

    L[tau] = J*L[theta''] + sum_i k_i*L[S_Delta_i[theta]] + b*L[theta'] (+ Fc*L[sign theta'] + c0 + K*L[theta])

with the Delta_i on a log-spaced candidate grid ranged from the data (hilbench.analysis.identification.regressors), all
coefficients >= 0 except the offset c0 (split into two non-negative columns). Solved with
scipy.optimize.nnls on unit-norm columns. Then adjacent active thresholds are merged, tiny elements
pruned, and (optionally) the thresholds refined by variable projection (NNLS inside a
Levenberg-Marquardt on log Delta).

Standard errors: a HAC (Newey-West) sandwich covariance on the active columns A_a
(analysis.identification.uncertainty): the filtered residuals and regressors are autocorrelated even after
thinning. Parameters at their bound (zero) get no standard error (NaN): the linearised covariance does not
apply there. The break-away sum k_i*Delta_i + Fc gets its standard error from the same covariance.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.regressors import (
    FilteredData,
    effective_sample_count,
    filtered_data,
    stop_columns,
    threshold_grid,
)
from hilbench.analysis.identification.uncertainty import bootstrap_standard_errors, hac_covariance
from hilbench.analysis.models.friction_model import FrictionModel, check_axis


@dataclass(frozen=True)
class LipSettings:
    """Settings of the linear-in-parameters fit. ``cutoff`` None: fs/20; ``decimation`` None: the
    largest step that keeps 2.5 rows per filter cutoff period (fs/(2.5*cutoff))."""

    n_thresholds: int = 64
    delta_range: tuple[float, float] | None = None  # rad or m
    cutoff: float | None = None  # Hz
    order: int = 4
    decimation: int | None = None
    viscous: bool = True
    coulomb: bool = False
    offset: bool = False
    spring: bool = False
    timing: str = "hold_next"  # see hilbench.analysis.identification.regressors.held_torque
    merge: bool = True
    prune_fraction: float = 1e-3  # drop elements whose W_i is below this fraction of sum W
    refine: bool = False
    max_inertia_rse: float = 0.2  # relative standard error of J above which J is unidentifiable
    fixed_inertia: float | None = None  # known J (kg*m^2 or kg; 0: a force-against-displacement record)

    def resolved(self, fs: float) -> tuple[float, int]:
        cutoff = self.cutoff if self.cutoff is not None else fs / 20.0
        dec = self.decimation if self.decimation is not None else max(1, int(fs / (2.5 * cutoff)))
        return float(cutoff), int(dec)

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


@dataclass
class LipFit:
    """Result: the model, and the regression it came from (filtered rows, prediction, figures)."""

    model: FrictionModel
    settings: LipSettings
    cutoff: float
    decimation: int
    candidate_deltas: np.ndarray
    measured: np.ndarray  # L[tau] at the rows, N*m or N
    predicted: np.ndarray  # model prediction of L[tau] at the rows
    rows: np.ndarray
    n_eff: float
    condition_number: float
    warnings: list[str] = field(default_factory=list)

    @property
    def torque_nrmse(self) -> float:
        """Equation-error NRMSE = rms(L tau - prediction)/std(L tau)."""
        return nrmse(self.measured, self.predicted)


def nrmse(y: np.ndarray, y_hat: np.ndarray) -> float:
    """Normalised RMS error rms(y - y_hat)/std(y) (fraction; NMSE in % = 100*nrmse^2)."""
    y = np.asarray(y, float)
    s = float(np.std(y))
    if s == 0:
        raise AnalysisError("cannot normalise the error: the reference signal is constant")
    return float(np.sqrt(np.mean((y - np.asarray(y_hat, float)) ** 2)) / s)


class _Design:
    """The linear columns (all but the stop operator) and their parameter names."""

    def __init__(self, data: FilteredData, s: LipSettings):
        cols, names = ([data.acceleration], ["inertia"]) if s.fixed_inertia is None else ([], [])
        if s.viscous:
            cols.append(data.velocity)
            names.append("viscous")
        if s.coulomb:
            cols.append(data.sign)
            names.append("coulomb")
        if s.spring:
            cols.append(data.position)
            names.append("spring")
        if s.offset:
            one = np.ones_like(data.torque)
            cols += [one, -one]
            names += ["offset+", "offset-"]
        self.columns = np.column_stack(cols) if cols else np.zeros((data.torque.size, 0))
        self.names = names


def _solve(a: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """NNLS on unit-norm columns; returns coefficients in the original scaling and |r|^2."""
    from scipy.optimize import nnls

    norms = np.linalg.norm(a, axis=0)
    norms[norms == 0] = 1.0
    coef, rnorm = nnls(a / norms, y, maxiter=50 * a.shape[1])
    return coef / norms, float(rnorm) ** 2


def _covariance(a: np.ndarray, residual: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Covariance of the active coefficients (inflated by n/n_eff), n_eff and cond of the active set."""
    n = a.shape[0]
    aa = a[:, active]
    p = aa.shape[1]
    if n <= p:
        raise AnalysisError(f"run too short: {n} rows for {p} active parameters")
    norms = np.linalg.norm(aa, axis=0)
    an = aa / norms
    n_eff = effective_sample_count(residual)
    cov, _ = hac_covariance(aa, residual)  # the scores' own autocorrelation (analysis.identification.uncertainty)
    return cov, n_eff, float(np.linalg.cond(an))


def _merge_adjacent(deltas: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Thresholds of merged elements: each run of adjacent active grid points becomes one element
    at the k-weighted mean Delta (the virgin curves agree below the first and above the last Delta)."""
    active = np.flatnonzero(k > 0)
    if active.size == 0:
        return active.astype(float)
    groups = np.split(active, np.flatnonzero(np.diff(active) > 1) + 1)
    return np.array([np.sum(k[g] * deltas[g]) / np.sum(k[g]) for g in groups])


def fit_lip(
    position: np.ndarray,
    torque: np.ndarray,
    fs: float,
    axis: str = "rotary",
    settings: LipSettings | None = None,
) -> LipFit:
    """Identify J, k_i (on a Delta grid), b (and optionally Fc, c0, K) by NNLS.

    Args:
        position: measured path theta, shape (n,), rad (rotary) or m (linear).
        torque: motor torque or force, shape (n,), N*m or N, with sample timing ``settings.timing``.
        fs: sampling rate, Hz.
        axis: "rotary" or "linear" (units only).
    Returns:
        :class:`LipFit`. Raises :class:`AnalysisError` for unusable input.
    """
    s = settings or LipSettings()
    check_axis(axis)
    cutoff, dec = s.resolved(fs)
    x = np.asarray(position, float)
    data = filtered_data(x, torque, fs, cutoff, order=s.order, decimation=dec, timing=s.timing)
    design = _Design(data, s)
    # n_thresholds 0: no Maxwell-slip elements (e.g. the EMPS reference model J, Fc, b, offset)
    grid = threshold_grid(x, s.n_thresholds, s.delta_range) if s.n_thresholds > 0 else np.empty(0)
    if s.fixed_inertia is not None and not (np.isfinite(s.fixed_inertia) and s.fixed_inertia >= 0):
        raise AnalysisError(f"a fixed inertia must be finite and >= 0, got {s.fixed_inertia}")
    y = data.torque if s.fixed_inertia is None else data.torque - s.fixed_inertia * data.acceleration
    lin = design.columns
    nl = lin.shape[1]

    def solve_with(deltas: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        a = np.column_stack([lin, stop_columns(x, deltas, data)])
        coef, rss = _solve(a, y)
        return a, coef, rss

    a, coef, rss = solve_with(grid)
    a_grid, deltas = a, grid
    if s.merge and np.count_nonzero(coef[nl:]) > 0:
        merged = _merge_adjacent(grid, coef[nl:])
        a2, coef2, rss2 = solve_with(merged)
        if rss2 <= rss * 1.02:
            a, coef, rss, deltas = a2, coef2, rss2, merged
    k = coef[nl:]
    w = k * deltas
    if s.prune_fraction > 0 and w.sum() > 0:
        keep = w >= s.prune_fraction * w.sum()
        if not np.all(keep):
            deltas = deltas[keep]
            a, coef, rss = solve_with(deltas)
    if s.refine and np.count_nonzero(coef[nl:]) > 0:
        deltas = _refine_thresholds(x, y, lin, data, deltas[coef[nl:] > 0], (grid[0], grid[-1]))
        a, coef, rss = solve_with(deltas)

    residual = y - a @ coef
    active = coef > 0
    cov, n_eff, cond = _covariance(a, residual, active)
    se_all = np.full(coef.size, np.nan)
    se_all[active] = np.sqrt(np.clip(np.diag(cov), 0, None))

    values = dict(zip(design.names, coef[:nl], strict=True))
    ses = dict(zip(design.names, se_all[:nl], strict=True))
    if s.fixed_inertia is not None:
        values["inertia"], ses["inertia"] = float(s.fixed_inertia), 0.0  # known, not estimated
    offset = values.pop("offset+", 0.0) - values.pop("offset-", 0.0)
    if s.offset:
        se_p, se_m = ses.pop("offset+"), ses.pop("offset-")
        ses["offset"] = se_p if np.isfinite(se_p) else se_m
    keep = coef[nl:] > 0
    std_errors = {name: float(v) for name, v in ses.items()}
    std_errors["ms_stiffness"] = se_all[nl:][keep]
    # break-away sum_i k_i*Delta_i (+ Fc): its gradient over the active coefficients
    grad = np.concatenate([[1.0 if n == "coulomb" else 0.0 for n in design.names], deltas])[active]
    std_errors["breakaway"] = float(np.sqrt(max(grad @ cov @ grad, 0.0)))
    bootstrap_standard_errors(std_errors, a_grid, y, residual, design.names, grid)  # the larger of the two
    model = FrictionModel(
        axis=axis,
        inertia=values["inertia"],
        ms_stiffness=coef[nl:][keep],
        ms_delta=deltas[keep],
        viscous=values.get("viscous", 0.0),
        coulomb=values.get("coulomb", 0.0),
        offset=offset,
        spring=values.get("spring", 0.0),
        std_errors=std_errors,
    )
    warnings = _identifiability(model, data, s)
    predicted = a @ coef + (data.torque - y)  # plus the known J*acceleration, if any
    return LipFit(model, s, cutoff, dec, grid, data.torque, predicted, data.rows, n_eff, cond, warnings)


def _identifiability(model: FrictionModel, data: FilteredData, s: LipSettings) -> list[str]:
    """Raise for an unidentifiable inertia; return warnings for the other parameters."""
    j, se_j = model.inertia, model.std_errors.get("inertia", np.nan)
    known = s.fixed_inertia is not None
    if not known and (not (j > 0) or not np.isfinite(se_j) or se_j > s.max_inertia_rse * j):
        rse = "inf" if not (j > 0 and np.isfinite(se_j)) else f"{100 * se_j / j:.0f} %"
        raise AnalysisError(
            f"inertia J is unidentifiable from this run (estimate {j:.4g}, relative standard error {rse}): "
            f"the filtered acceleration (rms {np.std(data.acceleration):.3g}) does not stand out from the "
            "friction and noise; excite faster torque changes or record longer"
        )
    warnings = []
    if model.ms_stiffness.size == 0:
        warnings.append("no Maxwell-slip element identified: the run shows no presliding hysteresis")
    b, se_b = model.viscous, model.std_errors.get("viscous", np.nan)
    if s.viscous and b > 0 and np.isfinite(se_b) and se_b > 0.5 * b:
        warnings.append(
            f"viscous b poorly determined (relative standard error {100 * se_b / b:.0f} %): "
            "the run has little sliding velocity"
        )
    return warnings


def _refine_thresholds(x, y, lin, data, deltas, bounds: tuple[float, float]) -> np.ndarray:
    """Variable projection: minimise the NNLS residual over log Delta (scipy least_squares), each Delta kept
    inside the candidate grid's range (below it the data cannot resolve a threshold, and an unbounded step
    can make an element so stiff that no simulation is stable)."""
    from scipy.optimize import least_squares

    def residual(logd: np.ndarray) -> np.ndarray:
        d = np.sort(np.exp(logd))
        a = np.column_stack([lin, stop_columns(x, d, data)])
        coef, _ = _solve(a, y)
        return y - a @ coef

    lo, hi = np.log(bounds[0]), np.log(bounds[1])
    start = np.clip(np.log(deltas), lo + 1e-9, hi - 1e-9)
    sol = least_squares(residual, start, bounds=(lo, hi), method="trf", x_scale=1.0, diff_step=1e-3, max_nfev=30)
    return np.sort(np.exp(sol.x))


def predict_filtered(
    model: FrictionModel,
    position: np.ndarray,
    torque: np.ndarray,
    fs: float,
    cutoff: float,
    *,
    order: int = 4,
    decimation: int = 1,
    timing: str = "hold_next",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Equation-error prediction on any run: (L[tau], model's L[tau], row indices) at the kept rows."""
    x = np.asarray(position, float)
    data = filtered_data(x, torque, fs, cutoff, order=order, decimation=decimation, timing=timing)
    pred = model.inertia * data.acceleration + model.viscous * data.velocity + model.coulomb * data.sign
    pred = pred + model.spring * data.position + model.offset
    if model.ms_delta.size:
        pred = pred + stop_columns(x, model.ms_delta, data) @ model.ms_stiffness
    return data.torque, pred, data.rows
