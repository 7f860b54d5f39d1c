"""The equivalent (geometrically nonlinear) model of a friction system, from its skeleton curves.

Equivalent model (Tjahjowidodo 2012, §6; issue 6 item 3), simulated by the one C engine through the plant's
``restoring_table`` / ``damping_table`` (odd extension, linear interpolation, held beyond the end):

    m*x'' + F_k(x) + F_d(x') (+ k*x) = F(t)

The skeleton analysis (:mod:`analysis.skeleton.forcevib`) does not measure F_k(x) and F_d(v) directly. It measures the
first-harmonic (describing-function) forces against *amplitudes*:

    P_k(A) = k_eq(A)*A        restoring force of the friction against displacement amplitude A
    P_d(V) = c_eq*V           damping force against velocity amplitude V = A*omega

Two ways to turn them into functions of the instantaneous x and v (``form``):

- ``"direct"`` (the paper's choice): F_k(x) = P_k(|x|)*sign(x), F_d(v) = P_d(|v|)*sign(v). Simple, but the
  first harmonic of F_k(A*sin(theta)) is not P_k(A): for a softening curve it is larger (the spring is
  stiffer than the skeleton at every amplitude), and the describing function of the damping differs alike.
- ``"describing"`` (default): the F_k whose describing function IS the skeleton,

      P(A) = (4/pi) * integral_0^{pi/2} F(A*sin(theta)) * sin(theta) dtheta,

  an Abel-type equation. With F piecewise linear on a grid 0 = x_0 < x_1 < ... < x_n and P sampled at the
  nodes, P = M @ F with M lower triangular (P(x_j) only sees F on [0, x_j]); it is solved by forward
  substitution. The same inversion gives F_d from P_d. Closed-form checks: F = k3*x^3 <-> P = 3/4*k3*A^3;
  F = F_c*sign(v) <-> P = 4*F_c/pi (Coulomb).

Either way P_d is a function of V along the path the chirp took (near resonance, omega ~ omega_n(A)); the
equivalent damping is therefore exact in first harmonic only near that path (the paper's limitation too).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.skeleton.forcevib import SkeletonCurves
from hilbench.analysis.skeleton.skeleton_fit import MonotoneSkeleton, PaperFit, fit_skeleton_monotone
from hilbench.firmware_sim.engine.plant import RK4_STABLE_RADIUS, PlantParams, stiffest_eigenvalue

FORMS = ("describing", "direct")
#: Gauss-Legendre nodes on [0, pi/2] for the describing-function integral.
N_THETA = 256


def describing_matrix(grid: np.ndarray, n_theta: int = N_THETA) -> np.ndarray:
    """Matrix M, shape (n, n), with P(grid[j]) = sum_i M[j-1, i-1]*F(grid[i]) for i, j = 1..n.

    F is the piecewise-linear function through (grid, F) with F(0) = 0 (grid[0] must be 0, increasing),
    P(A) = (4/pi)*int_0^{pi/2} F(A sin th) sin th dth its first-harmonic (in-phase) amplitude, by
    Gauss-Legendre quadrature with ``n_theta`` nodes. M is lower triangular.
    """
    grid = np.asarray(grid, dtype=float)
    if grid.ndim != 1 or grid.size < 2 or grid[0] != 0.0 or np.any(np.diff(grid) <= 0):
        raise AnalysisError("grid must start at 0 and increase strictly")
    z, w = np.polynomial.legendre.leggauss(n_theta)
    th = (z + 1.0) * (math.pi / 4.0)
    w = w * (math.pi / 4.0) * np.sin(th) * (4.0 / math.pi)
    s = np.sin(th)
    n = grid.size - 1
    u = grid[1:, None] * s[None, :]  # (n, n_theta) arguments A_j*sin(theta)
    # hat function i evaluated at u: piecewise-linear weights of the two bracketing nodes
    idx = np.clip(np.searchsorted(grid, u, side="right") - 1, 0, n - 1)
    frac = (u - grid[idx]) / (grid[idx + 1] - grid[idx])
    m = np.zeros((n, n + 1))
    rows = np.broadcast_to(np.arange(n)[:, None], u.shape)
    np.add.at(m, (rows, idx), (1.0 - frac) * w)
    np.add.at(m, (rows, idx + 1), frac * w)
    return m[:, 1:]  # column 0 multiplies F(0) = 0


def describing_function(
    grid: np.ndarray, values: np.ndarray, amplitudes: np.ndarray, n_theta: int = N_THETA
) -> np.ndarray:
    """First-harmonic amplitude P(A) of the odd piecewise-linear F through (grid, values), held beyond the
    end like the plant's tables; amplitudes shape (k,) >= 0, returns shape (k,) in the unit of ``values``."""
    grid = np.asarray(grid, dtype=float)
    values = np.asarray(values, dtype=float)
    a = np.asarray(amplitudes, dtype=float)
    z, w = np.polynomial.legendre.leggauss(n_theta)
    th = (z + 1.0) * (math.pi / 4.0)
    f = np.interp(a[:, None] * np.sin(th)[None, :], grid, values)
    return (f * (w * (math.pi / 4.0) * np.sin(th))).sum(axis=1) * (4.0 / math.pi)


def invert_describing_function(grid: np.ndarray, first_harmonic: np.ndarray) -> np.ndarray:
    """F on ``grid`` (F(0) = 0) whose describing function equals ``first_harmonic`` at grid[1:].

    Args:
        grid: 0 = x_0 < x_1 < ... < x_n, shape (n+1,), m or m/s.
        first_harmonic: P(x_j) for j = 1..n, shape (n,), N.
    Returns:
        F(grid), shape (n+1,), N. Accuracy ~ the grid's relative spacing (1e-3 on 200 log-spaced nodes per
        4 decades) once past the first few nodes, where the piecewise-linear F cannot follow a curved F.
    """
    m = describing_matrix(grid)
    p = np.asarray(first_harmonic, dtype=float)
    if p.shape != (m.shape[0],):
        raise AnalysisError(f"first_harmonic must have shape ({m.shape[0]},), got {p.shape}")
    return np.concatenate([[0.0], solve_triangular(m, p, lower=True)])


@dataclass(frozen=True)
class SkeletonFunctions:
    """First-harmonic forces of the friction against amplitude, and where the data supports them.

    Attributes:
        restoring: P_k(A) = k_eq(A)*A, A in m -> N (spring subtracted).
        damping: P_d(V) = c_eq*V, V in m/s -> N.
        amplitude_range: (A_min, A_max) covered by the skeleton, m.
        velocity_range: (V_min, V_max), m/s.
    """

    restoring: Callable[[np.ndarray], np.ndarray]
    damping: Callable[[np.ndarray], np.ndarray]
    amplitude_range: tuple[float, float]
    velocity_range: tuple[float, float]


def skeleton_functions(
    source,
    amplitude_range: tuple[float, float] | None = None,
    velocity_range: tuple[float, float] | None = None,
) -> SkeletonFunctions:
    """P_k(A) and P_d(V) from composed curves, a monotone fit or the paper's fits.

    Args:
        source: :class:`SkeletonCurves` (fitted here with the monotone PCHIP/isotonic fit),
            :class:`MonotoneSkeleton`, or a pair (restoring :class:`PaperFit`, damping :class:`PaperFit`).
        amplitude_range, velocity_range: override the ranges (required for paper fits, which carry none).
    """
    if isinstance(source, SkeletonCurves):
        source = fit_skeleton_monotone(
            source.amplitude, source.stiffness, source.velocity, source.damping_force
        )
    if isinstance(source, MonotoneSkeleton):
        ar = (float(source.stiffness.knots_x[0]), float(source.stiffness.knots_x[-1]))
        vr = (float(source.damping_force.knots_x[0]), float(source.damping_force.knots_x[-1]))
        restoring, damping = source.restoring_force, source.damping_force
    elif (
        isinstance(source, tuple)
        and len(source) == 2
        and all(isinstance(s, PaperFit) for s in source)
        and source[0].form == "restoring"
        and source[1].form == "damping"
    ):
        if amplitude_range is None or velocity_range is None:
            raise AnalysisError("paper fits carry no data range: give amplitude_range and velocity_range")
        ar, vr = amplitude_range, velocity_range
        restoring, damping = source
    else:
        raise AnalysisError(
            "source must be SkeletonCurves, MonotoneSkeleton or (restoring, damping) PaperFits, "
            f"got {type(source).__name__}"
        )
    ar = amplitude_range or ar
    vr = velocity_range or vr
    for name, (lo, hi) in (("amplitude_range", ar), ("velocity_range", vr)):
        if not (0 < lo < hi and math.isfinite(hi)):
            raise AnalysisError(f"{name} must satisfy 0 < min < max, got {(lo, hi)}")
    return SkeletonFunctions(restoring, damping, (float(ar[0]), float(ar[1])), (float(vr[0]), float(vr[1])))


def _linear_below(fun: Callable, lo: float) -> Callable[[np.ndarray], np.ndarray]:
    """fun above lo; the straight line through the origin and (lo, fun(lo)) below it."""
    f_lo = float(np.asarray(fun(np.array([lo])))[0])

    def g(x):
        x = np.asarray(x, dtype=float)
        return np.where(x >= lo, fun(np.maximum(x, lo)), f_lo * x / lo)

    return g


def equivalent_tables(
    source, form: str = "describing", n: int = 240, **ranges
) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """((x grid m, F_k N), (v grid m/s, F_d N)) for the plant, each grid 0 plus n log-spaced nodes.

    The grids run from 1/100 of the skeleton's smallest amplitude (velocity) to its largest. Below the
    smallest one P is extended as a straight line through the origin (all elements stick there: the
    friction is a linear spring, and the damping vanishes, the paper's dead-zone); above the largest the
    plant holds the last value. ``form``: "describing" (default) or "direct", see the module docstring.
    A restoring F_k that the inversion would make negative is clipped at 0 (friction never pushes away).
    """
    if form not in FORMS:
        raise AnalysisError(f"form must be one of {FORMS}, got {form!r}")
    sk = skeleton_functions(source, **ranges)
    out = []
    for fun, (lo, hi), clip in (
        (sk.restoring, sk.amplitude_range, True),
        (sk.damping, sk.velocity_range, False),
    ):
        grid = np.concatenate([[0.0], np.geomspace(lo / 100.0, hi, n)])
        p = _linear_below(fun, lo)(grid[1:])
        f = np.concatenate([[0.0], p]) if form == "direct" else invert_describing_function(grid, p)
        if clip:
            f = np.maximum(f, 0.0)
        if not np.all(np.isfinite(f)):
            raise AnalysisError("the skeleton gives a non-finite equivalent curve")
        out.append((grid, f))
    return out[0], out[1]


def equivalent_params(
    source, mass: float, spring: float = 0.0, *, form: str = "describing", n: int = 240, **ranges
) -> PlantParams:
    """PlantParams of the equivalent model m*x'' + F_k(x) + F_d(x') + spring*x = F.

    Args:
        source: SkeletonCurves, MonotoneSkeleton or (restoring, damping) PaperFits
            (see ``skeleton_functions``).
        mass: m, kg (J, kg*m^2 for a rotary axis), > 0.
        spring: linear spring k, N/m (N*m/rad), >= 0 (the skeleton's curves have it subtracted).
        form: "describing" (default: F_k's first harmonic equals k_eq(A)*A) or "direct" (the paper's).
        n: table nodes per curve.
        **ranges: amplitude_range, velocity_range overrides (m, m/s).
    Returns:
        PlantParams with inertia, spring, restoring_table and damping_table set (torque_constant 1: the input
        is the force).
    """
    if not (math.isfinite(mass) and mass > 0):
        raise AnalysisError(f"mass must be positive, got {mass}")
    if not (math.isfinite(spring) and spring >= 0):
        raise AnalysisError(f"spring must be >= 0, got {spring}")
    fk, fd = equivalent_tables(source, form, n, **ranges)
    return PlantParams(inertia=float(mass), spring=float(spring), restoring_table=fk, damping_table=fd)


def coulomb_params(params: PlantParams, breakaway: float | None = None) -> PlantParams:
    """The paper's Coulomb comparison model: same inertia and spring, friction F_c*sign(v) with F_c the
    break-away sum(W_i) of ``params`` unless given, N (N*m). Other friction terms removed."""
    fc = float(np.sum(params.ms_slip)) if breakaway is None else float(breakaway)
    return PlantParams(
        inertia=params.inertia, spring=params.spring, coulomb=fc, torque_constant=params.torque_constant
    )


def stable_substeps(params: PlantParams, dt: float, minimum: int = 1) -> int:
    """Smallest number of sub-steps (>= minimum) for which the plant accepts ``params`` at step dt, s."""
    lam = stiffest_eigenvalue(params)
    need = max(int(minimum), math.ceil(lam * dt / (0.98 * RK4_STABLE_RADIUS)))
    return need

