"""analysis.record_split: the head and tail a campaign step fits and validates on are the run's samples, cut once."""

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.record import load_record
from hilbench.analysis.record_split import split, window
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    folder = tmp_path_factory.mktemp("split")
    write_campaign(folder, SyntheticCampaign(runs=1, duration=0.5, seed=2))
    return load_record(folder / "id1-1.h5", channels=("temperature",))


def test_head_and_tail_are_the_run_cut_at_the_rounded_sample(record):
    n = record.t.size  # 500 samples at 1 kHz
    head, tail = split(record, 0.3)
    assert head.t.size == round(0.7 * n) == 350 and tail.t.size == n - 350
    for name in ("position", "torque"):
        assert np.array_equal(np.concatenate([getattr(head, name), getattr(tail, name)]), getattr(record, name))
    assert np.array_equal(np.concatenate([head.channels["temperature"], tail.channels["temperature"]]),
                          record.channels["temperature"])
    # each part's time restarts at 0 s on the same grid, as a run file of those samples would read
    assert tail.t[0] == 0.0 and np.allclose(np.diff(tail.t), 1 / record.sample_rate, rtol=1e-12)
    assert head.n_samples == 350 and tail.notes[-1] == f"validation tail: samples 350:{n} of {n}"
    assert (head.timing, head.kind, head.axis) == (record.timing, record.kind, record.axis)
    whole, none = split(record, 0.0)
    assert whole is record and none is None


def test_bad_cuts_are_refused_in_one_line(record):
    with pytest.raises(AnalysisError, match=r"validation fraction 1 is not in \[0, 1\)"):
        split(record, 1.0)
    with pytest.raises(AnalysisError, match="cannot be cut into a head and a tail"):
        split(record, 0.999)
    with pytest.raises(AnalysisError, match="samples 10:5 are not a window"):
        window(record, 10, 5, "x")
