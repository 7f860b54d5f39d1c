"""Campaign folders of short simulated runs, written without a device: the C plant (with the drift laws of
:mod:`hilbench.firmware_sim.engine.drift`) through :class:`~hilbench.common.runfile.RunWriter`, plus an ``index.json``
as ``hilbench campaign`` writes it. For tests and benchmarks: 200 runs take seconds, not the hours a device
would take in real time."""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

from hilbench.bench.acquisition import excitations
from hilbench.bench.acquisition.campaign import INDEX_NAME
from hilbench.common.runfile import CURRENT_CMD, SAMPLE_INDEX, RunWriter
from hilbench.firmware_sim.engine.drift import Drift, DriftState, rest, simulate_drifting
from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import PlantParams


@dataclass
class SyntheticCampaign:
    """What to simulate: ``runs`` runs of ``duration`` s at ``sample_rate`` Hz, one every ``interval`` s.

    ``ambient`` gives each run's ambient temperature (degC) from its index (default: 23 degC throughout);
    ``repeats`` groups consecutive runs as repeats of one planned run (name ``id<k>``, repeat 1..repeats).
    ``seed`` seeds the plant noise and the excitation of every run (run i uses seed + i)."""

    runs: int = 20
    duration: float = 2.0
    sample_rate: float = 1000.0
    amplitude: float = 12.0  # A: about 3x the DC motor's break-away current
    period: float = 1.0      # s, excitation envelope
    interval: float = 300.0  # s between run starts (the winding cools in between)
    repeats: int = 1
    seed: int = 0
    noise_current: float = 0.01      # A rms
    counts_per_rev: int = 2**16
    drift: Drift = field(default_factory=Drift)
    ambient: Callable[[int], float] | None = None
    params: PlantParams | None = None
    operator: str = "sim"
    start: datetime = field(default_factory=lambda: datetime(2026, 1, 5, 8, 0, tzinfo=UTC))
    #: put the drift's wear step at the distance slid when this run starts (None: at drift.wear_step_distance)
    wear_step_at_run: int | None = None


@dataclass
class SimulatedRun:
    index: int
    name: str
    repeat: int
    start_time: str                 # ISO 8601 UTC
    ambient: float                  # degC
    channels: dict[str, np.ndarray]  # the run file's channels, plus "temperature" (degC)
    params: dict                    # the identification protocol's parameters
    distance_end: float             # cumulative distance slid at the run's end (truth), rad

    @property
    def key(self) -> str:
        return f"{self.name}-{self.repeat}"


def simulate_runs(spec: SyntheticCampaign) -> Iterator[SimulatedRun]:
    """The campaign's runs one after another, with the drift state carried from run to run."""
    base = (spec.params or dc_motor()).replace(counts_per_rev=spec.counts_per_rev,
                                               noise_current=spec.noise_current)
    fs = float(spec.sample_rate)
    ambient0 = spec.ambient(0) if spec.ambient else 23.0
    state = DriftState(temperature=ambient0, ambient=ambient0)
    drift = spec.drift
    for i in range(spec.runs):
        if i == spec.wear_step_at_run:
            drift = replace(drift, wear_step_distance=state.distance)
        state.ambient = spec.ambient(i) if spec.ambient else 23.0
        if i:
            rest(drift, state, spec.interval - spec.duration)
        ex = excitations.random_enveloped(spec.duration, fs, amplitude=spec.amplitude, period=spec.period,
                                          seed=spec.seed + i, mode="current", limit=None)
        out_i, temperature = simulate_drifting(base.replace(seed=spec.seed + i), ex.u, 1 / fs, drift, state)
        n = ex.u.size
        channels = {SAMPLE_INDEX: np.arange(n), "t": np.arange(n) / fs, CURRENT_CMD: ex.u,
                    "current": out_i.current_meas, "torque": base.torque_constant * out_i.current_meas,
                    "position": out_i.position_meas, "temperature": temperature}
        params = {"duration": spec.duration, "amplitude": spec.amplitude, "period": spec.period,
                  "seed": spec.seed + i, "sample_rate": int(fs), "mode": "current"}
        start = spec.start + timedelta(seconds=i * spec.interval)
        yield SimulatedRun(i, f"id{i // spec.repeats + 1}", i % spec.repeats + 1,
                           start.isoformat().replace("+00:00", "Z"), state.ambient, channels, params, state.distance)


def write_campaign(out_dir: str | os.PathLike, spec: SyntheticCampaign,
                   fail_runs: Sequence[int] = ()) -> list[dict]:
    """Write the runs and ``index.json`` into ``out_dir`` (created; must not hold an index). Returns the index
    entries. ``fail_runs``: indices of runs whose file is written without a position channel (an analysis
    that needs it fails on them: for fault tests)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if (out / INDEX_NAME).exists():
        raise FileExistsError(f"{out / INDEX_NAME}: exists; a synthetic campaign goes into a new folder")
    entries = []
    for run in simulate_runs(spec):
        names = [SAMPLE_INDEX, "t", CURRENT_CMD, "current", "torque"]
        names += [] if run.index in fail_runs else ["position"]
        with RunWriter(out / f"{run.key}.h5", sample_rate=float(spec.sample_rate),
                       channels=(*names, "temperature"), protocol_name="identification",
                       protocol_params=run.params, operator=spec.operator, start_time=run.start_time,
                       device={"model": "synthetic", "serial": "C-plant"}) as w:
            w.append({k: run.channels[k] for k in [*names, "temperature"]})
            uid = w.uid
        entries.append({"key": run.key, "name": run.name, "repeat": run.repeat, "protocol": "identification",
                        "file": f"{run.key}.h5", "status": "completed", "uid": uid,
                        "samples": int(run.channels["t"].size), "parameters": run.params, "settings": {},
                        "environment": {"ambient": f"{run.ambient:g} C"},
                        "truth": {"distance_end": run.distance_end}})
    doc = {"campaign": f"synthetic-{spec.seed}.toml", "schema": "hilbench-campaign-index", "version": 1,
           "runs": entries}
    (out / INDEX_NAME).write_text(json.dumps(doc, indent=2))
    return entries
