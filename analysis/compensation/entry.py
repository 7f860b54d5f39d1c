"""The compensation metrics' entry in the analysis registry (hilbench.analysis.protocol): read a compensated run
(position, the commanded current; its reference rebuilt from the protocol's parameters), analyse
(metrics.tracking_metrics), report (``tracking.json``)."""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.protocol import Analysis, Inputs, ReadOptions, Result, one_run_whole, write_json
from hilbench.common.runfile import CURRENT_CMD, HOST_TIME, SAMPLE_TIMES_KEY

#: bytes per sample read whole (t, position, current, and the reference's position, velocity and acceleration)
BYTES_PER_SAMPLE = 64
BYTES_FIXED = 100 << 20


#: the metrics' glitch window (s) and settling band (rad) of a run that records none
WINDOW, TOLERANCE = 0.05, 1e-4


@dataclass(frozen=True)
class TrackingSettings:
    """``window`` (s) after each reversal for the glitch; settling ``tolerance`` (rad) of point-to-point moves.
    None: the run's own (its protocol parameters ``window`` and ``tolerance``, which ``hilbench compensate`` and a
    ``[[compensate]]`` step record), else :data:`WINDOW` and :data:`TOLERANCE`."""

    window: float | None = None
    tolerance: float | None = None


def reference_of(record):
    """The reference a compensated run played, rebuilt from its protocol parameters (``reference`` and that
    kind's parameters) at its sample rate."""
    from hilbench.analysis.compensation.references import make_reference, point_to_point, slow_sine, triangle

    params = dict(record.protocol_params)
    kind = params.get("reference")
    builder = {"sine": slow_sine, "triangle": triangle, "point_to_point": point_to_point}.get(kind)
    if builder is None:
        raise AnalysisError(f"{record.path}: a {record.protocol_name or 'unnamed'} run without a tracking reference "
                            "(hilbench compensate writes one)")
    names = set(inspect.signature(builder).parameters) - {"fs"}
    kw = {k: tuple(v) if isinstance(v, list) else v for k, v in params.items() if k in names}
    return make_reference(kind, float(record.sample_rate), **kw)


def reference_head(ref, m: int):
    """The first ``m`` samples of the reference ``ref`` (its moves and sections cut at sample ``m``)."""
    moves = np.minimum(ref.moves, m)
    return replace(ref, position=ref.position[:m], velocity=ref.velocity[:m], acceleration=ref.acceleration[:m],
                   moves=moves[moves[:, 0] < m],
                   sections=[(name, a, min(b, m)) for name, a, b in ref.sections if a < m])


def read(paths: Sequence[str | Path], options: ReadOptions) -> Inputs:
    """One compensated run, whole; refused in one line when it does not fit ``options.memory``."""
    return one_run_whole(paths, options, "tracking metrics", BYTES_FIXED, BYTES_PER_SAMPLE,
                         need_torque=False, channels=(CURRENT_CMD,), torque_channel=None)


def compute(inputs: Inputs, settings: TrackingSettings, validation: Inputs | None, progress=None):
    from hilbench.analysis.compensation.metrics import tracking_metrics

    rec = inputs.record
    ref = reference_of(rec)
    if rec.device.get(SAMPLE_TIMES_KEY) == HOST_TIME and rec.position.size == ref.n - 1:
        # a host-clocked drive's run is resampled on the grid j/rate from its first trigger to its last one, which
        # ends one sample short of the played reference when the last trigger came early: score what the grid holds
        ref = reference_head(ref, rec.position.size)
    if rec.position.size != ref.n:
        raise AnalysisError(f"{rec.path}: {rec.position.size} samples recorded, the reference has {ref.n}; the run "
                            "did not complete")
    params = rec.protocol_params
    window = settings.window if settings.window is not None else float(params.get("window", WINDOW))
    tolerance = settings.tolerance if settings.tolerance is not None else float(params.get("tolerance", TOLERANCE))
    return tracking_metrics(ref, rec.position, rec.channel(CURRENT_CMD), window=window, tolerance=tolerance)


def summarise(result: Result) -> dict[str, Any]:
    """:meth:`Metrics.summary`: rms and max tracking error, reversal glitches, settling times, effort."""
    return result.value.summary()


def write(result: Result, out: Path) -> list[Path]:
    return [write_json(out / "tracking.json", result.value.summary())]


COLUMNS = {"rms_error_rad": ("float64", "rad"), "max_error_rad": ("float64", "rad"),
           "glitch_mean_rad": ("float64", "rad"), "glitch_max_rad": ("float64", "rad"),
           "effort_rms_a": ("float64", "A"), "settling_max_s": ("float64", "s")}

ENTRY = Analysis("compensation", "Tracking metrics (compensated run)", read, compute, summarise,
                 TrackingSettings, write=write, protocols=("compensated",), columns=COLUMNS)
