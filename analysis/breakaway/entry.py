"""The break-away probe's entry in the analysis registry (hilbench.analysis.protocol): read a probe run whole
(position, measured current, the ramps), analyse (probe.probe_of_record), report (``breakaway.json``)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from hilbench.analysis.breakaway.probe import PROBE_PROTOCOL
from hilbench.analysis.protocol import Analysis, Inputs, ReadOptions, Result, one_run_whole, write_json

#: bytes per sample of a probe run read whole (t, position, current and the two smoothed derivatives)
BYTES_PER_SAMPLE = 64
BYTES_FIXED = 100 << 20


@dataclass(frozen=True)
class ProbeSettings:
    """``window`` (s) of the velocity's slope; ``velocity_threshold`` (rad/s) taken as sliding (None: 0.05 rad/s
    or five encoder counts per window, whichever is larger)."""

    window: float = 0.01
    velocity_threshold: float | None = None


def read(paths: Sequence[str | Path], options: ReadOptions) -> Inputs:
    """One probe run, whole (a probe lasts seconds); refused in one line when it does not fit
    ``options.memory``."""
    return one_run_whole(paths, options, "a break-away probe", BYTES_FIXED, BYTES_PER_SAMPLE,
                         need_torque=False, channels=("current",), protocol_arrays=("ramps",), torque_channel=None)


def compute(inputs: Inputs, settings: ProbeSettings, validation: Inputs | None, progress=None):
    from hilbench.analysis.breakaway.probe import probe_of_record

    return probe_of_record(inputs.record, **asdict(settings))


def summarise(result: Result) -> dict[str, Any]:
    """The break-away current of each direction (A, signed), the presliding distance (rad) and the fit of the
    slides."""
    res = result.value
    out = res.as_dict()
    for key, value in (res.sliding or {}).items():
        out[f"sliding_{key}"] = value
    for key, value in (res.restoring or {}).items():  # a spring load's fit over every moving sample
        out[f"restoring_{key}"] = value
    out.pop("sliding_fit", None)
    out.pop("restoring_fit", None)
    return out


def write(result: Result, out: Path) -> list[Path]:
    return [write_json(out / "breakaway.json", result.value.as_dict())]


COLUMNS = {"breakaway_positive_A": ("float64", "A"), "breakaway_negative_A": ("float64", "A"),
           "presliding_distance_rad": ("float64", "rad")}

ENTRY = Analysis("breakaway", "Break-away probe", read, compute, summarise, ProbeSettings, write=write,
                 protocols=(PROBE_PROTOCOL,), columns=COLUMNS)
