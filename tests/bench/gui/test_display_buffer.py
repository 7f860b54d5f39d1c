"""Ring buffer and min/max decimation against brute-force oracles (exact: no arithmetic is involved, only
copies, minima and maxima, so the tolerance is zero)."""

import numpy as np
import pytest

from hilbench.bench.gui.display_buffer import RingBuffer, minmax_decimate


def test_ring_buffer_keeps_the_last_samples_in_order():
    rng = np.random.default_rng(1)
    buf = RingBuffer(("a", "b"), capacity=100)
    t_all, a_all = [], []
    start = 0
    for n in rng.integers(1, 60, size=40):  # block sizes that wrap around many times
        t = np.arange(start, start + n, dtype=float)
        start += n
        buf.append(t, {"a": 2 * t, "b": -t})
        t_all.append(t)
        a_all.append(2 * t)
        expect_t = np.concatenate(t_all)[-100:]
        got_t, got = buf.snapshot()
        np.testing.assert_array_equal(got_t, expect_t)
        np.testing.assert_array_equal(got[0], 2 * expect_t)
        np.testing.assert_array_equal(got[1], -expect_t)
    assert buf.total == start
    assert buf.latest_time() == start - 1


def test_ring_buffer_block_larger_than_capacity():
    buf = RingBuffer(("a",), capacity=10)
    buf.append(np.arange(3.0), {"a": np.arange(3.0)})
    buf.append(np.arange(3.0, 28.0), {"a": np.arange(3.0, 28.0)})
    t, d = buf.snapshot()
    np.testing.assert_array_equal(t, np.arange(18.0, 28.0))
    np.testing.assert_array_equal(d[0], t)
    buf.clear()
    assert len(buf) == 0 and buf.snapshot()[0].size == 0


def _oracle(t, y, columns):
    size = -(-t.size // columns)
    ts, ys = [], []
    for s in range(0, t.size, size):
        seg = y[s:s + size]
        i_lo, i_hi = int(np.nanargmin(seg)), int(np.nanargmax(seg))
        first, second = (seg[i_lo], seg[i_hi]) if i_lo <= i_hi else (seg[i_hi], seg[i_lo])
        ts += [t[s], t[s]]
        ys += [first, second]
    return np.array(ts), np.array(ys)


@pytest.mark.parametrize("n, columns", [(10_000, 640), (100_001, 1000), (12_345, 7), (2_000, 999)])
def test_minmax_decimation_matches_per_bin_oracle(n, columns):
    rng = np.random.default_rng(n)
    t = np.arange(n) / 10_000.0
    y = np.sin(2 * np.pi * 3 * t) + 0.1 * rng.standard_normal(n)
    y[n // 3] = 50.0  # a one-sample spike must survive
    td, yd = minmax_decimate(t, y, columns)
    to, yo = _oracle(t, y, columns)
    assert td.size <= 2 * columns
    np.testing.assert_array_equal(td, to)
    np.testing.assert_array_equal(yd, yo)
    assert yd.max() == 50.0 and yd.min() == y.min()


def test_minmax_decimation_of_several_traces_and_nan():
    t = np.arange(1000.0)
    y = np.vstack([np.arange(1000.0), -np.arange(1000.0)])
    y[0, 100:200] = np.nan  # a whole bin of NaN stays NaN; a partly NaN bin ignores the NaN
    y[0, 205] = np.nan
    td, yd = minmax_decimate(t, y, 10)
    assert yd.shape == (2, 20)
    assert np.isnan(yd[0, 2:4]).all()
    assert yd[0, 4] == 200.0 and yd[0, 5] == 299.0
    np.testing.assert_array_equal(yd[1], -np.repeat(np.arange(0, 1000, 100), 2) - np.tile([0, 99], 10))


def test_short_traces_are_not_decimated():
    t = np.arange(50.0)
    td, yd = minmax_decimate(t, t**2, 100)
    assert td is not None and td.size == 50 and np.array_equal(yd, t**2)
    with pytest.raises(ValueError):
        minmax_decimate(t, t, 0)
