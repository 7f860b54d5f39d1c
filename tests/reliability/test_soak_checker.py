"""The soak's file check finds lost and invented samples (so its zeros mean something)."""

import numpy as np

from benchmarks.bench_soak import check_file
from hilbench.common.runfile import DEVICE_CHANNELS, RunWriter


def _write(path, index, cmd, setpoints):
    with RunWriter(path, sample_rate=1000.0, channels=DEVICE_CHANNELS,
                   protocol_arrays={"setpoints": setpoints}) as w:
        n = len(index)
        w.append({"sample_index": index, "t": index / 1000, "current_cmd": cmd, "current": cmd,
                  "torque": 0.2 * cmd, "position": np.zeros(n), "counts": np.zeros(n, dtype=np.int64)})


def test_check_file_counts_gaps_repeats_and_made_up_values(tmp_path):
    sp = np.linspace(-1, 1, 100)
    good = tmp_path / "good.h5"
    _write(good, np.arange(100), sp.astype(np.float32).astype(np.float64), sp)
    assert check_file(good, killed=False) == {"lost": 0, "invented": 0, "unreadable": 0, "samples": 100,
                                              "absent": 0}
    index = np.concatenate([np.arange(40), np.arange(45, 100)])  # 5 lost
    cmd = sp[index].astype(np.float32).astype(np.float64)
    cmd[-3:] = 0.0  # 3 made-up zeros
    bad = tmp_path / "bad.h5"
    _write(bad, index, cmd, sp)
    got = check_file(bad, killed=False)
    assert got["lost"] == 5 and got["invented"] == 3
    assert check_file(tmp_path / "none.h5", killed=True)["absent"] == 1
    assert check_file(tmp_path / "none.h5", killed=False)["unreadable"] == 1
