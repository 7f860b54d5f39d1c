"""Random metadata and arrays fed to the run-file writer and reader: the only exception is ours
(RunFileError), and whatever was accepted reads back exactly."""

import math
import os
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import array_shapes, arrays

from hilbench.common.runfile import CHANNELS, RunFileError, RunWriter, open_run

text = st.text(st.characters(codec=None), max_size=40)  # any code point, lone surrogates included
scalars = st.one_of(st.none(), st.booleans(), st.integers(min_value=-(2**70), max_value=2**70),
                    st.floats(allow_nan=True, allow_infinity=True), text)
metadata = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                         st.dictionaries(text, inner, max_size=4)), max_leaves=12)
dtypes = st.sampled_from([np.float64, np.float32, np.int64, np.int8, np.uint64, np.bool_, np.complex128,
                          np.dtype("U3"), object])
any_array = st.one_of(
    dtypes.flatmap(lambda dt: arrays(dt, array_shapes(min_dims=0, max_dims=3, max_side=5))
                   if dt is not object else st.just(np.array([None, "x"], dtype=object))),
    st.lists(st.floats(allow_nan=True), max_size=5), text, st.none(), st.integers())
channel_names = st.lists(st.one_of(st.sampled_from(sorted(CHANNELS)), text), max_size=5)


@st.composite
def blocks(draw, names):
    n = draw(st.integers(0, 20))
    out = {}
    for name in names:
        if draw(st.integers(0, 9)) == 0:
            out[name] = draw(any_array)  # garbage in one channel
        else:
            out[name] = draw(arrays(np.float64, n, elements=st.floats(allow_nan=True, allow_infinity=True,
                                                                      width=64)))
    if draw(st.booleans()) and names:
        out[draw(text)] = np.zeros(n)  # an unexpected channel
    return out


EXAMPLES = int(os.environ.get("HILBENCH_FUZZ_EXAMPLES", "150"))  # 1500 ran clean (48 s)


@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(),
       rate=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-5, 10**6), text, st.booleans()),
       axis=st.one_of(st.sampled_from(["rotary", "linear"]), text),
       extra=channel_names,
       custom=st.dictionaries(text, st.one_of(text, st.integers()), max_size=3),
       device=metadata, config=metadata, params=metadata,
       protocol_arrays=st.dictionaries(st.one_of(st.sampled_from(["setpoints", "step_windows"]), text),
                                       any_array, max_size=2),
       operator=text, notes=text, proto_name=text,
       events=st.lists(st.tuples(st.one_of(st.sampled_from(["info", "fault"]), text), text), max_size=3))
def test_writer_and_reader_raise_nothing_but_ours(data, rate, axis, extra, custom, device, config, params,
                                                  protocol_arrays, operator, notes, proto_name, events):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.h5"
        names = ("sample_index", "t", *extra)
        written = []
        try:
            writer = RunWriter(path, sample_rate=rate, axis=axis, channels=names, custom_channels=custom,
                               device=device, config=config, protocol_name=proto_name, protocol_params=params,
                               protocol_arrays=protocol_arrays, operator=operator, notes=notes)
        except RunFileError:
            if path.exists():  # refused after it appeared: it says so
                with open_run(path) as run:
                    assert run.status == "failed"
            return
        with writer:
            for _ in range(data.draw(st.integers(0, 3))):
                block = data.draw(blocks(writer.channels))
                try:
                    writer.append(block)
                    written.append(block)
                except RunFileError:
                    pass
            for kind, message in events:
                try:
                    writer.add_event(kind, message)
                except RunFileError:
                    pass
        with open_run(path) as run:
            assert run.status == "completed" and run.uid == writer.uid
            assert run.channels == writer.channels
            for name in run.channels:
                got = run.channel(name)
                want = np.concatenate([np.asarray(b[name], dtype=got.dtype).reshape(-1) for b in written]) \
                    if written else np.zeros(0, dtype=got.dtype)
                np.testing.assert_array_equal(got, want)
            assert run.meta["notes"] == notes and run.meta["operator"] == operator
            assert math.isclose(run.sample_rate, float(rate))
            for name in run.protocol_array_names:
                run.protocol_array(name)
            run.events  # noqa: B018 (reads and decodes the table)
