"""The residual loop's front door (analysis.residual.record_analysis): a record read chunk by chunk and reduced to
2 kHz gives the loop the same arrays, and so the same result, as the whole record loaded at once (docs/long-runs.md:
bit for bit; asserted to 1e-12)."""

from __future__ import annotations

import numpy as np
import pytest

from hilbench.analysis.record import load_record
from hilbench.analysis.residual.record_analysis import ResidualSettings, analyse, cost, read
from hilbench.analysis.runfile import RunWriter
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
            for metric in ("torque_nrmse", "torque_rel_pct"):
                assert streamed.loop.__dict__[key][part][metric] == pytest.approx(
                    whole.loop.__dict__[key][part][metric], rel=1e-12)
    assert 0 < whole.loop.error_after["validation"]["torque_nrmse"] < 0.2  # a real fit, not an empty one


def test_cost_grows_with_the_analysed_samples_only():
    assert cost(2_000_000) - cost(1_000_000) == cost(1_000_000) - cost(0) > 0
