"""Independent oracle for the skeleton tests: SDOF / Duffing under a chirp, integrated by scipy's DOP853.

m*x'' + c*x' + k*x + k3*x^3 = F(t),  F(t) = G*sin(pi*a*t^2) (instantaneous frequency a*t Hz),
integrated with rtol = 1e-10 and sampled at fs. This shares no code with analysis/ or firmware_sim/.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.integrate import solve_ivp


@lru_cache(maxsize=16)
def chirp_response(
    m: float, c: float, k: float, k3: float, G: float, a: float, duration: float, fs: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, x, F), each shape (round(duration*fs)+1,): t in s, x in m, F in N; starts at rest."""
    t = np.arange(int(round(duration * fs)) + 1) / fs

    def rhs(tt, y):
        x, v = y
        return [v, (G * np.sin(np.pi * a * tt * tt) - c * v - k * x - k3 * x**3) / m]

    sol = solve_ivp(rhs, (0.0, t[-1]), [0.0, 0.0], method="DOP853", t_eval=t, rtol=1e-10, atol=1e-13,
                    max_step=0.05 / max(a * duration, 1.0))
    if not sol.success:
        raise RuntimeError(sol.message)
    x = sol.y[0]
    for arr in (t, x):
        arr.setflags(write=False)
    force = G * np.sin(np.pi * a * t * t)
    force.setflags(write=False)
    return t, x, force
