"""Force-from-displacement identification for presliding records:

    F = sum_i k_i*S_Delta_i[x] + b*x' + Fc*sign(x') + c0  (+ J*x'' when the inertia J is known)

linear in (k_i, b, Fc, c0) on a log-spaced grid of thresholds Delta_i (the grid of
hilbench.analysis.identification.regressors), solved by non-negative least squares (scipy.optimize.nnls) on the
raw samples: a quasi-static record needs no filtering, and a known J*x'' is subtracted from the force first. The
validation is the force simulated from the measured displacement by the identified model against the measured
force. (hilbench identify --inertia 0 fits the same model through the filtered equation-error regression.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.regressors import position_resolution, threshold_grid
from hilbench.analysis.models.friction_model import FrictionModel, check_axis
from hilbench.analysis.presliding.reversals import find_reversals


@dataclass(frozen=True)
class PreslidingSettings:
    """What the force model holds. ``inertia``: known J (kg*m^2 or kg; 0: none). ``n_thresholds``: size of the
    candidate Delta grid. ``delta_range``: (lo, hi) in m or rad, default from half the data's position step to
    half its largest travel."""

    inertia: float = 0.0
    viscous: bool = True
    coulomb: bool = False
    offset: bool = True
    n_thresholds: int = 48
    delta_range: tuple[float, float] | None = None


@dataclass
class PreslidingFit:
    """The identified model, the force it simulates from the measured displacement, and its error.

    ``simulated``: F_model(x) at every sample (N or N*m); ``rms_error``: rms(F - F_model) (N or N*m);
    ``relative_rms``: rms error / the model's sliding level sum(W_i) + Fc; ``grid``: the candidate Delta_i."""

    model: FrictionModel
    simulated: np.ndarray
    rms_error: float
    relative_rms: float
    grid: np.ndarray
    settings: PreslidingSettings


def _columns(x: np.ndarray, fs: float, deltas: np.ndarray, s: PreslidingSettings) -> tuple[np.ndarray, list[str]]:
    """Design matrix (n, p) on the raw samples and the names of its non-element columns (elements last)."""
    from hilbench.firmware_sim.engine.plant import stop_operator

    v = np.gradient(x) * fs
    cols, names = [], []
    if s.viscous:
        cols.append(v)
        names.append("viscous")
    if s.coulomb:
        cols.append(np.sign(v))
        names.append("coulomb")
    if s.offset:
        cols += [np.ones_like(x), -np.ones_like(x)]
        names += ["offset+", "offset-"]
    a = np.column_stack(cols + [stop_operator(x, deltas)]) if deltas.size else np.column_stack(cols)
    return a, names


def _nnls(a: np.ndarray, y: np.ndarray) -> np.ndarray:
    """NNLS on unit-norm columns (coefficients in the original scaling)."""
    from scipy.optimize import nnls

    norms = np.linalg.norm(a, axis=0)
    norms[norms == 0] = 1.0
    coef, _ = nnls(a / norms, y, maxiter=50 * a.shape[1])
    return coef / norms


def model_force(model: FrictionModel, x: np.ndarray, fs: float) -> np.ndarray:
    """Force (N or N*m) a model produces along the displacement x (m or rad, shape (n,)) sampled at fs (Hz):
    sum k_i*S_Delta_i[x] (elements relaxed at x[0]) + b*x' + Fc*sign(x') + c0 + J*x'' (central differences)."""
    from hilbench.firmware_sim.engine.plant import stop_operator

    x = np.asarray(x, float)
    v = np.gradient(x) * fs
    f = model.viscous * v + model.coulomb * np.sign(v) + model.offset
    if model.inertia:
        f = f + model.inertia * np.gradient(v) * fs
    if model.ms_delta.size:
        f = f + stop_operator(x, model.ms_delta) @ model.ms_stiffness
    return f


def fit_presliding(x: np.ndarray, force: np.ndarray, fs: float, axis: str = "rotary",
                   settings: PreslidingSettings | None = None, grid: np.ndarray | None = None,
                   step: float | None = None) -> PreslidingFit:
    """Identify the presliding force model from a displacement-driven record.

    Args:
        x: measured displacement, shape (n,), rad (rotary) or m (linear), starting relaxed.
        force: measured torque or force, shape (n,), N*m or N.
        fs: sample rate, Hz.
        axis: "rotary" or "linear".
        grid: candidate thresholds Delta_i (m or rad); default from half the position step to half the largest
            travel between reversals of more than 1.5 steps.
        step: the position step (m or rad); default measured from x (position_resolution).
    Returns:
        :class:`PreslidingFit`; AnalysisError for unusable input.
    """
    s = settings or PreslidingSettings()
    check_axis(axis)
    if not (np.isfinite(s.inertia) and s.inertia >= 0):
        raise AnalysisError(f"a known inertia must be finite and >= 0, got {s.inertia}")
    x = np.asarray(x, float)
    force = np.asarray(force, float)
    if x.shape != force.shape or x.ndim != 1 or x.size < 50:
        raise AnalysisError(f"need equal 1-D displacement and force arrays of at least 50 samples, got "
                            f"{x.shape} and {force.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(force)) and fs > 0):
        raise AnalysisError("displacement and force must be finite and the sample rate > 0")
    if grid is None and s.delta_range is None:
        # below one position step an element still shows as a force step at each reversal: start the grid at half
        # a step (threshold_grid starts at two; on a quantised presliding record that halves the virgin-curve error)
        # and end it at half the largest travel between reversals of more than 1.5 steps
        step = position_resolution(x) if step is None else step
        ends = np.concatenate([[0], find_reversals(x, 1.5 * step), [x.size - 1]])
        top = 0.5 * float(np.max(np.abs(np.diff(x[ends]))))
        if not top > 0:
            raise AnalysisError("the displacement does not move: nothing to identify")
        grid = np.geomspace(min(max(0.5 * step, top * 1e-5), top / 2), top, s.n_thresholds)
    elif grid is None:
        grid = threshold_grid(x, s.n_thresholds, s.delta_range)
    y = force - s.inertia * np.gradient(np.gradient(x) * fs) * fs if s.inertia else force
    a, names = _columns(x, fs, grid, s)
    coef = _nnls(a, y)
    nl = len(names)
    values = dict(zip(names, coef[:nl], strict=True))
    k = coef[nl:]
    keep = k > 0
    if not np.any(keep):
        raise AnalysisError("no Maxwell-slip element identified: the record shows no presliding hysteresis")
    model = FrictionModel(axis=axis, inertia=float(s.inertia), ms_stiffness=k[keep], ms_delta=grid[keep],
                          viscous=values.get("viscous", 0.0), coulomb=values.get("coulomb", 0.0),
                          offset=values.get("offset+", 0.0) - values.get("offset-", 0.0))
    sim = model_force(model, x, fs)
    rms = float(np.sqrt(np.mean((force - sim) ** 2)))
    return PreslidingFit(model, sim, rms, rms / model.breakaway, grid, s)
