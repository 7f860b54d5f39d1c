"""Steady hysteresis loops of a displacement-driven Maxwell-slip model, for closed-form tests."""

import numpy as np

from hilbench.firmware_sim.engine.plant import stop_operator


def sine_loop(k: np.ndarray, w: np.ndarray, amplitude: float, n: int = 100_000) -> tuple[float, float]:
    """Energy per cycle E = closed-integral F dx and first-harmonic in-phase stiffness
    k_eq = (1/(pi*A)) * integral_0^2pi F(phi) sin(phi) dphi, for x = A*sin(phi), after a quarter-cycle
    priming so the loop is steady. Trapezoidal rule; F is piecewise linear in phase, error O(n^-2)."""
    k = np.asarray(k, float)
    prime = amplitude * np.sin(np.linspace(0.0, np.pi / 2, 2001))
    phase = np.linspace(np.pi / 2, 2.5 * np.pi, n + 1)
    x = np.concatenate([prime, amplitude * np.sin(phase)[1:]])
    force = stop_operator(x, np.asarray(w, float) / k) @ k
    xs = x[prime.size - 1:]
    fs = force[prime.size - 1:]
    energy = np.trapezoid(fs, xs)
    keq = np.trapezoid(fs * np.sin(phase), phase) / (np.pi * amplitude)
    return float(energy), float(keq)
