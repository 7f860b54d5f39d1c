"""The one record loader (hilbench.analysis.record.load_record) against files written by the bench's RunWriter."""

import os
import time

import h5py
import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.record import IncompleteRecordError, load_record
from hilbench.common.runfile import RunWriter


def _write(path, n=5000, finish="completed", planned=None, events=()):
    planned = n if planned is None else planned
    w = RunWriter(path, sample_rate=1000.0, protocol_name="identification",
                  protocol_params={"amplitude": 2.0}, protocol_arrays={"setpoints": np.arange(planned, dtype=float)},
                  calibration={"torque_constant": 0.2})
    k = np.arange(n)
    w.append({"sample_index": k, "t": k / 1000.0, "current_cmd": np.sin(k / 50.0), "current": np.cos(k / 50.0),
              "torque": 0.2 * np.cos(k / 50.0), "position": k * 1e-4, "counts": k})
    for kind, message in events:
        w.add_event(kind, message)
    if finish:
        w.finish(finish)
    return w


def test_reads_what_the_writer_wrote(tmp_path):
    path = tmp_path / "r.h5"
    _write(path)
    r = load_record(path, channels=("current",), protocol_arrays=("setpoints",))
    assert (r.status, r.axis, r.sample_rate, r.protocol_name, r.timing, r.torque_channel, r.incomplete) == (
        "completed", "rotary", 1000.0, "identification", "hold_previous", "torque", None)
    np.testing.assert_array_equal(r.position, np.arange(5000) * 1e-4)
    np.testing.assert_array_equal(r.channel("current"), np.cos(np.arange(5000) / 50.0))
    assert r.units["torque"] == "N*m" and r.calibration["torque_constant"] == 0.2
    np.testing.assert_array_equal(r.protocol_arrays["setpoints"], np.arange(5000, dtype=float))
    a = r.arrays()
    assert a.fs == pytest.approx(1000.0) and a.torque.size == 5000
    with pytest.raises(AnalysisError, match="'velocity' was not loaded"):
        r.channel("velocity")
    assert load_record(path, torque_channel="torque_cmd" if False else "current_cmd").timing == "hold_next"
    with pytest.raises(AnalysisError, match="no channel 'velocity'"):
        load_record(path, torque_channel="velocity")


@pytest.mark.parametrize(("finish", "planned", "events", "reason"), [
    ("aborted", None, [("abort", "aborted by operator")], "the run is aborted (aborted by operator)"),
    ("completed", 6000, [], "it holds 5000 of the 6000 planned samples"),
    ("completed", None, [("info", "host-clocked timing: jitter 40 % of T; UNFIT for identification")],
     "its device marked it unfit"),
])
def test_an_incomplete_record_is_refused_in_one_line_unless_allowed(tmp_path, finish, planned, events, reason):
    path = tmp_path / "r.h5"
    _write(path, finish=finish, planned=planned, events=events)
    with pytest.raises(IncompleteRecordError) as err:
        load_record(path)
    text = str(err.value)
    assert "\n" not in text and reason in text and "--allow-incomplete" in text
    r = load_record(path, allow_incomplete=True)
    assert r.incomplete.startswith(reason) and "INCOMPLETE RECORD" in r.incomplete_line()


def test_a_file_still_being_written_is_incomplete(tmp_path):
    path = tmp_path / "live.h5"
    w = _write(path, n=2000, finish=None)
    try:
        with pytest.raises(IncompleteRecordError, match="the run is running"):
            load_record(path)
        r = load_record(path, allow_incomplete=True)
        assert r.status == "running" and r.t.size == 2000  # 2 s = 4 whole flush chunks
    finally:
        w.finish("completed")


def test_non_finite_samples_are_refused_naming_the_channel(tmp_path):
    path = tmp_path / "r.h5"
    _write(path)
    with h5py.File(path, "r+") as f:
        f["samples/torque"][7] = np.nan
    with pytest.raises(AnalysisError, match="channel 'torque' has 1 non-finite value.*sample 7"):
        load_record(path)


def test_truncated_and_foreign_files_fail_fast_with_one_line(tmp_path):
    path = tmp_path / "r.h5"
    _write(path)
    with open(path, "r+b") as f:
        f.truncate(os.path.getsize(path) // 2)
    t0 = time.monotonic()
    with pytest.raises(AnalysisError, match="truncated"):
        load_record(path)
    assert time.monotonic() - t0 < 5
    foreign = tmp_path / "x.h5"
    with h5py.File(foreign, "w") as f:
        f["a"] = 1
    with pytest.raises(AnalysisError, match="not a hilbench run file"):
        load_record(foreign)
    with pytest.raises(AnalysisError, match="missing.h5"):
        load_record(tmp_path / "missing.h5")


# every timing with chunks shorter than, around and longer than a block; chunks of one sample (5003 reads, 7-11 s
# each) with one timing only: the chunking is the same code for all three
@pytest.mark.parametrize("timing, chunk", [(t, c) for t in ("hold_previous", "hold_next", "instant")
                                           for c in (7, 1000, 1 << 17)] + [("hold_previous", 1)])
def test_decimated_record_read_chunk_by_chunk_equals_block_average_of_the_whole_arrays(tmp_path, timing, chunk):
    from hilbench.analysis.record import block_average, decimated_record

    path = tmp_path / "r.h5"
    _write(path, n=5003)  # 5003 = 1000 blocks of 5 and 3 samples dropped
    whole = load_record(path, timing=timing)
    x, tau, fs = block_average(whole.position, whole.torque, whole.sample_rate, 5, timing)
    seen = []
    dec = decimated_record(path, 200.0, timing=timing, chunk=chunk, progress=seen.append)
    assert (dec.sample_rate, dec.n_samples, dec.timing) == (200.0, 1000, timing)
    np.testing.assert_array_equal(dec.position, x)  # bit for bit: the same samples summed in the same order
    np.testing.assert_array_equal(dec.torque, tau)
    np.testing.assert_allclose(dec.t, np.arange(1000) / 200.0, rtol=0, atol=1e-15)
    assert seen[-1] == 5003 and "decimated by 5" in dec.notes[-1]


def test_block_average_of_a_held_torque_keeps_its_impulse():
    # Closed form: a torque held over each sample has impulse sum(tau) * T; the block means held over q*T keep it.
    from hilbench.analysis.record import block_average, decimation_factor

    rng = np.random.default_rng(1)
    tau = rng.normal(size=3000)
    x, means, fs = block_average(np.arange(3000.0), tau, 10_000.0, decimation_factor(10_000.0, 2_000.0), "hold_next")
    assert fs == 2000.0 and means.size == 600
    assert means.sum() / fs == pytest.approx(tau.sum() / 10_000.0, rel=1e-12)
    np.testing.assert_array_equal(x, np.arange(0.0, 3000.0, 5.0))  # position at the block's first edge
    assert decimation_factor(10_000.0, 10_000.0) == 1 and decimation_factor(20_000.0, 3_000.0) == 7


def test_decimated_record_holds_the_kept_samples_not_the_chunks(tmp_path):
    """Peak memory while reading is the decimated copy plus a few chunks: 400 000 samples reduced 50-fold in chunks
    of 4096 allocate under 1.5 MB (the position alone is 3.2 MB; kept as strided views of each chunk it stayed whole,
    13 B per input sample on a 12 M-sample run)."""
    import tracemalloc

    from hilbench.analysis.record import decimated_record

    path = tmp_path / "long.h5"
    _write(path, n=400_000)
    tracemalloc.start()
    try:
        dec = decimated_record(path, 20.0, chunk=4096)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert dec.n_samples == 8000
    assert peak < 1.5e6, peak


@pytest.mark.parametrize("chunk", [7, 1000, 1 << 17])
def test_a_bounded_span_is_the_reduction_of_the_record_cut_there_and_reads_no_further(tmp_path, chunk):
    """``max_samples`` keeps the first reduced samples only: bit for bit ``block_average`` of the record cut at
    ``max_samples * q`` input samples, the reading stops within one chunk of there, and a note says what was cut."""
    from hilbench.analysis.record import SPAN_NOTE, block_average, decimated_record, span_note

    path = tmp_path / "r.h5"
    _write(path, n=50_003)
    whole = load_record(path, timing="hold_previous")
    x, tau, _ = block_average(whole.position[:1500], whole.torque[:1500], whole.sample_rate, 5, "hold_previous")
    seen = []
    dec = decimated_record(path, 200.0, timing="hold_previous", chunk=chunk, progress=seen.append, max_samples=300)
    assert (dec.sample_rate, dec.n_samples) == (200.0, 300)
    np.testing.assert_array_equal(dec.position, x)
    np.testing.assert_array_equal(dec.torque, tau)
    assert seen[-1] == min(50_003, chunk * -(-1500 // chunk))  # stopped at the chunk that filled the span
    note = span_note(dec)
    assert note is not None and note.startswith(SPAN_NOTE) and "1.5 s of 50.003 s" in note
    # longer than the record: no cut (read in large chunks: in chunks of 7 the whole record took 14 s)
    free = decimated_record(path, 200.0, chunk=max(chunk, 1000), max_samples=10_000)
    assert free.n_samples == 10_000 and span_note(free) is None
    with pytest.raises(AnalysisError, match="max_samples must be >= 1"):
        decimated_record(path, 200.0, max_samples=0)


def test_a_streamed_record_names_the_chunk_of_a_non_finite_sample(tmp_path):
    """stream_record reads through the one chunk reader (analysis.channel_windows): a NaN at sample 4321 read in
    chunks of 1000 is refused in one line naming the chunk's first sample and the index within it."""
    from hilbench.analysis.record import stream_record

    path = tmp_path / "nan.h5"
    n = 10_000
    k = np.arange(n)
    x = k * 1e-4
    x[4321] = np.nan
    with RunWriter(path, sample_rate=1000.0, channels=("sample_index", "t", "torque", "position")) as w:
        w.append({"sample_index": k, "t": k / 1000.0, "torque": np.cos(k / 50.0), "position": x})
    rec, source = stream_record(path, chunk=1000)
    assert rec.n_samples == n and rec.position is None
    with pytest.raises(AnalysisError, match=r"samples from 4000\): channel 'position' has 1 non-finite value\(s\), "
                                            r"first at sample 321"):
        for _ in source():
            pass
