"""Acceptance: three stationary simulated campaigns of 200 runs (different seeds) raise no alarm."""

import pytest

from hilbench.analysis.drift.monitor import monitor
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign
from tests.analysis.drift.campaign_rows import campaign_rows


@pytest.mark.slow
@pytest.mark.parametrize("seed", [2, 3, 4])
def test_stationary_campaign_raises_no_alarm(seed):
    summary = monitor(campaign_rows(SyntheticCampaign(runs=200, seed=seed * 1000))).summary()
    assert summary["alarms"] == []
    assert all(not p["change_points"] for p in summary["parameters"].values())
