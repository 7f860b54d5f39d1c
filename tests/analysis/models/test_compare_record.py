"""compare's front door (analysis.models.compare.analyse) on a record read chunk by chunk and reduced to 5 kHz, as
``hilbench compare --memory`` does over its budget: the same rows as the whole record reduced at once (bit for bit
arrays; figures asserted to 1e-12, the tolerance docs/long-runs.md states)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hilbench.analysis.models.compare import DECIMATED_RATE, CompareSettings, analyse
from hilbench.analysis.record import block_average, decimated_record, load_record
from tests.analysis.residual.test_record_analysis import runs  # noqa: F401 (the fixture: two 3 s runs at 10 kHz)

FAMILIES = ("coulomb_viscous", "maxwell_slip", "dahl")
KEYS = ("torque_nrmse", "position_nrmse_segmented")


def _whole_reduced(path):
    rec = load_record(path)
    x, tau, fs = block_average(rec.position, rec.torque, rec.sample_rate, 2, rec.timing)
    return replace(rec, position=x, torque=tau, sample_rate=fs, t=np.arange(x.size) / fs, n_samples=x.size)


def _figures(result):
    return {r.name: {k: r.validation[k] for k in KEYS} | {f"train_{k}": r.train[k] for k in KEYS}
            for r in result.rows}


def test_streamed_with_tiny_chunks_equals_the_whole_record_reduced(runs):  # noqa: F811
    settings = CompareSettings(families=FAMILIES, max_nfev=10)
    seen = []
    streamed = analyse(decimated_record(runs / "a.h5", DECIMATED_RATE, chunk=777),
                       decimated_record(runs / "b.h5", DECIMATED_RATE, chunk=777), settings, progress=seen.append)
    whole = analyse(_whole_reduced(runs / "a.h5"), _whole_reduced(runs / "b.h5"), settings)
    assert seen == list(FAMILIES) and all(r.error is None for r in streamed.rows)
    assert streamed.train.fs == 5000.0 and streamed.train.x.size == 15_000
    a, b = _figures(streamed), _figures(whole)
    assert a.keys() == b.keys()
    for name in a:
        for k in a[name]:
            assert a[name][k] == pytest.approx(b[name][k], rel=1e-12), (name, k)


def test_reading_plan_whole_reduced_or_a_bounded_span(monkeypatch):
    """compare's plan for a budget (docs/long-runs.md): whole at the recorded rate when it fits; reduced to 5 kHz
    when that fits; else the first samples of each run at 5 kHz that fit, the closed form
    (budget - fixed) // (per_sample * runs); one line when not even 10 s fit."""
    from types import SimpleNamespace

    import hilbench.analysis.models.compare as compare
    from hilbench.analysis.errors import AnalysisError

    heads = [SimpleNamespace(n_samples=1_200_000, sample_rate=20_000.0)] * 2  # 60 s at 20 kHz each
    assert compare.reading_plan(heads, compare.cost(2_400_000)) is None
    assert compare.reading_plan(heads, compare.cost(600_000)) == ([4, 4], None)  # 5 kHz: 300 000 samples each
    budget = compare.cost(600_000) - 1
    qs, span = compare.reading_plan(heads, budget)
    assert qs == [4, 4] and span == (budget - compare.COMPARE_BYTES_FIXED) // (2 * compare.COMPARE_BYTES_PER_SAMPLE)
    assert span == 299_999 and compare.cost(2 * span) <= budget
    with pytest.raises(AnalysisError, match="first 10 s of each run reduced to 5000 Hz about .* over --memory"):
        compare.reading_plan(heads, compare.cost(2 * 49_999))


def test_a_bounded_span_against_the_whole_run(runs):  # noqa: F811
    """Approximate, stated in docs/long-runs.md ("A bounded span"): the families fitted on the first half of the 3 s
    training run (reduced to 5 kHz), scored on the whole validation run, rank as when fitted on the whole run, and
    the Maxwell-slip family's validation errors are within 0.1 percentage points (torque; measured 0.76 % and
    0.84 %) and 1 (segmented position; 0.93 % and 1.75 %: identify's terms since issue #37, no offset, which the
    half run's fit with an offset had at 0.95 % and 1.16 %)."""
    settings = CompareSettings(families=FAMILIES, max_nfev=10)
    val = decimated_record(runs / "b.h5", DECIMATED_RATE)
    whole = analyse(decimated_record(runs / "a.h5", DECIMATED_RATE), val, settings)
    half = analyse(decimated_record(runs / "a.h5", DECIMATED_RATE, max_samples=7500), val, settings)
    assert half.train.x.size == 7500 and whole.train.x.size == 15_000
    a, b = _figures(half), _figures(whole)
    assert sorted(a, key=lambda f: a[f]["torque_nrmse"]) == sorted(b, key=lambda f: b[f]["torque_nrmse"])
    assert abs(a["maxwell_slip"]["torque_nrmse"] - b["maxwell_slip"]["torque_nrmse"]) < 1e-3
    assert abs(a["maxwell_slip"]["position_nrmse_segmented"] - b["maxwell_slip"]["position_nrmse_segmented"]) < 1e-2
    assert b["maxwell_slip"]["torque_nrmse"] < 0.02  # a real fit
