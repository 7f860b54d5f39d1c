"""Selection rules of the residual loop (issue 14): evidence combination, two-sided comparison, record kinds."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from hilbench.analysis.residual.selection import _dm_two_sided, _evidence
from hilbench.common.runfile import RunFileError, record_kind


def test_evidence_without_a_diagnostic_is_the_held_out_test():
    assert _evidence(3e-4, 0.0) == 3e-4


def test_evidence_combines_independent_p_values_by_fisher():
    p_dm, p_diag = 8.7e-4, 2.5e-6
    fisher = stats.chi2.sf(-2 * (np.log(p_dm) + np.log(p_diag)), 4)
    assert _evidence(p_dm, -np.log10(p_diag)) == pytest.approx(2 * fisher, rel=1e-9)
    # a weak diagnostic never makes a strong held-out result weaker than 2x its p-value
    assert _evidence(1e-9, 0.5) == pytest.approx(2e-9, rel=1e-6)


def test_two_sided_comparison_is_symmetric_and_detects_a_difference():
    rng = np.random.default_rng(0)
    a = rng.standard_normal(4000)
    b = a + 0.01 * rng.standard_normal(4000)
    assert _dm_two_sided(a, b) == pytest.approx(_dm_two_sided(b, a))
    assert _dm_two_sided(a, 0.5 * a) < 1e-6


def test_record_kind():
    assert record_kind(None) == "torque-driven"
    assert record_kind(b"displacement-driven") == "displacement-driven"
    with pytest.raises(RunFileError, match="unknown record kind"):
        record_kind("force-driven", "x.h5")
