"""Acceptance: a campaign whose only drift is temperature: the dependence is found, no wear alarm is raised."""

import numpy as np
import pytest

from hilbench.analysis.drift.monitor import DriftSettings, monitor
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign
from hilbench.firmware_sim.engine.drift import Drift
from tests.analysis.drift.campaign_rows import campaign_rows

ALPHA = -0.005  # 1/K: the friction level falls 0.5 % per kelvin


@pytest.mark.slow
def test_temperature_dependence_is_found_and_no_wear_alarm():
    ambient = np.random.default_rng(7).uniform(18.0, 30.0, 200)  # the lab's ambient from day to day, degC
    rows = campaign_rows(SyntheticCampaign(runs=200, seed=21, ambient=lambda i: float(ambient[i]),
                                           drift=Drift(level_temperature_coefficient=ALPHA)))
    summary = monitor(rows).summary()
    c = summary["parameters"]["breakaway"]["covariates"]["temperature_mean"]
    assert c["found"]
    # d(break-away)/dT = alpha * break-away at the reference temperature: within 3 standard errors
    truth = ALPHA * summary["parameters"]["breakaway"]["baseline_mean"] / (1 + ALPHA * (c["centre"] - 23.0))
    assert abs(c["coefficient"] - truth) <= 3 * c["se"]
    assert summary["alarms"] == []
    # the fit explains the spread the temperature adds: the residual sigma is below the one without it
    blind = monitor(rows, DriftSettings(covariates=())).summary()["parameters"]["breakaway"]
    assert summary["parameters"]["breakaway"]["sigma"] < 0.9 * blind["sigma"]
