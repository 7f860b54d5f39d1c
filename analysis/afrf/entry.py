"""The AFRF's entry in the analysis registry (hilbench.analysis.protocol): read within a memory budget (whole, else
one step window at a time: the same result bit for bit), analyse, report (``afrf.json``, ``afrf.png``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from hilbench.analysis.afrf import AfrfSettings
from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.protocol import STREAMED, Analysis, Inputs, ReadOptions, Result


def read(paths: Sequence[str | Path], options: ReadOptions) -> Inputs:
    """One stepped-sine run: whole when it fits ``options.memory`` (or is host-clocked: resampled whole), else
    one measure window at a time; refused in one line before the samples are read when its longest window does
    not fit."""
    from hilbench.analysis import afrf
    from hilbench.analysis.afrf.steps import largest_window
    from hilbench.common.units import mib

    if len(paths) != 1:
        raise AnalysisError(f"an AFRF is measured on one stepped-sine run, got {len(paths)}")
    path = paths[0]
    record, windows = afrf.stream_header(path, options.allow_incomplete)
    budget = options.memory
    if record.position is not None:  # host-clocked: stream_header read it whole (afrf.load), resampled
        return Inputs([record], budget=budget)
    if budget is None or afrf.array_cost(record.n_samples) <= budget:
        return Inputs([afrf.load(path, allow_incomplete=options.allow_incomplete)], budget=budget)
    window = largest_window(windows)
    if afrf.stream_cost(window) > budget:
        raise AnalysisError(f"{path}: its longest step window ({window} samples) needs about "
                            f"{mib(afrf.stream_cost(window))}, over --memory {mib(budget)}: raise --memory")
    return Inputs([record], reads=[STREAMED], budget=budget)


def compute(inputs: Inputs, settings: AfrfSettings, validation: Inputs | None, progress=None):
    from hilbench.analysis import afrf

    rec = inputs.record
    if inputs.streamed:
        return afrf.analyse_stream(rec.path, settings, allow_incomplete=rec.incomplete is not None,
                                   progress=progress)
    return afrf.analyse(rec, settings, progress=progress)


def _nanmax(a) -> float:
    a = np.asarray(a, float)
    return float(np.nanmax(a)) if np.isfinite(a).any() else math.nan


def summarise(result: Result) -> dict[str, Any]:
    """The measured grid's extent, the first-harmonic compliance |X1/T1| at the lowest frequency of the lowest and
    of the highest amplitude, the largest |X3|/|X1| and period-to-period change, and the warnings."""
    res = result.value
    c1, c3 = res.response[..., 0], res.response[..., min(2, res.n_harmonics - 1)]
    with np.errstate(divide="ignore", invalid="ignore"):
        compliance = np.abs(c1 / res.drive)
        third = np.abs(c3) / np.abs(c1) if res.n_harmonics >= 3 else np.full(c1.shape, math.nan)
    lowest_f = int(np.argmin(res.frequencies))
    return {"afrf_steps": int(np.isfinite(c1).sum()), "afrf_frequency_min": float(res.frequencies.min()),
            "afrf_frequency_max": float(res.frequencies.max()),
            "afrf_compliance_low_amplitude": float(compliance[int(np.argmin(res.amplitudes)), lowest_f]),
            "afrf_compliance_high_amplitude": float(compliance[int(np.argmax(res.amplitudes)), lowest_f]),
            "afrf_third_harmonic_ratio_max": _nanmax(third), "afrf_convergence_max": _nanmax(res.convergence),
            "warnings": "; ".join(res.warnings)}


def write(result: Result, out: Path) -> list[Path]:
    from hilbench.analysis import afrf

    return afrf.report(result.value, out)


COLUMNS = {
    # the measured grid's extent, the first-harmonic compliance |X1/T1| (rotary rad/(N*m), linear m/N) at the
    # lowest frequency of the lowest and of the highest amplitude, the largest |X3|/|X1| and period-to-period
    # change over the grid
    "afrf_steps": ("int64", "1"), "afrf_frequency_min": ("float64", "Hz"), "afrf_frequency_max": ("float64", "Hz"),
    "afrf_compliance_low_amplitude": ("float64", "compliance"),
    "afrf_compliance_high_amplitude": ("float64", "compliance"),
    "afrf_third_harmonic_ratio_max": ("float64", "1"), "afrf_convergence_max": ("float64", "1"),
    "warnings": ("string", ""),
}

ENTRY = Analysis("afrf", "AFRF", read, compute, summarise, AfrfSettings, write=write, protocols=("stepped_sine",),
                 columns=COLUMNS)
