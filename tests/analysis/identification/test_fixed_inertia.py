"""``LipSettings.fixed_inertia``: a known J is subtracted, not estimated (0 allowed)."""

from __future__ import annotations

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.maxwell_fit import LipSettings, fit_lip


def _run(j: float, b: float, fs: float = 1000.0, n: int = 20000):
    t = np.arange(n) / fs
    x = 0.5 * np.sin(2 * np.pi * 0.7 * t) + 0.2 * np.sin(2 * np.pi * 3.1 * t)
    v = 0.5 * 2 * np.pi * 0.7 * np.cos(2 * np.pi * 0.7 * t) + 0.2 * 2 * np.pi * 3.1 * np.cos(2 * np.pi * 3.1 * t)
    a = -0.5 * (2 * np.pi * 0.7) ** 2 * np.sin(2 * np.pi * 0.7 * t) - 0.2 * (2 * np.pi * 3.1) ** 2 * np.sin(
        2 * np.pi * 3.1 * t)
    return x, j * a + b * v, fs


def test_known_inertia_is_kept_and_viscous_recovered():
    x, tau, fs = _run(0.01, 0.3)
    fit = fit_lip(x, tau, fs, settings=LipSettings(n_thresholds=0, fixed_inertia=0.01, timing="instant"))
    assert fit.model.inertia == 0.01
    assert fit.model.viscous == pytest.approx(0.3, rel=1e-3)


def test_zero_inertia_force_against_displacement():
    x, f, fs = _run(0.0, 2.0)
    fit = fit_lip(x, f, fs, settings=LipSettings(n_thresholds=0, fixed_inertia=0.0, timing="instant"))
    assert fit.model.inertia == 0.0 and fit.model.viscous == pytest.approx(2.0, rel=1e-3)
    assert fit.torque_nrmse < 1e-3


def test_negative_inertia_is_refused():
    x, f, fs = _run(0.0, 2.0)
    with pytest.raises(AnalysisError, match="fixed inertia"):
        fit_lip(x, f, fs, settings=LipSettings(n_thresholds=0, fixed_inertia=-1.0))
