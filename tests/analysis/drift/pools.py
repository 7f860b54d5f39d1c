"""Stationary campaigns of any length drawn from the pools of identified plant runs (make_pools.py)."""

from __future__ import annotations

from functools import cache

import numpy as np

from tests.analysis.drift.make_pools import FIELDS, POOL


@cache
def pool(name: str) -> dict[str, np.ndarray]:
    with np.load(POOL) as data:
        return {f: data[f"{name}_{f}"] for f in FIELDS}


def campaign(name: str, runs: int, rng: np.random.Generator, *, order: str = "random",
             protocol: str = "identification") -> list[dict]:
    """``runs`` rows drawn without replacement from pool ``name``; ``order`` "random" (a stationary campaign) or
    "warm-up" (the same runs sorted by winding temperature: a motor warming over the campaign)."""
    p = pool(name)
    idx = rng.choice(p["breakaway"].size, runs, replace=False)
    if order == "warm-up":
        idx = idx[np.argsort(p["temperature_mean"][idx])]
    return [{"campaign": "c", "key": f"id{i + 1}-1", "protocol": protocol, "settings_hash": "s",
             "start_time": f"2026-01-{1 + i // 1440:02d}T{(i // 60) % 24:02d}:{i % 60:02d}:00Z", "status": "ok",
             **{f: float(p[f][j]) for f in FIELDS}} for i, j in enumerate(idx)]
