"""Hilbert-transform side of the instantaneous analysis: band mask and edge length.

The analytic signal x + j*H[x] is ``scipy.signal.hilbert``'s: the FFT of x with negative frequencies removed
and positive ones doubled. :mod:`analysis.skeleton.instantaneous` computes it with the same chunked spectral code as
the wavelet (gain G(f) = 1, or the mask below), which also gives its exact time derivatives.
"""

from __future__ import annotations

import math

import numpy as np

#: Width of the raised-cosine band edges, relative to the edge frequency.
TAPER = 0.25


def band_gain(f: np.ndarray, band: tuple[float, float] | None) -> np.ndarray:
    """Zero-phase band-pass gain on frequencies f (Hz): 1 inside band, raised-cosine tapers of relative width
    TAPER outside, 0 beyond; all ones when band is None. Applied identically to response and force, so
    Feldman's ForceVib identities still hold exactly for a linear system."""
    f = np.asarray(f, dtype=float)
    if band is None:
        return np.ones_like(f)
    lo, hi = band
    g = np.ones_like(f)
    if lo > 0:
        w = TAPER * lo
        below = f < lo
        g[below] = 0.5 * (1.0 + np.cos(math.pi * np.clip((lo - f[below]) / w, 0.0, 1.0)))
    w = TAPER * hi
    above = f > hi
    g[above] = 0.5 * (1.0 + np.cos(math.pi * np.clip((f[above] - hi) / w, 0.0, 1.0)))
    return g


def default_edge(duration: float, band: tuple[float, float] | None) -> float:
    """Seconds discarded at each end of a Hilbert analysis.

    The Hilbert kernel 1/(pi*t) decays slowly, so a record cut mid-vibration disturbs the envelope over many
    periods: keep 5 % of the record, and at least 3 periods of the lowest band frequency when a band is set.
    """
    edge = 0.05 * duration
    if band is not None and band[0] > 0:
        edge = max(edge, 3.0 / band[0])
    return edge
