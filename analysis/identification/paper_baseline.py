"""The paper's identification, kept for comparison: a global search, then Nelder-Mead, on the
simulation error of a Maxwell-slip model with N elements (Tjahjowidodo 2012 used a GA; we use
scipy.optimize.differential_evolution, the same family of population search).

Parameters searched (all in log10): J, and for each element k_i and Delta_i; b is searched
linearly. Bounds are ranged from the data: Delta from the same automatic grid range as the NNLS
method, k_i up to max|tau|/Delta_min, J from 0.01 to 10 times the crude scale rms(L tau)/rms(L theta'').
Cost: mean squared simulated-position error (hilbench.analysis.identification.output_error.simulate_position).
"""

from __future__ import annotations

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.output_error import initial_velocity, simulate_position
from hilbench.analysis.identification.regressors import filtered_data, threshold_grid
from hilbench.analysis.models.friction_model import FrictionModel, check_axis


def fit_paper(
    position: np.ndarray,
    torque: np.ndarray,
    fs: float,
    axis: str = "rotary",
    *,
    n_elements: int = 16,
    timing: str = "hold_next",
    maxiter: int = 20,
    popsize: int = 5,
    nm_maxfev: int = 500,
    seed: int = 0,
) -> tuple[FrictionModel, dict]:
    """Differential evolution (``maxiter`` generations of ``popsize`` x dims) then Nelder-Mead.

    Returns the model and figures (cost, evaluations). Small budgets give a poor fit: that is the
    point of the comparison (benchmarks/bench_identification.py), not a defect.
    """
    from scipy.optimize import differential_evolution, minimize

    check_axis(axis)
    x = np.asarray(position, float)
    tau = np.asarray(torque, float)
    if n_elements < 1:
        raise AnalysisError(f"n_elements must be >= 1, got {n_elements}")
    grid = threshold_grid(x, 2)
    d_lo, d_hi = float(grid[0]), float(grid[-1])
    data = filtered_data(x, tau, fs, fs / 20.0, decimation=max(1, int(fs / 50)), timing=timing)
    j_scale = float(np.std(data.torque) / max(np.std(data.acceleration), 1e-300))
    b_max = float(np.std(data.torque) / max(np.std(data.velocity), 1e-300))
    k_hi = float(np.max(np.abs(tau))) / d_lo
    bounds = [(np.log10(j_scale) - 2, np.log10(j_scale) + 1)]
    bounds += [(np.log10(k_hi) - 8, np.log10(k_hi))] * n_elements
    bounds += [(np.log10(d_lo), np.log10(d_hi))] * n_elements
    bounds += [(0.0, b_max)]
    theta0, omega0 = float(x[0]), initial_velocity(x, fs)
    var = float(np.var(x)) or 1.0

    def model_of(v: np.ndarray) -> FrictionModel:
        n = n_elements
        return FrictionModel(
            axis=axis,
            inertia=10 ** v[0],
            ms_stiffness=10 ** v[1 : 1 + n],
            ms_delta=10 ** v[1 + n : 1 + 2 * n],
            viscous=float(v[-1]),
        )

    evaluations = 0

    def cost(v: np.ndarray) -> float:
        nonlocal evaluations
        evaluations += 1
        try:
            sim = simulate_position(model_of(v), tau, fs, timing=timing, theta0=theta0, omega0=omega0)
        except AnalysisError:
            return 1e6
        return float(np.mean((sim - x) ** 2) / var)

    de = differential_evolution(
        cost, bounds, maxiter=maxiter, popsize=popsize, seed=seed, polish=False, tol=1e-8, init="sobol"
    )
    nm = minimize(
        cost, de.x, method="Nelder-Mead", options={"maxfev": nm_maxfev, "xatol": 1e-6, "fatol": 1e-12}
    )
    best = nm.x if nm.fun <= de.fun else de.x
    return model_of(best), {"de_cost": float(de.fun), "nm_cost": float(nm.fun), "evaluations": evaluations}
