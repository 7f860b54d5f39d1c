"""Rolling-friction virgin curve, its exact Maxwell-slip discretisation, and reference parameter sets.

References: ``docs/science.md`` §2 (virgin curve, Masing rules, discretisation) and §6 (DC motor).
"""

from __future__ import annotations

import numpy as np

from hilbench.firmware_sim.engine.plant import PlantParameterError, PlantParams


def virgin_curve(x: np.ndarray, h: float, d: float) -> np.ndarray:
    """Rolling-friction virgin curve phi(x) = h*[1 - (d/(d+|x|))^2]*sign(x) (Al-Bender and Symens).

    Args:
        x: displacement, any shape (rad or m).
        h: limit force as |x| -> inf (N*m or N).
        d: characteristic presliding displacement (rad or m); the initial slope is 2h/d.
    """
    x = np.asarray(x, dtype=float)
    return h * (1.0 - (d / (d + np.abs(x))) ** 2) * np.sign(x)


def geometric_breakpoints(d: float, n: int, lo: float = 0.005, hi: float = 40.0) -> np.ndarray:
    """n breakpoints spaced geometrically from lo*d to hi*d."""
    if n < 1:
        raise PlantParameterError(f"need at least one element, got n={n}")
    if n == 1:
        return np.array([hi * d])
    return d * np.geomspace(lo, hi, n)


def discretise_virgin_curve(breakpoints: np.ndarray, h: float, d: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact Maxwell-slip discretisation of the virgin curve through the given breakpoints.

    With 0 < Delta_1 < ... < Delta_N, s_j = [phi(Delta_j) - phi(Delta_{j-1})]/(Delta_j - Delta_{j-1})
    (Delta_0 = 0) and s_{N+1} = 0, the elements are k_j = s_j - s_{j+1} and W_j = k_j*Delta_j
    (science.md §2). The resulting virgin curve is the piecewise-linear interpolant of phi through the
    breakpoints, flat beyond Delta_N.

    Returns:
        (k, W): stiffnesses (N*m/rad) and slip forces (N*m), each shape (N,).
    """
    b = np.asarray(breakpoints, dtype=float)
    if b.ndim != 1 or b.size == 0 or b[0] <= 0 or np.any(np.diff(b) <= 0):
        raise PlantParameterError("breakpoints must be positive and strictly increasing")
    nodes = np.concatenate([[0.0], b])
    phi = virgin_curve(nodes, h, d)
    s = np.diff(phi) / np.diff(nodes)
    k = s - np.concatenate([s[1:], [0.0]])
    return k, k * b


def maxwell_virgin_curve(x: np.ndarray, k: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Virgin curve of a Maxwell-slip model: sum_i k_i*clip(x, -Delta_i, Delta_i) (N*m)."""
    x = np.asarray(x, dtype=float)
    k = np.asarray(k, dtype=float)
    delta = np.asarray(w, dtype=float) / k
    return np.sum(k * np.clip(x[..., None], -delta, delta), axis=-1)


PAPER_MASS = 1.0
PAPER_H = 1.64
PAPER_D = 0.656
PAPER_SPRING = 50.0


def paper_system(n: int = 16, spring: float = PAPER_SPRING) -> PlantParams:
    """The paper's simulated mass-spring system (Table 1, inferred values: science.md §2):
    m = 1 kg, h = 1.64 N, d = 0.656 m, linear spring k = 50 N/m, n Maxwell-slip elements."""
    k, w = discretise_virgin_curve(geometric_breakpoints(PAPER_D, n), PAPER_H, PAPER_D)
    return PlantParams(inertia=PAPER_MASS, spring=spring, ms_stiffness=tuple(k), ms_slip=tuple(w))


DC_MOTOR_INERTIA = 0.0022
DC_MOTOR_BREAKAWAY = 0.76
DC_MOTOR_D = 5e-4
DC_MOTOR_VISCOUS = 4e-3
DC_MOTOR_TORQUE_CONSTANT = 0.2


def dc_motor(n: int = 16) -> PlantParams:
    """A DC-motor-like system after the paper's Section 7 (science.md §6): J = 0.0022 kg*m^2,
    break-away sum(W_i) = 0.76 N*m over n elements on a rolling-friction virgin curve with d = 0.5 mrad,
    viscous b = 0.004 N*m*s/rad and torque constant 0.2 N*m/A. No injected effects."""
    breakpoints = geometric_breakpoints(DC_MOTOR_D, n)
    k, w = discretise_virgin_curve(breakpoints, 1.0, DC_MOTOR_D)
    scale = DC_MOTOR_BREAKAWAY / float(np.sum(w))
    return PlantParams(
        inertia=DC_MOTOR_INERTIA,
        ms_stiffness=tuple(k * scale),
        ms_slip=tuple(w * scale),
        viscous=DC_MOTOR_VISCOUS,
        torque_constant=DC_MOTOR_TORQUE_CONSTANT,
    )
