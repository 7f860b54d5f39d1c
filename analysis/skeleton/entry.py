"""The skeleton's entry in the analysis registry (hilbench.analysis.protocol): read chirp runs within a memory
budget (whole, else chunk by chunk into decimated copies), analyse (ForceVib per run, composed), report
(skeleton.json, skeleton.png)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.protocol import STREAMED, Analysis, Inputs, ReadOptions, Result, whole
from hilbench.analysis.skeleton import SkeletonSettings


def read(paths: Sequence[str | Path], options: ReadOptions) -> Inputs:
    """The runs whole when they fit ``options.memory`` together (or one is host-clocked: resampled whole), else
    their headers, each streamed by ``analyse`` into a copy decimated to its band (which refuses in one line,
    before reading the samples, a copy that would not fit)."""
    from hilbench.analysis import skeleton
    from hilbench.analysis.record import stream_record

    heads = [stream_record(p, **options.loader()) for p in paths]
    samples = sum(h.n_samples for h, _ in heads)
    if options.memory is None or skeleton.array_cost(samples) <= options.memory or any(
            src is None for _, src in heads):
        return whole(paths, options, heads)
    return Inputs([h for h, _ in heads], [s for _, s in heads], [STREAMED] * len(heads), options.memory)


def compute(inputs: Inputs, settings: SkeletonSettings, validation: Inputs | None, progress=None):
    from hilbench.analysis import skeleton

    if not inputs.streamed:
        return skeleton.analyse(inputs.records, settings, progress=progress)
    rec = inputs.record
    return skeleton.analyse_stream(inputs.paths, settings, torque_channel=rec.torque_channel, timing=rec.timing,
                                   allow_incomplete=any(r.incomplete is not None for r in inputs.records),
                                   budget=inputs.budget, progress=progress)


def summarise(result: Result) -> dict[str, Any]:
    """The composed amplitude range, the equivalent stiffness k_eq at its smallest and largest amplitude bins and
    the warnings."""
    res = result.value
    a, k = np.asarray(res.curves.amplitude, float), np.asarray(res.curves.stiffness, float)
    ok = np.isfinite(a) & np.isfinite(k)
    if not ok.any():
        raise AnalysisError(f"{', '.join(res.runs)}: no amplitude bin has a skeleton point")
    a, k = a[ok], k[ok]
    return {"skeleton_bins": int(a.size), "skeleton_amplitude_min": float(a.min()),
            "skeleton_amplitude_max": float(a.max()), "skeleton_stiffness_low_amplitude": float(k[np.argmin(a)]),
            "skeleton_stiffness_high_amplitude": float(k[np.argmax(a)]), "mass": res.mass,
            "warnings": "; ".join(res.warnings)}


def write(result: Result, out: Path) -> list[Path]:
    from hilbench.analysis import skeleton
    from hilbench.analysis.skeleton.figure import skeleton_figure

    return skeleton.report(result.value, out, figure=skeleton_figure)


COLUMNS = {
    # the composed amplitude range (rotary rad, linear m) and the equivalent stiffness k_eq at its smallest and
    # largest amplitude bins (rotary N*m/rad, linear N/m)
    "skeleton_bins": ("int64", "1"),
    "skeleton_amplitude_min": ("float64", "position"), "skeleton_amplitude_max": ("float64", "position"),
    "skeleton_stiffness_low_amplitude": ("float64", "stiffness"),
    "skeleton_stiffness_high_amplitude": ("float64", "stiffness"),
    "warnings": ("string", ""),
}

ENTRY = Analysis("skeleton", "Skeleton (ForceVib)", read, compute, summarise, SkeletonSettings, write=write,
                 protocols=("chirp",), columns=COLUMNS)
