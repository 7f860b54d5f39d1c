"""Default identification: linear in parameters, non-negative least squares on filtered regressors.

    L[tau] = J*L[theta''] + sum_i k_i*L[S_Delta_i[theta]] + b*L[theta'] (+ Fc*L[sign theta'] + c0 + K*L[theta])

with the Delta_i on a log-spaced candidate grid ranged from the data (hilbench.analysis.identification.regressors), all
coefficients >= 0 except the offset c0 (split into two non-negative columns). Solved with
scipy.optimize.nnls on unit-norm columns, on the triangular factor R of the regression rows, which are
accumulated block by block (``chunked``; docs/long-runs.md), so memory does not grow with the record.
On whole arrays the passes are kept (``_HeldPasses``): the record is filtered once for the candidate grid and
once for the merged thresholds, and every later subset (pruning, prediction, bootstrap) picks its columns.
Then adjacent active thresholds are merged, tiny elements pruned, and (optionally) the thresholds refined
by variable projection (NNLS inside a Levenberg-Marquardt on log Delta).

Standard errors. On whole arrays (:func:`fit_lip`): a HAC (Newey-West) sandwich covariance on the active
columns (analysis.identification.uncertainty), raised to a moving-block bootstrap of the NNLS on the whole
threshold grid where that is larger: the filtered residuals and regressors are autocorrelated even after
thinning, and the active set changes from record to record. The break-away sum k_i*Delta_i + Fc gets its
standard error from the same covariance. On a record read chunk by chunk (:func:`fit_lip_chunks`, a long
record over the memory budget): sigma^2 (A_a^T A_a)^-1 from the triangular factor, inflated by n/n_eff of the
residual (regressors.effective_sample_count), which is smaller than the spread (docs/model-file.md).
Parameters at their bound (zero) get no standard error (NaN): the linearised covariance does not apply there.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.chunked import BLOCK, ChunkSource, RecordScan, array_chunks, blocks, scan
from hilbench.analysis.identification.regressors import (
    edge_samples,
    effective_sample_count,
    filtered_data,
    reversal_travels,
    threshold_grid,
)
from hilbench.analysis.identification.uncertainty import bootstrap_standard_errors, hac_covariance
from hilbench.analysis.models.friction_model import FrictionModel, check_axis
from hilbench.common.metrics import nrmse


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


def _lin_columns(blk, s: LipSettings) -> tuple[list[np.ndarray], list[str]]:
    """The linear columns (all but the stop operator) of a block of rows, and their parameter names."""
    cols, names = ([blk.acceleration], ["inertia"]) if s.fixed_inertia is None else ([], [])
    if s.viscous:
        cols.append(blk.velocity)
        names.append("viscous")
    if s.coulomb:
        cols.append(blk.sign)
        names.append("coulomb")
    if s.spring:
        cols.append(blk.position)
        names.append("spring")
    if s.offset:
        one = np.ones_like(blk.torque)
        cols += [one, -one]
        names += ["offset+", "offset-"]
    return cols, names


def _block_system(blk, s: LipSettings) -> tuple[np.ndarray, np.ndarray]:
    """(A, y) of a block: A = [linear columns, stop columns], y = L[tau] (minus J*L[theta''] for a known J)."""
    cols, _ = _lin_columns(blk, s)
    a = np.column_stack([*cols, blk.stop]) if cols else blk.stop
    y = blk.torque if s.fixed_inertia is None else blk.torque - s.fixed_inertia * blk.acceleration
    return a, y


@dataclass
class _Triangular:
    """R of the QR decomposition of [A | y] over every row so far, (p+1, p+1): A = Q R_11, Q^T y = r_12 and
    r_22^2 the residual sum of squares of the unconstrained least squares. Updated block by block."""

    r: np.ndarray
    rows: int = 0

    def add(self, a: np.ndarray, y: np.ndarray) -> None:
        stacked = np.vstack([self.r, np.column_stack([a, y])])
        self.r = np.linalg.qr(stacked, mode="r")[: self.r.shape[1]]
        self.rows += a.shape[0]

    def solve(self) -> tuple[np.ndarray, float]:
        """NNLS on unit-norm columns: coefficients in the original scaling and |A c - y|^2."""
        from scipy.optimize import nnls

        p = self.r.shape[1] - 1
        r11, r12, r22 = self.r[:p, :p], self.r[:p, p], self.r[p, p]
        norms = np.linalg.norm(r11, axis=0)  # = the column norms of A (Q has orthonormal columns)
        norms[norms == 0] = 1.0
        coef, rnorm = nnls(r11 / norms, r12, maxiter=50 * max(p, 1))
        return coef / norms, float(rnorm) ** 2 + float(r22) ** 2


@dataclass
class _Rows:
    """The regression of one block: A (linear columns, then one stop column per threshold), y, and what the
    prediction needs (L[tau], L[theta''] and the global row indices)."""

    a: np.ndarray
    y: np.ndarray
    torque: np.ndarray
    acceleration: np.ndarray
    rows: np.ndarray


def _pass(source: ChunkSource, fs: float, s: LipSettings, cutoff: float, dec: int, deltas: np.ndarray,
          block: int) -> Iterator[_Rows]:
    """One pass over the record: the regression rows with the thresholds ``deltas``, block by block."""
    for blk in blocks(source, fs, cutoff, order=s.order, decimation=dec, timing=s.timing, deltas=deltas,
                      block=block):
        a, y = _block_system(blk, s)
        yield _Rows(a, y, blk.torque, blk.acceleration, blk.rows)


class _HeldPasses:
    """The passes of a fit on whole arrays, kept: a later threshold set that is a subset of a kept one (the
    pruned elements, the final prediction, the bootstrap's whole grid) takes its columns instead of filtering
    the record again. Each stop column depends on its own threshold only, so the picked columns are the
    numbers a new pass computes, bit for bit. Memory: rows x columns x 8 bytes per kept pass, as the
    calibrated standard errors hold anyway; a record read in chunks keeps nothing."""

    def __init__(self, n_linear: int):
        self.n_linear = n_linear
        self.kept: list[tuple[np.ndarray, list[_Rows]]] = []

    def rows(self, deltas: np.ndarray, fresh: Callable[[], Iterator[_Rows]]) -> list[_Rows]:
        for kept_deltas, parts in self.kept:
            where = {float(d): i for i, d in enumerate(kept_deltas)}
            if all(float(d) in where for d in deltas):
                cols = np.concatenate([np.arange(self.n_linear), self.n_linear + np.array(
                    [where[float(d)] for d in deltas], dtype=int)])
                return [_Rows(p.a[:, cols], p.y, p.torque, p.acceleration, p.rows) for p in parts]
        parts = list(fresh())
        self.kept.append((np.array(deltas, float), parts))
        return parts


def _triangular(parts: Iterable[_Rows]) -> _Triangular:
    """The triangular factor of the regression rows ``parts``."""
    tri: _Triangular | None = None
    for p in parts:
        if tri is None:
            tri = _Triangular(np.zeros((0, p.a.shape[1] + 1)))
        tri.add(p.a, p.y)
    if tri is None:
        raise AnalysisError("run too short: no regression rows after dropping the filter start-up samples")
    return tri


def _regression(source: ChunkSource, fs: float, s: LipSettings, cutoff: float, dec: int, deltas: np.ndarray,
                block: int) -> _Triangular:
    """One pass over the record: the triangular factor of the regression with the thresholds ``deltas``."""
    return _triangular(_pass(source, fs, s, cutoff, dec, deltas, block))


def _covariance(r11: np.ndarray, n: int, residual: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Covariance of the active coefficients (inflated by n/n_eff), n_eff and cond of the active set, from R
    (A_a = Q R_a, so A_a^T A_a = R_a^T R_a and cond(A_a) = cond(R_a))."""
    ra = r11[:, active]
    p = ra.shape[1]
    if n <= p:
        raise AnalysisError(f"run too short: {n} rows for {p} active parameters")
    norms = np.linalg.norm(ra, axis=0)
    rn = ra / norms
    s2 = float(residual @ residual) / (n - p)
    n_eff = effective_sample_count(residual)
    inflate = max(1.0, n / n_eff)
    gram_inv = np.linalg.pinv(rn.T @ rn)
    cov = s2 * inflate * gram_inv / np.outer(norms, norms)
    return cov, n_eff, float(np.linalg.cond(rn))


def _hac_covariance(a: np.ndarray, residual: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, float, float]:
    """As :func:`_covariance`, from the rows of the active columns: the HAC sandwich (uncertainty.hac_covariance)."""
    aa = a[:, active]
    if aa.shape[0] <= aa.shape[1]:
        raise AnalysisError(f"run too short: {aa.shape[0]} rows for {aa.shape[1]} active parameters")
    norms = np.linalg.norm(aa, axis=0)
    norms[norms == 0] = 1.0
    cov, _ = hac_covariance(aa, residual)  # the scores' own autocorrelation
    return cov, effective_sample_count(residual), float(np.linalg.cond(aa / norms))


def _merge_adjacent(deltas: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Thresholds of merged elements: each run of adjacent active grid points becomes one element
    at the k-weighted mean Delta (the virgin curves agree below the first and above the last Delta)."""
    active = np.flatnonzero(k > 0)
    if active.size == 0:
        return active.astype(float)
    groups = np.split(active, np.flatnonzero(np.diff(active) > 1) + 1)
    return np.array([np.sum(k[g] * deltas[g]) / np.sum(k[g]) for g in groups])


def grid_from_scan(sc: RecordScan, n: int, delta_range: tuple[float, float] | None = None) -> np.ndarray:
    """``regressors.threshold_grid`` from a record scan (its resolution and thinned path)."""
    if delta_range is not None or n < 1:
        return threshold_grid(np.zeros(2), n, delta_range)
    res = sc.resolution
    travels = reversal_travels(sc.thinned, hysteresis=max(4 * res, 1e-15))
    hi = 0.5 * float(travels.max()) if travels.size else 0.0
    lo = max(2.0 * res, hi * 1e-5)
    if not hi > lo:
        raise AnalysisError(
            f"the position hardly moves (largest travel {2 * hi:.3g}, resolution {res:.3g}): "
            "the friction thresholds are unidentifiable; excite a larger displacement"
        )
    return np.geomspace(lo, hi, n)


def fit_lip(
    position: np.ndarray,
    torque: np.ndarray,
    fs: float,
    axis: str = "rotary",
    settings: LipSettings | None = None,
    *,
    block: int = BLOCK,
) -> LipFit:
    """Identify J, k_i (on a Delta grid), b (and optionally Fc, c0, K) by NNLS.

    Args:
        position: measured path theta, shape (n,), rad (rotary) or m (linear).
        torque: motor torque or force, shape (n,), N*m or N, with sample timing ``settings.timing``.
        fs: sampling rate, Hz.
        axis: "rotary" or "linear" (units only).
        block: samples per processing block (``chunked``); the result does not depend on it beyond rounding.
    Returns:
        :class:`LipFit`. Raises :class:`AnalysisError` for unusable input.
    """
    s = settings or LipSettings()
    x = np.asarray(position, float)
    tau = np.asarray(torque, float)
    if x.shape != tau.shape or x.ndim != 1:
        raise AnalysisError(f"position and torque must be 1-D of equal length, got {x.shape} and {tau.shape}")
    # the exact grid of the whole array (the chunk API estimates the noise level over blocks)
    grid = threshold_grid(x, s.n_thresholds, s.delta_range) if s.n_thresholds > 0 else np.empty(0)
    return fit_lip_chunks(array_chunks(x, tau), fs, axis, s, grid=grid, block=block, n_samples=x.size,
                          calibrated=True)


def fit_lip_chunks(
    source: ChunkSource,
    fs: float,
    axis: str = "rotary",
    settings: LipSettings | None = None,
    *,
    grid: np.ndarray | None = None,
    block: int = BLOCK,
    n_samples: int | None = None,
    calibrated: bool = False,
) -> LipFit:
    """:func:`fit_lip` on a record read chunk by chunk (``chunked``: a callable returning a fresh iterator of
    ``(position, torque)`` pairs). Memory is bounded by ``block`` and the thresholds, plus 24 bytes per
    regression row for the returned prediction. ``grid``: the candidate thresholds (default from one scan of
    the record); ``n_samples``: the record length if known (saves the scan when a grid is given).
    ``calibrated``: the HAC and bootstrap standard errors (module docstring), which hold the regression rows
    (rows x columns x 8 bytes); :func:`fit_lip` on whole arrays sets it."""
    s = settings or LipSettings()
    check_axis(axis)
    cutoff, dec = s.resolved(fs)
    if s.fixed_inertia is not None and not (np.isfinite(s.fixed_inertia) and s.fixed_inertia >= 0):
        raise AnalysisError(f"a fixed inertia must be finite and >= 0, got {s.fixed_inertia}")
    if grid is None or n_samples is None:
        sc = scan(source)
        n_samples = sc.n
        if grid is None:
            # n_thresholds 0: no Maxwell-slip elements (e.g. the EMPS reference model J, Fc, b, offset)
            grid = grid_from_scan(sc, s.n_thresholds, s.delta_range) if s.n_thresholds > 0 else np.empty(0)
    grid = np.asarray(grid, float)
    edge = edge_samples(fs, cutoff)
    n_rows = len(range(edge, n_samples - edge, dec))
    if n_rows < 10:
        raise AnalysisError(
            f"run too short: {n_samples} samples leave {n_rows} rows after dropping {edge} filter start-up "
            f"samples at each end (cutoff {cutoff:g} Hz); record longer or raise the cutoff"
        )
    _, names = _lin_columns(_EmptyRows(), s)
    nl = len(names)
    if n_rows <= nl + grid.size:  # least squares needs more rows than unknowns (the factor is square at most)
        raise AnalysisError(
            f"run too short: {n_samples} samples leave {n_rows} rows for {nl + grid.size} unknowns ({nl} linear "
            f"terms and {grid.size} thresholds); record longer, or fewer thresholds (--thresholds)"
        )

    # whole arrays: the passes are kept, and the later threshold sets (all subsets) pick their columns
    held = _HeldPasses(nl) if calibrated else None

    def rows_with(deltas: np.ndarray) -> Iterable[_Rows]:
        def fresh() -> Iterator[_Rows]:
            return _pass(source, fs, s, cutoff, dec, deltas, block)

        return fresh() if held is None else held.rows(deltas, fresh)

    def solve_with(deltas: np.ndarray) -> tuple[_Triangular, np.ndarray, float]:
        tri = _triangular(rows_with(deltas))
        coef, rss = tri.solve()
        return tri, coef, rss

    tri, coef, rss = solve_with(grid)
    deltas = grid
    if s.merge and np.count_nonzero(coef[nl:]) > 0:
        merged = _merge_adjacent(grid, coef[nl:])
        tri2, coef2, rss2 = solve_with(merged)
        if rss2 <= rss * 1.02:
            tri, coef, rss, deltas = tri2, coef2, rss2, merged
    k = coef[nl:]
    w = k * deltas
    if s.prune_fraction > 0 and w.sum() > 0:
        keep = w >= s.prune_fraction * w.sum()
        if not np.all(keep):
            deltas = deltas[keep]
            tri, coef, rss = solve_with(deltas)
    if s.refine and np.count_nonzero(coef[nl:]) > 0:
        deltas = _refine_thresholds(source, fs, s, cutoff, dec, block, deltas[coef[nl:] > 0], (grid[0], grid[-1]))
        tri, coef, rss = solve_with(deltas)

    # last pass: the prediction at every row (the plots' curves, the residual's colour)
    measured, predicted, rows, a_rows = [], [], [], []
    acc_sum = acc_sq = 0.0
    for part in rows_with(deltas):
        if calibrated:
            a_rows.append(part.a)
        measured.append(part.torque)
        predicted.append(part.a @ coef + (part.torque - part.y))  # plus the known J*acceleration, if any
        rows.append(part.rows)
        acc_sum += float(np.sum(part.acceleration))
        acc_sq += float(part.acceleration @ part.acceleration)
    measured_a, predicted_a, rows_a = np.concatenate(measured), np.concatenate(predicted), np.concatenate(rows)
    residual = measured_a - predicted_a
    active = coef > 0
    p = coef.size
    if calibrated:
        cov, n_eff, cond = _hac_covariance(np.concatenate(a_rows), residual, active)
        del a_rows
    else:
        cov, n_eff, cond = _covariance(tri.r[:p, :p], tri.rows, residual, active)
    se_all = np.full(coef.size, np.nan)
    se_all[active] = np.sqrt(np.clip(np.diag(cov), 0, None))

    values = dict(zip(names, coef[:nl], strict=True))
    ses = dict(zip(names, se_all[:nl], strict=True))
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
    grad = np.concatenate([[1.0 if n == "coulomb" else 0.0 for n in names], deltas])[active]
    std_errors["breakaway"] = float(np.sqrt(max(grad @ cov @ grad, 0.0)))
    if calibrated and grid.size:  # the larger of the two (uncertainty.bootstrap_standard_errors)
        grid_rows = rows_with(grid)  # the first pass's, kept
        a_grid = np.concatenate([p.a for p in grid_rows])
        y_grid = np.concatenate([p.y for p in grid_rows])
        bootstrap_standard_errors(std_errors, a_grid, y_grid, residual, names, grid)
        del a_grid, y_grid
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
    acc_std = float(np.sqrt(max(acc_sq / tri.rows - (acc_sum / tri.rows) ** 2, 0.0)))
    warnings = _identifiability(model, acc_std, s)
    return LipFit(model, s, cutoff, dec, grid, measured_a, predicted_a, rows_a, n_eff, cond, warnings)


class _EmptyRows:
    """Zero rows, for the column names alone."""

    torque = acceleration = velocity = position = sign = np.empty(0)


def _identifiability(model: FrictionModel, acc_std: float, s: LipSettings) -> list[str]:
    """Raise for an unidentifiable inertia; return warnings for the other parameters."""
    j, se_j = model.inertia, model.std_errors.get("inertia", np.nan)
    known = s.fixed_inertia is not None
    if not known and (not (j > 0) or not np.isfinite(se_j) or se_j > s.max_inertia_rse * j):
        rse = "inf" if not (j > 0 and np.isfinite(se_j)) else f"{100 * se_j / j:.0f} %"
        raise AnalysisError(
            f"inertia J is unidentifiable from this run (estimate {j:.4g}, relative standard error {rse}): "
            f"the filtered acceleration (rms {acc_std:.3g}) does not stand out from the "
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


def _refine_thresholds(source: ChunkSource, fs: float, s: LipSettings, cutoff: float, dec: int, block: int,
                       deltas: np.ndarray, bounds: tuple[float, float]) -> np.ndarray:
    """Variable projection: minimise the NNLS residual over log Delta (scipy least_squares), each Delta kept
    inside the candidate grid's range (below it the data cannot resolve a threshold, and an unbounded step
    can make an element so stiff that no simulation is stable). The residual vector is the triangular form's,
    [R_11 c - r_12, r_22], whose squared norm is the regression's |A c - y|^2; each evaluation is one pass."""
    from scipy.optimize import least_squares

    def residual(logd: np.ndarray) -> np.ndarray:
        tri = _regression(source, fs, s, cutoff, dec, np.sort(np.exp(logd)), block)
        coef, _ = tri.solve()
        p = coef.size
        return np.append(tri.r[:p, :p] @ coef - tri.r[:p, p], tri.r[p, p])

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
    block: int = BLOCK,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Equation-error prediction on any run: (L[tau], model's L[tau], row indices) at the kept rows."""
    x = np.asarray(position, float)
    tau = np.asarray(torque, float)
    edge = edge_samples(fs, cutoff)
    if len(range(edge, x.size - edge, max(1, int(decimation)))) < 10:
        filtered_data(x, tau, fs, cutoff, order=order, decimation=decimation, timing=timing)  # its message
    return predict_chunks(model, array_chunks(x, tau), fs, cutoff, order=order, decimation=decimation,
                          timing=timing, block=block)


def predict_chunks(
    model: FrictionModel,
    source: ChunkSource,
    fs: float,
    cutoff: float,
    *,
    order: int = 4,
    decimation: int = 1,
    timing: str = "hold_next",
    block: int = BLOCK,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`predict_filtered` on a record read chunk by chunk (``chunked``)."""
    measured, predicted, rows = [], [], []
    for blk in blocks(source, fs, cutoff, order=order, decimation=decimation, timing=timing,
                      deltas=model.ms_delta if model.ms_delta.size else None, block=block):
        pred = model.inertia * blk.acceleration + model.viscous * blk.velocity + model.coulomb * blk.sign
        pred = pred + model.spring * blk.position + model.offset
        if model.ms_delta.size:
            pred = pred + blk.stop @ model.ms_stiffness
        measured.append(blk.torque)
        predicted.append(pred)
        rows.append(blk.rows)
    if not rows:
        raise AnalysisError("run too short: no regression rows after dropping the filter start-up samples")
    return np.concatenate(measured), np.concatenate(predicted), np.concatenate(rows)
