"""The analysis steps ``hilbench analyse`` runs on one run file, each returning one small flat dict.

A step is an entry of the analysis registry (hilbench.analysis.protocol.ANALYSES) and its row flattening: the step
reads the file through the entry's ``read`` (inside a worker process, within :data:`STEP_MEMORY`; a run reads as
the CLI and the GUI read it), cuts it into the head it fits and the tail it validates on
(``protocol.held_out``) when the analysis takes a validation run, calls the entry's ``analyse``, and takes the
columns of its report's summary (``Analysis.columns``), with the campaign's own columns (:data:`STEP_COLUMNS`:
the run's size, its temperature, the grade of the verdict). Any registered analysis is a step.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass
from functools import partial
from typing import Any

import numpy as np

from hilbench.analysis import protocol

#: the campaign's own columns besides each analysis's (``Analysis.columns``): name -> (Arrow type name, unit).
#: A unit that names a quantity of ``hilbench.common.units.AXIS_UNITS`` (``inertia``, ``torque``...) follows the
#: run's axis (the row's ``axis``); the table's metadata gives both units. Common columns: table.BASE_COLUMNS.
STEP_COLUMNS: dict[str, tuple[str, str]] = {
    "verdict": ("string", ""),  # identify: the grade of hilbench.bench.verdict; residual: the loop's verdict
    "temperature_mean": ("float64", "degC"), "sliding_distance": ("float64", "position"),
    "samples": ("int64", "1"), "duration": ("float64", "s"),
}


def _columns() -> dict[str, tuple[str, str]]:
    """Every column a step can fill: the campaign's and each registered analysis's (one type and unit each)."""
    out = dict(STEP_COLUMNS)
    for e in protocol.entries().values():
        for name, kind in e.columns.items():
            if out.setdefault(name, kind) != kind:
                raise ValueError(f"column {name!r}: {e.name} declares {kind}, another step {out[name]}")
    return out


#: result columns of the steps: name -> (Arrow type name, unit)
COLUMNS: dict[str, tuple[str, str]] = _columns()
#: bytes a step may use to read its run (a worker's share of a lab PC); over it the entry streams or refuses
STEP_MEMORY = 2 << 30


@dataclass(frozen=True)
class StepSettings:
    """What the steps compute with; part of every row's key (a changed setting re-analyses).

    thresholds: candidate Maxwell-slip thresholds of the identification (``hilbench identify --thresholds``).
    method: ``lip`` or ``oe`` (``paper`` is minutes per run). coulomb/offset: extra terms.
    validation_fraction: the tail of each run held out for validation (the model is fitted on the rest)."""

    thresholds: int = 32
    method: str = "lip"
    coulomb: bool = False
    offset: bool = False
    validation_fraction: float = 0.3
    compare_families: tuple[str, ...] = ("coulomb_viscous", "stribeck", "maxwell_slip")
    residual_start: tuple[str, ...] = ("inertia", "maxwell_slip")
    presliding_replicates: int = 20
    skeleton_mass: float | None = None  # J (kg*m^2) or m (kg); None: the run's declared calibration inertia
    allow_incomplete: bool = False  # analyse aborted or short runs too (--allow-incomplete), as the commands do

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def sliding_distance(position: np.ndarray, fs: float) -> float:
    """Total variation of the position (rad): the distance slid, from a zero-phase low-passed position so that
    encoder flicker and noise (which add |dx| without any sliding) do not count. Cut-off fs/20."""
    from scipy import signal

    from hilbench.analysis.identification.regressors import lowpass_design

    x = np.asarray(position, dtype=float)
    if x.size < 30:
        return float(np.sum(np.abs(np.diff(x))))
    sos = lowpass_design(2, fs / 20, fs)[0].copy()
    return float(np.sum(np.abs(np.diff(signal.sosfiltfilt(sos, x)))))


def _breakaway_se(model) -> float:
    from hilbench.analysis.identification.entry import breakaway_se

    return breakaway_se(model)


def step_settings(name: str, s: StepSettings) -> Any:
    """The analysis settings of step ``name`` from the campaign's :class:`StepSettings` (the entry's defaults for
    an analysis the campaign sets nothing of)."""
    if name == "identify":
        from hilbench.analysis.identification.entry import IdentifySettings
        from hilbench.analysis.identification.maxwell_fit import LipSettings

        return IdentifySettings(LipSettings(n_thresholds=s.thresholds, coulomb=s.coulomb, offset=s.offset),
                                method=s.method)
    if name == "compare":
        from hilbench.analysis.identification.maxwell_fit import LipSettings
        from hilbench.analysis.models.compare import CompareSettings

        # the maxwell_slip row fits the identify step's terms, so the two rows of one model read one figure
        lip = LipSettings(n_thresholds=s.thresholds, coulomb=s.coulomb, offset=s.offset)
        return CompareSettings(families=s.compare_families, lip=lip)
    if name == "residual":
        from hilbench.analysis.residual import ResidualSettings

        return ResidualSettings(start=s.residual_start)
    if name == "presliding":
        from hilbench.analysis.presliding.entry import PreslidingAnalysis

        return PreslidingAnalysis(replicates=s.presliding_replicates)
    if name == "skeleton":
        from hilbench.analysis.skeleton import SkeletonSettings

        return SkeletonSettings(mass=s.skeleton_mass)
    return None


def _size(rec) -> dict[str, Any]:
    n = int(rec.n_samples)
    return {"samples": n, "duration": float(rec.t[-1] - rec.t[0]) if rec.t is not None and rec.t.size
            else (n - 1) / rec.sample_rate}


def _temperature(path: str) -> dict[str, Any]:
    """The mean of the run's temperature channel (degC), when it has one."""
    from hilbench.analysis.record import load_record

    rec = load_record(path, need_torque=False, need_position=False, channels=("temperature",),
                      allow_incomplete=True)
    t = rec.channels.get("temperature")
    if t is None or not np.isfinite(t).any():  # NaN: the protocol's "no reading"
        return {}
    return {"temperature_mean": float(np.nanmean(t))}


def _identify_row(result: protocol.Result, inputs: protocol.Inputs, path: str) -> dict[str, Any]:
    """identify's own columns: the grade of the verdict, the distance slid over the whole run (``inputs``, before
    the split) and the temperature."""
    from hilbench.common.metrics import DRIFT_POSITION_PCT, grade, percent

    f = result.value.figures
    where = "validation" if result.validation is not None else "train"
    row: dict[str, Any] = {}
    if f"{where}_torque_nrmse" in f:  # the grade of bench.verdict.judge's line, from the same bands
        torque, position = percent(f[f"{where}_torque_nrmse"]), percent(f[f"{where}_position_nrmse"])
        drifts = "; the open-loop position drifts" if position > DRIFT_POSITION_PCT else ""
        row["verdict"] = "no" if torque != torque else grade(torque) + drifts
    if not inputs.streamed:
        row["sliding_distance"] = sliding_distance(inputs.record.position, inputs.record.sample_rate)
    return {**row, **_temperature(path)}


#: step -> its own columns beside the analysis's summary: (result, the run's inputs, run file) -> dict
ROWS: dict[str, Callable[[protocol.Result, protocol.Inputs, str], dict[str, Any]]] = {"identify": _identify_row}


def run_step(name: str, path: str, settings: StepSettings) -> dict[str, Any]:
    """Step ``name`` on one run file: the registry entry's read, held-out split, analyse and summary (module
    docstring); one flat row of :data:`COLUMNS`."""
    from hilbench.analysis.errors import AnalysisError

    entry = protocol.entry(name)
    # the one loader: an aborted or short run is a failed row (unless --allow-incomplete)
    inputs = entry.read([path], protocol.ReadOptions(memory=STEP_MEMORY, allow_incomplete=settings.allow_incomplete))
    head, tail = inputs, None
    if entry.matches is not None and settings.validation_fraction > 0:
        head, tail = protocol.held_out(inputs, settings.validation_fraction)
    elif entry.needs_validation:
        raise AnalysisError(f"{name} scores models on the held-out tail: --validation-fraction must be > 0")
    result = entry.analyse(head, step_settings(name, settings), tail)
    summary = entry.report(result)[1]
    row = {k: v for k, v in summary.items() if k in entry.columns}
    row.update(_size(inputs.record))
    row.update(ROWS.get(name, lambda _r, _i, _p: {})(result, inputs, path))
    return row




def step(name: str) -> Callable[[str, StepSettings], dict[str, Any]]:
    """The step function of analysis ``name`` (picklable: a worker process runs it)."""
    return partial(run_step, name)


identify_step = step("identify")


class _Steps(Mapping):
    """Step name -> step function, read live from the registry (a registered analysis is a step at once)."""

    def __getitem__(self, name: str) -> Callable[[str, StepSettings], dict[str, Any]]:
        if name not in protocol.ANALYSES:
            raise KeyError(name)
        return step(name)

    def __iter__(self) -> Iterator[str]:
        return iter(protocol.ANALYSES)

    def __len__(self) -> int:
        return len(protocol.ANALYSES)


STEPS: Mapping[str, Callable[[str, StepSettings], dict[str, Any]]] = _Steps()


def steps_for(protocol_name: str, wanted: tuple[str, ...]) -> list[str]:
    """The wanted steps a run of ``protocol_name`` supports (the entry's ``protocols``)."""
    return [s for s in wanted if s in protocol.ANALYSES and protocol_name in protocol.entry(s).protocols]


def run_meta(path: str) -> dict[str, Any]:
    """The run file's own identity: run id, start time and operator (its root attributes alone)."""
    from hilbench.common.runfile.identity import run_identity

    return run_identity(path)
