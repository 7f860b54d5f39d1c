"""Results rows of simulated campaigns, made fast for the drift tests: the runs of
bench.campaign_analysis.synthetic (the C plant with the drift laws) identified in memory by the same NNLS fit
``hilbench analyse`` runs (analysis.identification.maxwell_fit.fit_lip, 16 thresholds), without writing files:
200 runs take seconds. The end-to-end path through files is tests/bench/campaign_analysis."""

from __future__ import annotations

import numpy as np

from hilbench.analysis.identification.maxwell_fit import LipSettings, fit_lip
from hilbench.bench.campaign_analysis.steps import _breakaway_se, sliding_distance
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, simulate_runs


def campaign_rows(spec: SyntheticCampaign, campaign: str = "sim") -> list[dict]:
    rows = []
    fs = float(spec.sample_rate)
    for run in simulate_runs(spec):
        ch = run.channels
        fit = fit_lip(ch["position"], ch["torque"], fs, settings=LipSettings(n_thresholds=16, timing="hold_previous"))
        m = fit.model
        rows.append({"campaign": campaign, "key": run.key, "start_time": run.start_time, "status": "ok",
                     "inertia": m.inertia, "inertia_se": m.std_errors["inertia"],
                     "breakaway": m.breakaway, "breakaway_se": _breakaway_se(m),
                     "viscous": m.viscous, "viscous_se": m.std_errors["viscous"],
                     "temperature_mean": float(np.mean(ch["temperature"])), "ambient": run.ambient,
                     "sliding_distance": sliding_distance(ch["position"], fs), "distance_true": run.distance_end})
    return rows
