"""The joint linear-in-parameters design of the residual loop and its bounded least-squares solve.

A model is a list of (term, nonlinear settings) pairs (``analysis.residual.candidates``). For one run
the equation error is

    L[tau](t - d) - J_fixed*L[theta''] = sum_terms A_term(theta, theta', t; settings) @ c_term + e

where d is the input delay of a ``delay`` term (0 otherwise) and J_fixed a known inertia (when the
user supplies one; then the inertia column is dropped). Runs are stacked row-wise. Coefficients with
a physical sign (inertia, stiffnesses, viscous, Stribeck excess, Coulomb levels) are >= 0; the others
are free. The solve is scipy.optimize.nnls on unit-norm columns, each free column split into a +/-
pair (the exact bounded least-squares solution).

Set-valued friction at rest: where the rotor is at rest (``RunData.rest``) a Coulomb or Stribeck
friction is a reaction anywhere in [-F_static, F_static], not a function of the state, so those rows
are left out of the fit, and their residual is the distance of the torque from the model's admissible
band: e = sign(r)*max(|r| - F_static, 0) with r the plain residual and F_static the sum of the model's
static friction levels (``Term.static_level``). A model without Coulomb-like friction has F_static = 0
and keeps its plain residual.

Standard errors: sigma^2 (A_a^T A_a)^-1 on the active columns (free, or non-zero), with sigma^2 =
|e|^2/(n - p_a), inflated by n/n_eff from the residual autocorrelation
(:func:`analysis.identification.regressors.effective_sample_count`), as in :mod:`analysis.identification.maxwell_fit`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.regressors import effective_sample_count
from hilbench.analysis.residual.rundata import RunData


@dataclass(frozen=True)
class Setting:
    """What every design shares: a known inertia (or None), the Maxwell-slip threshold grid (from
    the training runs), and the total input delay of the model (samples)."""

    fixed_inertia: float | None
    thresholds: np.ndarray
    delay: float = 0.0


@dataclass
class Design:
    """Stacked design of one model on a list of runs."""

    y: np.ndarray  # (N,)
    columns: np.ndarray  # (N, p)
    lower: np.ndarray  # (p,) 0 or -inf
    slices: dict  # term name -> slice into the columns
    run_rows: list  # (start, stop) of each run in the stack
    rest: np.ndarray  # (N,) bool, rows at rest


def build_design(model: list, runs: list[RunData], setting: Setting) -> Design:
    """Stack y and the term columns of ``model`` = [(term, nl), ...] over ``runs``."""
    delay = sum(term.delay(nl) for term, nl in model)
    s = Setting(setting.fixed_inertia, setting.thresholds, delay)
    ys, blocks, run_rows, rests, start = [], [], [], [], 0
    for run in runs:
        y = run.torque_rows(delay)
        if s.fixed_inertia is not None:
            y = y - s.fixed_inertia * run.data.acceleration
        cols = [term.columns(run, nl, s) for term, nl in model]
        ys.append(y)
        rests.append(run.rest if run.rest is not None else np.zeros(y.size, bool))
        blocks.append(cols)
        run_rows.append((start, start + y.size))
        start += y.size
    slices, lower, k = {}, [], 0
    for i, (term, nl) in enumerate(model):
        q = blocks[0][i].shape[1]
        slices[term.name] = slice(k, k + q)
        lower.append(np.asarray(term.lower(nl, q), float))
        k += q
    a = np.vstack([np.column_stack(cols) if cols else np.zeros((len(y), 0)) for cols, y in zip(blocks, ys,
                                                                                               strict=True)])
    return Design(np.concatenate(ys), a, np.concatenate(lower) if lower else np.zeros(0), slices, run_rows,
                  np.concatenate(rests))


def static_band(model: list, coef: np.ndarray, slices: dict) -> float:
    """Sum of the model's static friction levels F_static (N*m or N)."""
    return float(sum(term.static_level(coef[slices[term.name]]) for term, _ in model))


def project_rest(residual: np.ndarray, rest: np.ndarray, band: float) -> np.ndarray:
    """Residual with the rows at rest replaced by their distance from the band [-band, band]."""
    e = np.asarray(residual, float).copy()
    e[rest] = np.sign(e[rest]) * np.maximum(np.abs(e[rest]) - band, 0.0)
    return e


def bounded_lstsq(a: np.ndarray, y: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """min |y - a c|^2 subject to c_j >= 0 where lower_j == 0 (c_j free where lower_j == -inf).

    Exact: free columns enter scipy.optimize.nnls as a (+col, -col) pair; unit-norm scaling."""
    from scipy.optimize import nnls

    if a.shape[1] == 0:
        return np.zeros(0)
    free = ~(np.asarray(lower) == 0)
    norms = np.linalg.norm(a, axis=0)
    norms[norms == 0] = 1.0
    an = a / norms
    big = np.column_stack([an, -an[:, free]])
    sol, _ = nnls(big, y, maxiter=50 * big.shape[1])
    c = sol[: a.shape[1]].copy()
    c[free] -= sol[a.shape[1]:]
    return c / norms


@dataclass
class Fit:
    """A fitted model: coefficients per term, covariance of the active coefficients, residuals."""

    model: list
    setting: Setting
    coef: np.ndarray
    cov: np.ndarray  # (p, p), NaN rows/cols for inactive (at-bound) coefficients
    slices: dict
    residual: np.ndarray  # stacked training residual (rows at rest projected on the static band)
    y: np.ndarray
    n_eff: float
    run_rows: list = field(default_factory=list)
    rest: np.ndarray | None = None
    band: float = 0.0

    def term_coef(self, name: str) -> np.ndarray:
        return self.coef[self.slices[name]]

    def term_se(self, name: str) -> np.ndarray:
        sl = self.slices[name]
        return np.sqrt(np.clip(np.diag(self.cov)[sl], 0, None))

    def term_cov(self, name: str) -> np.ndarray:
        sl = self.slices[name]
        return self.cov[sl, sl]

    @property
    def sse(self) -> float:
        """Sum of squared residuals over the fitted rows (the rows not at rest)."""
        e = self.residual if self.rest is None else self.residual[~self.rest]
        return float(e @ e)


def fit_model(model: list, runs: list[RunData], setting: Setting, covariance: bool = True) -> Fit:
    """Bounded least squares of ``model`` on the stacked ``runs``."""
    d = build_design(model, runs, setting)
    moving = ~d.rest
    if moving.sum() <= 2 * d.columns.shape[1]:
        raise AnalysisError(f"too few moving rows: {int(moving.sum())} rows (of {d.y.size}) for "
                            f"{d.columns.shape[1]} parameters; excite more motion or record longer")
    coef = bounded_lstsq(d.columns[moving], d.y[moving], d.lower)
    band = static_band(model, coef, d.slices)
    e_all = project_rest(d.y - d.columns @ coef, d.rest, band)
    e = e_all[moving]
    p = coef.size
    cov = np.full((p, p), np.nan)
    n_eff = float(e.size)
    if covariance and p:
        active = (d.lower != 0) | (coef != 0)
        aa = d.columns[moving][:, active]
        n = e.size
        n_eff = effective_sample_count(e)
        s2 = float(e @ e) / max(n - int(active.sum()), 1)
        norms = np.linalg.norm(aa, axis=0)
        norms[norms == 0] = 1.0
        an = aa / norms
        c = s2 * max(1.0, n / n_eff) * np.linalg.pinv(an.T @ an) / np.outer(norms, norms)
        idx = np.flatnonzero(active)
        cov[np.ix_(idx, idx)] = c
    return Fit(model, setting, coef, cov, d.slices, e_all, d.y, n_eff, d.run_rows, d.rest, band)


def predict(fit: Fit, runs: list[RunData]) -> tuple[np.ndarray, np.ndarray]:
    """(y, residual) of a fitted model on other runs (stacked), same parameters; rows at rest
    projected on the model's static band."""
    d = build_design(fit.model, runs, fit.setting)
    return d.y, project_rest(d.y - d.columns @ fit.coef, d.rest, fit.band)


def blocked_cv_residual(model: list, runs: list[RunData], setting: Setting, folds: int = 5,
                        gap: int = 2) -> np.ndarray:
    """Held-out residual (rows at rest projected) by blocked cross-validation over the stacked rows:
    ``folds`` contiguous blocks; each is predicted by the model fitted on the others with ``gap`` rows
    on each side of the block also left out of the fit (the filtered rows are correlated over a few
    rows)."""
    d = build_design(model, runs, setting)
    n = d.y.size
    edges = np.linspace(0, n, folds + 1).astype(int)
    out = np.empty(n)
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        train = ~d.rest
        train[max(0, lo - gap): min(n, hi + gap)] = False
        coef = bounded_lstsq(d.columns[train], d.y[train], d.lower)
        band = static_band(model, coef, d.slices)
        out[lo:hi] = project_rest(d.y[lo:hi] - d.columns[lo:hi] @ coef, d.rest[lo:hi], band)
    return out
