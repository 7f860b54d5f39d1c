"""The residual loop's front door (analysis.residual.record_analysis): a record read chunk by chunk and reduced to
2 kHz gives the loop the same arrays, and so the same result, as the whole record loaded at once (docs/long-runs.md:
bit for bit; asserted to 1e-12)."""

from __future__ import annotations

import numpy as np
import pytest

from hilbench.analysis.record import load_record
from hilbench.analysis.residual.record_analysis import ResidualSettings, analyse, cost, read
from hilbench.common.runfile import RunWriter
from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import simulate
from tests.analysis.identification.test_identification import random_enveloped

FS = 10_000.0


def write_run(path, seed: int, seconds: float = 3.0) -> None:
    """A measured-torque run of the DC motor at 10 kHz (torque from the measured current: hold_previous)."""
    n = int(seconds * FS)
    p = dc_motor().replace(viscous=0.01, counts_per_rev=2**20, seed=seed)
    out = simulate(p, random_enveloped(n, FS, seed, 6.0), 1 / FS)
    with RunWriter(path, sample_rate=FS, channels=("sample_index", "t", "torque", "position")) as w:
        w.append({"sample_index": np.arange(n), "t": np.arange(n) / FS,
                  "torque": p.torque_constant * out.current_meas, "position": out.position_meas})


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("residual_front")
    write_run(d / "a.h5", 3)
    write_run(d / "b.h5", 4)
    return d


def test_streamed_with_tiny_chunks_equals_the_whole_record(runs):
    settings = ResidualSettings(candidates=("viscous", "offset"))
    whole = analyse(load_record(runs / "a.h5"), settings, validation=[load_record(runs / "b.h5")])
    streamed = analyse(read(runs / "a.h5", chunk=999), settings, validation=[read(runs / "b.h5", chunk=999)])
    assert streamed.record.sample_rate == 2000.0 and whole.train.fs == 2000.0  # both reduced to the loop's rate
    np.testing.assert_array_equal(streamed.train.position, whole.train.position)
    np.testing.assert_array_equal(streamed.train.torque, whole.train.torque)
    assert streamed.loop.names_added == whole.loop.names_added
    for key in ("error_before", "error_after"):
        for part in ("train", "validation"):
            for metric in ("torque_nrmse", "torque_rel_pct"):  # the loop's own figures, on its 2 kHz rows
                assert streamed.loop.__dict__[key][part]["loop"][metric] == pytest.approx(
                    whole.loop.__dict__[key][part]["loop"][metric], rel=1e-12)
    assert 0 < whole.loop.error_after["validation"]["torque_nrmse"] < 0.2  # a real fit, not an empty one


def test_cost_grows_with_the_analysed_samples_only():
    assert cost(2_000_000) - cost(1_000_000) == cost(1_000_000) - cost(0) > 0


def test_span_for_reads_whole_what_fits_bounds_what_does_not_and_refuses_what_cannot(monkeypatch):
    """The bounded span of a budget (docs/long-runs.md, "A bounded span"): the closed form
    (budget - fixed) // (per_sample * runs), None when the whole runs fit, one line when not 10 s fit."""
    from types import SimpleNamespace

    import hilbench.analysis.residual.record_analysis as ra
    from hilbench.analysis.errors import AnalysisError

    heads = [SimpleNamespace(n_samples=1_200_000, sample_rate=20_000.0)] * 2  # 60 s: 120 000 samples at 2 kHz each
    assert ra.span_for(heads, ra.cost(240_000)) is None
    budget = ra.cost(240_000) - 1
    assert ra.span_for(heads, budget) == (budget - ra.LOOP_BYTES_FIXED) // (2 * ra.LOOP_BYTES_PER_SAMPLE) == 119_999
    assert ra.cost(2 * ra.span_for(heads, budget)) <= budget
    with pytest.raises(AnalysisError, match="on the first 20000 samples of each run about .* over --memory"):
        ra.span_for(heads, ra.cost(2 * 19_999))


def test_a_bounded_span_is_the_loop_on_the_record_cut_there(runs):
    """Exact: the loop on a span read chunk by chunk equals the loop on the whole record cut at the span, reduced
    (figures to 1e-12); the span is the run's first 1.5 s."""
    from dataclasses import replace

    from hilbench.analysis.record import span_note

    settings = ResidualSettings(candidates=("viscous", "offset"))
    spanned = analyse(read(runs / "a.h5", chunk=999, max_samples=3000), settings)
    rec = load_record(runs / "a.h5")
    cut = replace(rec, position=rec.position[:15_000], torque=rec.torque[:15_000], t=rec.t[:15_000],
                  n_samples=15_000)
    whole = analyse(cut, settings)
    assert "1.5 s of 3 s" in span_note(spanned.record)
    np.testing.assert_array_equal(spanned.train.position, whole.train.position)
    assert spanned.loop.names_added == whole.loop.names_added
    for key in ("error_before", "error_after"):
        for metric in ("torque_nrmse", "torque_rel_pct"):
            assert spanned.loop.__dict__[key]["validation"][metric] == pytest.approx(
                whole.loop.__dict__[key]["validation"][metric], rel=1e-12)


def test_a_bounded_span_against_the_whole_run(runs):
    """Approximate, stated in docs/long-runs.md: the loop on the first half of the 3 s training run, validated on the
    whole validation run, adds the same effect as on the whole run, and its validation torque NRMSE is within 0.5
    percentage points (measured: 0.98 % against 1.13 %)."""
    settings = ResidualSettings(candidates=("viscous", "offset"))
    val = [read(runs / "b.h5")]
    whole = analyse(read(runs / "a.h5"), settings, validation=val)
    half = analyse(read(runs / "a.h5", max_samples=3000), settings, validation=val)
    assert half.train.position.size == 3000 and whole.train.position.size == 6000
    assert half.loop.names_added == whole.loop.names_added == ["viscous"]
    a, b = (r.loop.error_after["validation"]["torque_nrmse"] for r in (half, whole))
    assert abs(a - b) < 0.005 and 0 < b < 0.2
