"""A long presliding record is many repeats of the same nested path: averaged whole into MAX_SAMPLES blocks, its
reversals average away. The analysis cuts it to its first whole repeats at the path's own resolution
(analysis/presliding/span.py) and says so; a record whose blocks are short enough is analysed whole, as before."""

from __future__ import annotations

import numpy as np
import pytest

from hilbench.analysis import presliding
from hilbench.analysis.presliding.span import KEEP_BLOCKS_PER_BRANCH, plan_span, x_means
from hilbench.analysis.record import load_record
from hilbench.common.runfile import RunWriter
from hilbench.firmware_sim.engine.friction_models import DC_MOTOR_D
from tests.analysis.presliding.records import dc_elements, repeated_force, repeated_path

FS = 1000.0
STROKE = 200  # samples a stroke: 0.2 s at FS
PERIOD = 12 * STROKE  # samples a repeat of the path (12 strokes)
K, W = dc_elements()


def _write(path, repeats: int) -> None:
    x = repeated_path(DC_MOTOR_D, STROKE, repeats)
    force = repeated_force(x, PERIOD, K, W) + 2e-3 * np.random.default_rng(3).standard_normal(x.size)
    with RunWriter(path, sample_rate=FS, channels=("sample_index", "t", "position", "torque"),
                   record="displacement-driven", protocol_name="presliding", protocol_params={"inertia": 0.0}) as w:
        w.append({"sample_index": np.arange(x.size), "t": np.arange(x.size) / FS, "position": x, "torque": force})


def test_a_long_record_gives_the_short_records_figures_from_its_first_repeats(tmp_path):
    """10 repeats (24 000 samples, blocks of 3: 66 a stroke) against 500 repeats (1.2 M samples: the old blocks of
    120 put fewer than two in a stroke, and the old analysis was far off or refused). The long record is cut to its
    first 24 repeats in blocks of 6 (33 a stroke), with one warning naming the span; the break-away agrees with the
    short record's within 0.5 % and the presliding distance within 2 % (docs/long-runs.md); read chunk by chunk,
    the long record gives the whole read's figures to 1e-9 and the same warning."""
    _write(tmp_path / "short.h5", 10)
    _write(tmp_path / "long.h5", 500)
    short = presliding.analyse(load_record(tmp_path / "short.h5"), replicates=4)
    long = presliding.analyse(load_record(tmp_path / "long.h5"), replicates=4)
    assert short.warnings == [] and short.block == 3
    assert long.block == 6 and len(long.warnings) == 1
    assert long.warnings[0].startswith("analysed the first 57.6 s of 1200 s (24 whole repeats of the path)")
    assert long.quantities["breakaway"] == pytest.approx(short.quantities["breakaway"], rel=0.005)
    assert long.quantities["presliding_distance"] == pytest.approx(short.quantities["presliding_distance"], rel=0.02)
    streamed, _ = presliding.analyse_stream(tmp_path / "long.h5", replicates=4, chunk=1 << 16)
    assert streamed.warnings == long.warnings and streamed.block == long.block
    np.testing.assert_array_equal(streamed.reversals, long.reversals)
    for key, value in long.quantities.items():
        assert streamed.quantities[key] == pytest.approx(value, rel=1e-9)


def test_a_record_whose_blocks_resolve_its_path_is_analysed_whole():
    """Blocks of ceil(n/max_samples) that leave KEEP_BLOCKS_PER_BRANCH or more in the shortest branch: no span (the
    old analysis, unchanged); one block fewer a stroke and the record is cut, at a whole repeat of the path."""
    x = repeated_path(DC_MOTOR_D, STROKE, 40)  # 96 000 samples
    for max_samples, cut in ((x.size // (STROKE // KEEP_BLOCKS_PER_BRANCH), False),
                             (x.size // (STROKE // KEEP_BLOCKS_PER_BRANCH + 1), True)):
        span = plan_span(x.size, max_samples, 1e-9, lambda m, head: x_means(x, m, head), lambda a, b: x[a:b])
        assert (span is not None) == cut
        if cut:
            assert span.samples % PERIOD == 0 and span.repeats == span.samples // PERIOD
