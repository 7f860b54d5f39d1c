"""analysis' plain-h5py reader against files written by the bench's RunWriter."""

import os
import time

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.run_file import read_run_file
from hilbench.bench.runfile import RunWriter


def _write(path, n=5000, finish=True):
    w = RunWriter(path, sample_rate=1000.0, protocol_name="identification",
                  protocol_params={"amplitude": 2.0}, protocol_arrays={"setpoints": np.arange(n, dtype=float)},
                  calibration={"torque_constant": 0.2})
    k = np.arange(n)
    w.append({"sample_index": k, "t": k / 1000.0, "current_cmd": np.sin(k / 50.0), "current": np.cos(k / 50.0),
              "torque": 0.2 * np.cos(k / 50.0), "position": k * 1e-4, "counts": k})
    if finish:
        w.finish("completed")
    return w


def test_reads_what_the_writer_wrote(tmp_path):
    path = tmp_path / "r.h5"
    _write(path)
    r = read_run_file(path)
    assert (r.status, r.axis, r.sample_rate, r.protocol_name, r.torque_timing) == (
        "completed", "rotary", 1000.0, "identification", "hold_previous")
    np.testing.assert_array_equal(r.channel("position"), np.arange(5000) * 1e-4)
    assert r.units["torque"] == "N*m" and r.calibration["torque_constant"] == 0.2
    np.testing.assert_array_equal(r.protocol_arrays["setpoints"], np.arange(5000, dtype=float))
    a = r.arrays()
    assert a.fs == pytest.approx(1000.0) and a.torque.size == 5000
    with pytest.raises(AnalysisError, match="no 'velocity' channel"):
        r.channel("velocity")


def test_reads_a_file_still_being_written(tmp_path):
    path = tmp_path / "live.h5"
    w = _write(path, n=2000, finish=False)
    try:
        r = read_run_file(path)
        assert r.status == "running" and r.t.size == 2000  # 2 s = 4 whole flush chunks
    finally:
        w.finish("completed")


def test_truncated_and_foreign_files_fail_fast_with_one_line(tmp_path):
    path = tmp_path / "r.h5"
    _write(path)
    with open(path, "r+b") as f:
        f.truncate(os.path.getsize(path) // 2)
    t0 = time.monotonic()
    with pytest.raises(AnalysisError, match="truncated or damaged"):
        read_run_file(path)
    assert time.monotonic() - t0 < 5
    foreign = tmp_path / "x.h5"
    import h5py

    with h5py.File(foreign, "w") as f:
        f["a"] = 1
    with pytest.raises(AnalysisError, match="not a hilbench run file"):
        read_run_file(foreign)
    with pytest.raises(AnalysisError, match="no such run file"):
        read_run_file(tmp_path / "missing.h5")
