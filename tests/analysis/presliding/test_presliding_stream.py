"""The record-level presliding analysis: read whole or chunk by chunk (the same result to rounding, except the
edge-pinned fit, which a streamed read does not make), its output files, and the warning for too few reversals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hilbench.analysis import presliding
from hilbench.analysis.presliding.streamed import NOT_STREAMED
from hilbench.analysis.record import load_record
from hilbench.common.runfile import RunWriter
from hilbench.firmware_sim.engine.friction_models import DC_MOTOR_D
from tests.analysis.presliding.records import dc_elements, maxwell_force, smooth_path

FS = 1000.0
K, W = dc_elements()


def _write(path, x, force):
    n = x.size
    with RunWriter(path, sample_rate=FS, channels=("sample_index", "t", "position", "torque"),
                   record="displacement-driven", protocol_name="presliding", protocol_params={"inertia": 0.0}) as w:
        w.append({"sample_index": np.arange(n), "t": np.arange(n) / FS, "position": x, "torque": force})


def _noisy(x):
    return maxwell_force(x, K, W) + 2e-3 * np.random.default_rng(3).standard_normal(x.size)


def test_streamed_equals_whole(tmp_path):
    """A nested path of 24 k samples (averaged in blocks of 3) with force noise: read in chunks of 1000 samples,
    every figure (quantities, bootstrap uncertainties, model, reversal table, checks) equals the whole read's to
    1e-9 relative (block means summed in the same order; the moving average of the extreme forces filtered per
    padded chunk); the progress callback ends at both passes' samples."""
    x = smooth_path(DC_MOTOR_D, 400)
    path = tmp_path / "p.h5"
    _write(path, x, _noisy(x))
    rec = load_record(path)
    whole = presliding.analyse(rec, replicates=4)
    seen = []
    streamed, head = presliding.analyse_stream(path, replicates=4, chunk=1000, progress=lambda d, t: seen.append(t))
    assert whole.block == streamed.block == 3 and seen[-1] == 2 * x.size
    np.testing.assert_array_equal(streamed.reversals, whole.reversals)
    for key, value in whole.quantities.items():
        assert streamed.quantities[key] == pytest.approx(value, rel=1e-9)
        assert streamed.uncertainties[key] == pytest.approx(whole.uncertainties[key], rel=1e-9)
    np.testing.assert_allclose(streamed.fit.model.ms_stiffness, whole.fit.model.ms_stiffness, rtol=1e-9)
    np.testing.assert_allclose(streamed.extremes, whole.extremes, rtol=1e-12)
    assert streamed.resolution.step == pytest.approx(whole.resolution.step, rel=1e-12)
    assert streamed.edge_error == whole.edge_error == "the displacement is not quantised in whole steps"
    doc_w = presliding.document(whole, rec)
    doc_s = presliding.document(streamed, head, "chunk by chunk")
    assert doc_s["checks"] == pytest.approx(doc_w["checks"], rel=1e-9)
    written = presliding.report(streamed, tmp_path / "out", doc_s)
    assert sorted(p.name for p in written) == sorted(presliding.OUTPUT_FILES)
    assert json.loads(written[0].read_text())["read"] == "chunk by chunk"
    assert streamed.warnings == whole.warnings == []


def test_streamed_quantised_record_says_the_edge_fit_was_not_made(tmp_path):
    """An encoder record (2^16 counts/rev): the whole read makes the edge-pinned fit, the streamed read reports
    it as not made and why (docs/long-runs.md)."""
    q = 2 * np.pi / 2**16
    x = np.round(smooth_path(DC_MOTOR_D, 400) / q) * q
    path = tmp_path / "q.h5"
    _write(path, x, _noisy(x))
    whole = presliding.analyse(load_record(path), replicates=2)
    streamed, _ = presliding.analyse_stream(path, replicates=2, chunk=1000)
    assert whole.edges is not None and whole.edge_error == ""
    assert streamed.edges is None and streamed.edge_error == NOT_STREAMED
    assert streamed.resolution.step == pytest.approx(q, rel=1e-9)


def test_warns_with_fewer_than_four_reversals(tmp_path):
    """A virgin ramp and one reversal: the analysis completes and warns, naming --amplitudes."""
    x = smooth_path(DC_MOTOR_D, 200, sequence=(6.0, -4.0))
    path = tmp_path / "short.h5"
    _write(path, x, _noisy(x))
    res = presliding.analyse(load_record(path), replicates=2)
    assert res.reversals.size < presliding.MIN_REVERSALS
    assert len(res.warnings) == 1 and "reversal" in res.warnings[0] and "--amplitudes" in res.warnings[0]
