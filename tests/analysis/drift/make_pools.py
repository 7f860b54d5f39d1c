"""Pools of identified runs from the C plant, for the drift monitor's false-alarm and detection tests:
``python -m tests.analysis.drift.make_pools`` writes tests/data/drift/pools.npz (a few minutes; the tests read it).

A stationary campaign of any length is a random draw of runs from a pool of exchangeable runs (same plant, same
protocol, no drift), so hundreds of campaigns cost no simulation. Two pools of 600 runs each, 2 s at 1 kHz,
identified by the same NNLS fit as ``hilbench analyse`` (tests/analysis/drift/campaign_rows.py):

- ``flat``: 23 degC ambient, no drift law;
- ``warm``: ambient drawn uniformly in 18-30 degC per run, friction level -0.5 %/K (a temperature covariate).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign
from hilbench.firmware_sim.engine.drift import Drift
from tests.analysis.drift.campaign_rows import campaign_rows

POOL = Path(__file__).resolve().parents[2] / "data" / "drift" / "pools.npz"
FIELDS = ("breakaway", "breakaway_se", "viscous", "viscous_se", "temperature_mean")
RUNS = 600


def main() -> None:
    ambient = np.random.default_rng(11).uniform(18.0, 30.0, RUNS)
    pools = {
        "flat": campaign_rows(SyntheticCampaign(runs=RUNS, seed=50_000)),
        "warm": campaign_rows(SyntheticCampaign(runs=RUNS, seed=60_000, ambient=lambda i: float(ambient[i]),
                                                drift=Drift(level_temperature_coefficient=-0.005))),
    }
    arrays = {f"{pool}_{f}": np.array([r[f] for r in rows]) for pool, rows in pools.items() for f in FIELDS}
    POOL.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(POOL, **arrays)
    print(f"{POOL}: {', '.join(f'{k} {v.size}' for k, v in arrays.items())}")


if __name__ == "__main__":
    main()
