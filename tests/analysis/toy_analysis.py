"""A toy analysis for tests/analysis/test_protocol.py: the whole package a new analysis needs (read, analyse,
report and its registry entry). It sums the position's absolute increments, sum |x[k+1] - x[k]| (rad): the
distance slid, unfiltered."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hilbench.analysis.protocol import Analysis, Inputs, ReadOptions, Result, one_run_whole, write_json


@dataclass(frozen=True)
class ToySettings:
    scale: float = 1.0


def read(paths, options: ReadOptions) -> Inputs:
    return one_run_whole(paths, options, "the toy", 64 << 20, 24)


def compute(inputs: Inputs, settings: ToySettings, validation, progress=None) -> float:
    return settings.scale * float(np.sum(np.abs(np.diff(inputs.record.position))))


def summarise(result: Result) -> dict:
    return {"model": "toy", "sliding_distance": result.value}


def write(result: Result, out: Path) -> list[Path]:
    return [write_json(out / "toy.json", summarise(result))]


ENTRY = Analysis("toy", "Toy (distance slid)", read, compute, summarise, ToySettings, write=write,
                 protocols=("identification",), columns={"model": ("string", ""),
                                                        "sliding_distance": ("float64", "rad")})
