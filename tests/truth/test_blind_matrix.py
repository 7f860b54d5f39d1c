"""A representative subset of the strict blind matrix (one seed; the whole matrix, 3 seeds, is
``benchmarks/bench_residual.py`` and docs/residual-blind-matrix.md): clean data of a family the library
does not contain (Dahl), a Stribeck curve with exponent 1, an angle-modulated friction level, a first-order
current-loop lag, Stribeck + 9th-order cogging on LuGre, and a clean record of the default simulated bench (issue 29).
Right means: the added set EQUALS the truth's, and a clean record ends with nothing unexplained."""

from __future__ import annotations

import pytest

from tests.truth.matrix import CASES, QUICK, run_case


@pytest.mark.parametrize("case", QUICK)
def test_added_set_equals_the_truth(case):
    out = run_case(case, 1)
    assert out.right, (f"{case}: added {out.added}, truth {sorted(CASES[case][1])}, "
                       f"unexplained {out.unexplained}")
    # the loop's own time: 10 s records at 1 kHz (issue 14: < 10 s for 30 s); the bench record is 20 s at 10 kHz
    # (reduced to 2 kHz), 14.5 s measured under a load average of 11 on 2 cores
    assert out.seconds < (30.0 if case.startswith("bench-") else 10.0)


#: runs that were wrong before issue 29's fixes (docs/residual-blind-matrix.md): a GMS level slope that added
#: asymmetric_friction beside preload_variation (the truth's stick overshoot and the slip-force form), a Stribeck
#: curve missed on a record that hardly slides (the Stribeck grid's top), and clean Dahl data over a 4 rad stroke
#: left unexplained (the presliding check; seed 1 is tests/analysis/residual/test_presliding_check.py)
FIXED = (("preload-linear-gms", 1), ("stribeck+lag", 2), ("clean-stroke4-dahl", 2), ("clean-stroke4-dahl", 3))


@pytest.mark.slow
@pytest.mark.parametrize("case,seed", FIXED)
def test_runs_fixed_by_issue_29_stay_right(case, seed):
    out = run_case(case, seed)
    assert out.right, (f"{case} seed {seed}: added {out.added}, truth {sorted(CASES[case][1])}, "
                       f"unexplained {out.unexplained}")
