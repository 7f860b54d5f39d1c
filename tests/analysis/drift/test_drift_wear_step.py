"""Acceptance: a simulated 200-run campaign with a wear step at run 120 (8 % of the friction level)."""

import pytest

from hilbench.analysis.drift.monitor import monitor
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign
from hilbench.firmware_sim.engine.drift import Drift
from tests.analysis.drift.campaign_rows import campaign_rows


@pytest.mark.slow
def test_wear_step_at_run_120_is_found_within_3_runs():
    rows = campaign_rows(SyntheticCampaign(runs=200, seed=1, drift=Drift(wear_step=0.08), wear_step_at_run=120))
    result = monitor(rows)
    s = result.summary()["parameters"]["breakaway"]
    assert len(s["change_points"]) == 1
    cp = s["change_points"][0]
    assert abs(cp["index"] - 120) <= 3 and cp["run"] == f"sim/id{cp['index'] + 1}-1"
    assert cp["shift"] == pytest.approx(0.08 * s["baseline_mean"], rel=0.25)  # the step, from the estimates
    # the charts signal after the step, never before it
    for chart in ("ewma_alarms", "cusum_alarms"):
        assert s[chart] and 120 <= s[chart][0]["index"] <= 130
