"""The identification's zero-phase low-pass with its cached design: the same numbers as scipy.signal.sosfiltfilt
(the oracle), bit for bit, and a design computed once per (order, cutoff, rate)."""

import numpy as np
import pytest
from scipy import signal

from hilbench.analysis.identification.regressors import edge_samples, lowpass_design, zero_phase_lowpass


@pytest.mark.parametrize("shape", [(1400,), (3, 2000), (2, 2, 900)])
@pytest.mark.parametrize(("order", "cutoff", "fs"), [(4, 50.0, 1000.0), (2, 500.0, 10_000.0), (6, 33.3, 2000.0)])
def test_lowpass_is_scipy_sosfiltfilt_on_the_odd_extension(shape, order, cutoff, fs):
    x = np.random.default_rng(7).standard_normal(shape).cumsum(axis=-1)
    pad = min(edge_samples(fs, cutoff), shape[-1] - 1)
    ext = np.concatenate([2 * x[..., :1] - x[..., pad:0:-1], x, 2 * x[..., -1:] - x[..., -2:-pad - 2:-1]], axis=-1)
    oracle = signal.sosfiltfilt(signal.butter(order, cutoff, fs=fs, output="sos"), ext, axis=-1, padtype=None)
    assert np.array_equal(zero_phase_lowpass(x, fs, cutoff, order), oracle[..., pad:pad + shape[-1]])


def test_the_design_is_made_once_and_cannot_be_changed():
    lowpass_design.cache_clear()
    for _ in range(5):
        zero_phase_lowpass(np.arange(500.0), 1000.0, 50.0)
    info = lowpass_design.cache_info()
    assert (info.misses, info.hits) == (1, 4)
    sos, zi = lowpass_design(4, 50.0, 1000.0)
    with pytest.raises(ValueError, match="read-only"):
        sos[0, 0] = 1.0
    assert np.array_equal(zi, signal.sosfilt_zi(sos))
