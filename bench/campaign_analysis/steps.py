"""The analysis steps ``hilbench analyse`` runs on one run file, each returning one small flat dict.

This is the one adapter between the campaign engine and the analysis packages: a step reads the file itself
through the one record loader (it runs inside a worker process; hilbench.analysis.record.load_record, so a run
reads as the CLI and the GUI read it), cuts it into the head it fits and the tail it validates on
(hilbench.analysis.record_split), calls the analysis package's front door ``analyse`` as the CLI command does, and
flattens its result into the columns of :data:`COLUMNS`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

#: step -> protocols whose runs it can analyse (a run gets the steps its protocol supports)
PROTOCOLS_OF_STEP = {"identify": ("identification", "chirp"), "compare": ("identification", "chirp"),
                     "residual": ("identification", "chirp"), "presliding": ("presliding",),
                     "afrf": ("stepped_sine",), "skeleton": ("chirp",)}
STEPS_DONE = tuple(PROTOCOLS_OF_STEP)

#: result columns of the steps: name -> (Arrow type name, unit). Common columns: engine.BASE_COLUMNS.
COLUMNS: dict[str, tuple[str, str]] = {
    "inertia": ("float64", "kg*m^2"), "inertia_se": ("float64", "kg*m^2"),
    "breakaway": ("float64", "N*m"), "breakaway_se": ("float64", "N*m"),
    "viscous": ("float64", "N*m*s/rad"), "viscous_se": ("float64", "N*m*s/rad"),
    "coulomb": ("float64", "N*m"), "coulomb_se": ("float64", "N*m"),
    "offset": ("float64", "N*m"), "offset_se": ("float64", "N*m"),
    "n_elements": ("int64", "1"),
    "train_torque_nrmse": ("float64", "1"), "validation_torque_nrmse": ("float64", "1"),
    "validation_position_nrmse": ("float64", "1"), "validation_position_nrmse_segmented": ("float64", "1"),
    "verdict": ("string", ""),
    # compare: the family with the lowest validation torque NRMSE; residual: the terms of the final model
    "model": ("string", ""), "validation_torque_nrmse_start": ("float64", "1"),
    # presliding: the quantities of docs/presliding.md with their standard uncertainties (axis units: rotary
    # N*m, N*m/rad, rad; linear N, N/m, m) and the force simulated from the displacement against the measured one
    "presliding_breakaway": ("float64", "N*m"), "presliding_breakaway_se": ("float64", "N*m"),
    "initial_stiffness": ("float64", "N*m/rad"), "initial_stiffness_se": ("float64", "N*m/rad"),
    "presliding_distance": ("float64", "rad"), "presliding_distance_se": ("float64", "rad"),
    "validation_force_relative_error": ("float64", "1"),
    # afrf: the measured grid's extent, the first-harmonic compliance |X1/T1| (rotary rad/(N*m), linear m/N) at
    # the lowest frequency of the lowest and of the highest amplitude, the largest |X3|/|X1| and period-to-period
    # change over the grid
    "afrf_steps": ("int64", "1"), "afrf_frequency_min": ("float64", "Hz"), "afrf_frequency_max": ("float64", "Hz"),
    "afrf_compliance_low_amplitude": ("float64", "rad/(N*m)"),
    "afrf_compliance_high_amplitude": ("float64", "rad/(N*m)"),
    "afrf_third_harmonic_ratio_max": ("float64", "1"), "afrf_convergence_max": ("float64", "1"),
    # skeleton: the composed amplitude range (rotary rad, linear m) and the equivalent stiffness k_eq at its
    # smallest and largest amplitude bins (rotary N*m/rad, linear N/m)
    "skeleton_bins": ("int64", "1"),
    "skeleton_amplitude_min": ("float64", "rad"), "skeleton_amplitude_max": ("float64", "rad"),
    "skeleton_stiffness_low_amplitude": ("float64", "N*m/rad"),
    "skeleton_stiffness_high_amplitude": ("float64", "N*m/rad"),
    # afrf, skeleton, presliding: the analysis's warnings, "; "-separated (presliding: the span of a long record
    # analysed, fewer than 4 reversals)
    "warnings": ("string", ""),
    "temperature_mean": ("float64", "degC"), "sliding_distance": ("float64", "rad"),
    "samples": ("int64", "1"), "duration": ("float64", "s"),
}


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
    """Standard error of the break-away sum k_i*Delta_i from the elements' own errors (their covariance is not
    kept in the model, so correlations are ignored: an approximation that says so in docs/campaign-analysis.md)."""
    se = np.asarray(model.std_errors.get("ms_stiffness", []), dtype=float)
    if se.size != model.ms_stiffness.size:
        return math.nan
    return float(np.sqrt(np.sum((se * np.asarray(model.ms_delta)) ** 2)))


def identify_step(path: str, settings: StepSettings) -> dict[str, Any]:
    """``hilbench identify`` on one run: ``analysis.identification.analyse`` fitted on the head, validated on the
    held-out tail (analysis.record_split)."""
    from hilbench.analysis.identification import analyse
    from hilbench.analysis.identification.maxwell_fit import LipSettings
    from hilbench.analysis.record import load_record
    from hilbench.analysis.record_split import split
    from hilbench.bench.verdict import judge

    # the one loader: an aborted or short run is a failed row (unless --allow-incomplete)
    rec = load_record(path, channels=("temperature",), allow_incomplete=settings.allow_incomplete)
    head, tail = split(rec, settings.validation_fraction)
    lip = LipSettings(n_thresholds=settings.thresholds, coulomb=settings.coulomb, offset=settings.offset)
    res = analyse(head, lip, method=settings.method, validation=tail)
    m, f, se = res.model, res.figures, res.model.std_errors
    row: dict[str, Any] = {
        "inertia": m.inertia, "inertia_se": se.get("inertia", math.nan),
        "breakaway": m.breakaway, "breakaway_se": se.get("breakaway", _breakaway_se(m)),
        "viscous": m.viscous, "viscous_se": se.get("viscous", math.nan),
        "coulomb": m.coulomb, "coulomb_se": se.get("coulomb", math.nan),
        "offset": m.offset, "offset_se": se.get("offset", math.nan),
        "n_elements": int(m.ms_stiffness.size),
        "train_torque_nrmse": f.get("train_torque_nrmse"),
        "validation_torque_nrmse": f.get("validation_torque_nrmse"),
        "validation_position_nrmse": f.get("validation_position_nrmse"),
        "validation_position_nrmse_segmented": f.get("validation_position_nrmse_segmented"),
        **_size(rec), "sliding_distance": sliding_distance(rec.position, rec.sample_rate),
    }
    where = "validation" if tail is not None else "train"
    verdict = judge(100 * f[f"{where}_torque_nrmse"], 100 * f[f"{where}_position_nrmse"],
                    100 * f[f"{where}_position_nrmse_segmented"], where, residual_hint=False)
    grade = verdict.split(":", 1)[1].split()[0] if verdict.startswith("verdict:") else "none"
    row["verdict"] = grade + ("; the open-loop position drifts" if "position drifts" in verdict else "")
    temperature = rec.channels.get("temperature")
    if temperature is not None and np.isfinite(temperature).any():  # NaN: the protocol's "no reading"
        row["temperature_mean"] = float(np.nanmean(temperature))
    return row


def _size(rec) -> dict[str, Any]:
    return {"samples": int(rec.t.size), "duration": float(rec.t[-1] - rec.t[0])}


def _held_out(path: str, settings: StepSettings, step: str):
    """The record's head and tail for a step that needs a validation set (compare, residual)."""
    from hilbench.analysis.errors import AnalysisError
    from hilbench.analysis.record import load_record
    from hilbench.analysis.record_split import split

    if settings.validation_fraction <= 0:
        raise AnalysisError(f"{step} scores models on the held-out tail: --validation-fraction must be > 0")
    rec = load_record(path, allow_incomplete=settings.allow_incomplete)
    head, tail = split(rec, settings.validation_fraction)
    return rec, head, tail


def compare_step(path: str, settings: StepSettings) -> dict[str, Any]:
    """``hilbench compare`` on one run: ``analysis.models.compare.analyse`` with every family of
    ``compare_families`` fitted on the head and scored on the tail; the row is the family with the lowest
    validation torque NRMSE."""
    from hilbench.analysis.errors import AnalysisError
    from hilbench.analysis.models.compare import CompareSettings, analyse

    rec, head, tail = _held_out(path, settings, "compare")
    result = analyse(head, tail, CompareSettings(families=settings.compare_families))
    scored = [r for r in result.rows if r.error is None and math.isfinite(r.validation["torque_nrmse"])]
    if not scored:
        raise AnalysisError("compare: no family could be fitted (" + "; ".join(
            f"{r.name}: {r.error}" for r in result.rows) + ")")
    best = min(scored, key=lambda r: r.validation["torque_nrmse"])
    return {"model": best.name, "train_torque_nrmse": best.train["torque_nrmse"],
            "validation_torque_nrmse": best.validation["torque_nrmse"],
            "validation_position_nrmse_segmented": best.validation["position_nrmse_segmented"], **_size(rec)}


def residual_step(path: str, settings: StepSettings) -> dict[str, Any]:
    """``hilbench residual`` on one run: ``analysis.residual.analyse`` from ``residual_start``, fitted on the head
    and judged on the tail; the row has the validation torque NRMSE of the start and of the final model and the
    loop's verdict."""
    from hilbench.analysis.residual import ResidualSettings, analyse

    rec, head, tail = _held_out(path, settings, "residual")
    loop = analyse(head, ResidualSettings(start=settings.residual_start), validation=[tail]).loop
    before, after = loop.error_before["validation"], loop.error_after["validation"]
    return {"model": ",".join([*loop.start, *loop.names_added]),
            "validation_torque_nrmse_start": before["torque_nrmse"],
            "validation_torque_nrmse": after["torque_nrmse"],
            "validation_position_nrmse": after.get("position_nrmse"),
            "verdict": loop.verdict, **_size(rec)}


def presliding_step(path: str, settings: StepSettings) -> dict[str, Any]:
    """``hilbench presliding`` on one displacement-driven run with the command's defaults (fraction 0.9, 48
    thresholds, the protocol's inertia, ``presliding_replicates`` bootstrap replicates): ``analysis.presliding
    .analyse``; the row has the quantities with their standard uncertainties, the relative rms error of the
    force simulated from the measured displacement and the warnings (e.g. the span of a long record analysed)."""
    from hilbench.analysis import presliding
    from hilbench.analysis.record import load_record

    rec = load_record(path, allow_incomplete=settings.allow_incomplete)
    res = presliding.analyse(rec, replicates=settings.presliding_replicates)
    q, e = res.quantities, res.uncertainties
    row: dict[str, Any] = {"validation_force_relative_error": res.fit.relative_rms,
                           "warnings": "; ".join(res.warnings), **_size(rec)}
    for name, column in (("breakaway", "presliding_breakaway"), ("initial_stiffness", "initial_stiffness"),
                         ("presliding_distance", "presliding_distance")):
        row[column], row[f"{column}_se"] = q[name], e[name]
    return row


def afrf_step(path: str, settings: StepSettings) -> dict[str, Any]:
    """``hilbench afrf RUN.h5`` on one stepped-sine run: ``analysis.afrf.analyse`` on the record its ``load``
    reads; the row summarises the grid (:data:`COLUMNS`)."""
    from hilbench.analysis import afrf

    rec = afrf.load(path, allow_incomplete=settings.allow_incomplete)
    res = afrf.analyse(rec)
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
            "warnings": "; ".join(res.warnings), **_size(rec)}


def skeleton_step(path: str, settings: StepSettings) -> dict[str, Any]:
    """``hilbench skeleton RUN.h5 [--mass skeleton_mass]`` on one chirp run: ``analysis.skeleton.analyse`` of the
    record alone (a campaign row is one run; composing several gains is the command's job)."""
    from hilbench.analysis import skeleton
    from hilbench.analysis.record import load_record

    rec = load_record(path, allow_incomplete=settings.allow_incomplete)
    res = skeleton.analyse([rec], skeleton.SkeletonSettings(mass=settings.skeleton_mass))
    a, k = np.asarray(res.curves.amplitude, float), np.asarray(res.curves.stiffness, float)
    ok = np.isfinite(a) & np.isfinite(k)
    if not ok.any():
        from hilbench.analysis.errors import AnalysisError

        raise AnalysisError(f"{path}: no amplitude bin has a skeleton point")
    a, k = a[ok], k[ok]
    return {"skeleton_bins": int(a.size), "skeleton_amplitude_min": float(a.min()),
            "skeleton_amplitude_max": float(a.max()), "skeleton_stiffness_low_amplitude": float(k[np.argmin(a)]),
            "skeleton_stiffness_high_amplitude": float(k[np.argmax(a)]), "warnings": "; ".join(res.warnings),
            **_size(rec)}


def _nanmax(a: np.ndarray) -> float:
    a = np.asarray(a, float)
    return float(np.nanmax(a)) if np.isfinite(a).any() else math.nan


STEPS: dict[str, Callable[[str, StepSettings], dict[str, Any]]] = {
    "identify": identify_step, "compare": compare_step, "residual": residual_step, "presliding": presliding_step,
    "afrf": afrf_step, "skeleton": skeleton_step}


def steps_for(protocol: str, wanted: tuple[str, ...]) -> list[str]:
    """The wanted steps a run of ``protocol`` supports."""
    return [s for s in wanted if protocol in PROTOCOLS_OF_STEP.get(s, ())]


def run_meta(path: str) -> dict[str, Any]:
    """The run file's own identity: run id, start time and operator (its root attributes alone)."""
    from hilbench.analysis.runfile.identity import run_identity

    return run_identity(path)
