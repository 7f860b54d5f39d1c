"""Friction identification on plain arrays: check the input, fit, evaluate, validate.

    J*theta'' + sum_i k_i*S_Delta_i[theta] + b*theta' (+ Fc*sign(theta') + c0) = tau

Methods:
- ``lip`` (default): linear in parameters, NNLS on filtered stop-operator regressors (maxwell_fit);
- ``oe``: ``lip`` followed by output-error refinement on the simulated position (output_error);
- ``paper``: differential evolution then Nelder-Mead on the simulation error, N elements (paper_baseline).

Figures, scored by the one scoring function (analysis.scoring, rms(error)/std(measured)): torque NRMSE of the
equation error on the filtered rows, position NRMSE of the open-loop simulation over the whole record, and
position NRMSE of the simulation restarted every ``segment`` seconds from the measured state, on the training run
and on an optional validation run (a held-out tail scored from the friction state the run before it left).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.maxwell_fit import LipFit, LipSettings, fit_lip
from hilbench.analysis.identification.output_error import (
    refine_output_error,
)
from hilbench.analysis.models.friction_model import FrictionModel, check_axis

METHODS = ("lip", "oe", "paper")


@dataclass
class RunArrays:
    """One run as arrays: t (s, uniform), torque (N*m or N), position (rad or m), its axis and name."""

    t: np.ndarray
    torque: np.ndarray | None
    position: np.ndarray
    axis: str = "rotary"
    name: str = "run"
    lead: tuple[np.ndarray, np.ndarray] | None = None  # (position, torque) of the run before a held-out tail

    @property
    def fs(self) -> float:
        """Sampling rate from the whole record, (n - 1)/(t[-1] - t[0]), Hz."""
        t = np.asarray(self.t, float)
        return float((t.size - 1) / (t[-1] - t[0]))


def check_run(run: RunArrays, min_samples: int = 200) -> RunArrays:
    """Validate a run; raise :class:`AnalysisError` with the reason in one line."""
    check_axis(run.axis)
    if run.torque is None:
        raise AnalysisError(f"{run.name}: no torque channel; identification needs the motor torque or force")
    t = np.asarray(run.t, float).ravel()
    tau = np.asarray(run.torque, float).ravel()
    x = np.asarray(run.position, float).ravel()
    if not (t.size == tau.size == x.size):
        raise AnalysisError(
            f"{run.name}: t, torque and position lengths differ ({t.size}, {tau.size}, {x.size})"
        )
    if t.size < min_samples:
        raise AnalysisError(
            f"{run.name}: run too short to identify ({t.size} samples, need >= {min_samples})"
        )
    for name, arr in (("t", t), ("torque", tau), ("position", x)):
        bad = ~np.isfinite(arr)
        if bad.any():
            raise AnalysisError(
                f"{run.name}: {name} contains NaN or inf (first at sample {int(np.argmax(bad))})"
            )
    dt = np.diff(t)
    period = (t[-1] - t[0]) / (t.size - 1)
    # uniform to 1 % of the period: recorders that store time in float32 (EMPS: 4e-5 of dt) pass
    off_grid = np.abs(t - (t[0] + period * np.arange(t.size)))
    if not (dt.min() > 0 and off_grid.max() <= 0.01 * period):
        raise AnalysisError(
            f"{run.name}: time stamps are not uniformly spaced (dt from {dt.min():.3g} to "
            f"{dt.max():.3g} s, up to {off_grid.max():.3g} s off a uniform grid); resample first"
        )
    if np.ptp(x) == 0:
        raise AnalysisError(f"{run.name}: the position never changes; nothing is identifiable (no motion)")
    if np.ptp(tau) == 0:
        raise AnalysisError(f"{run.name}: the torque is constant; J and the friction are unidentifiable")
    return RunArrays(t, tau, x, run.axis, run.name, run.lead)


@dataclass
class Identification:
    """Model, method, settings, figures and the arrays the plots need."""

    model: FrictionModel
    method: str
    settings: dict
    figures: dict
    wall_time: float
    lip: LipFit | None = None
    curves: dict = field(default_factory=dict)  # name -> arrays for the plots


#: scorer figures identify's documents do not carry (the model file's figures are fixed by docs/model-file.md)
_NOT_REPORTED = ("position_rms_segmented", "torque_rel_pct")


def _score_settings(lip: LipFit, segment: float, force_mode: bool):
    """The scoring of identify's figures: the fit's cutoff, order and row thinning (the scorer's defaults unless
    the user set them), restarts every ``segment`` s, force figures for a force-against-displacement fit."""
    from hilbench.analysis.scoring import ScoreSettings

    return ScoreSettings(cutoff=lip.cutoff, order=lip.settings.order, decimation=lip.decimation, segment=segment,
                         force=force_mode)


def _figures(
    model: FrictionModel, run: RunArrays, lip: LipFit, timing: str, prefix: str, curves: dict, segment: float,
    force_mode: bool = False,
) -> dict:
    from hilbench.analysis.scoring import ScoredRun, score_run

    lead = run.lead
    scored = ScoredRun(run.position, run.torque, run.fs, timing) if lead is None else ScoredRun(
        np.concatenate([lead[0], run.position]), np.concatenate([lead[1], run.torque]), run.fs, timing,
        int(np.asarray(lead[0]).size))
    sc = score_run(model.plant_params(), scored, _score_settings(lip, segment, force_mode), keep=True)
    rows = sc.rows - scored.start  # rows of the span, indices into this run's arrays
    curves[prefix] = {"t": run.t, "position": run.position, "torque_filtered": sc.measured,
                      "torque_predicted": sc.predicted, "t_rows": run.t[rows]}
    if lead is not None:  # the span's rows come from filtering the run before it too: the plots filter the same
        curves[prefix]["lead_position"] = np.asarray(lead[0], float)
    if force_mode:  # the model maps the measured displacement to the force: no integration, nothing drifts
        curves[prefix]["position_rows"] = run.position[rows]
    else:
        curves[prefix]["position_sim"] = sc.position_sim
    return sc.prefixed(prefix, _NOT_REPORTED)


def _force_mode(record: str, s: LipSettings, method: str) -> bool:
    """Whether the fit maps the measured displacement to the force (a displacement-driven record or J = 0); only
    ``lip`` fits that way (the other methods refine a simulated position)."""
    force_mode = record == "displacement-driven" or s.fixed_inertia == 0
    if force_mode and method != "lip":
        raise AnalysisError(f"method {method!r} refines a simulated position; a force-against-displacement "
                            "fit (displacement-driven record or inertia 0) uses method 'lip'")
    return force_mode


def identify(
    run: RunArrays,
    *,
    method: str = "lip",
    validate: RunArrays | None = None,
    settings: LipSettings | None = None,
    oe_max_nfev: int = 100,
    paper_options: dict | None = None,
    segment: float = 1.0,
    record: str = "torque-driven",
) -> Identification:
    """Identify the friction model of ``run`` (see the module docstring); optionally validate.

    ``segment`` (s): restart interval of the segmented simulation figure (output_error.segmented_simulation_error).
    ``record``: ``torque-driven`` or ``displacement-driven`` (force measured against an imposed displacement;
    give ``settings.fixed_inertia``, usually 0). A displacement-driven record, or a fixed inertia of 0, gets
    force figures (``*_force_nrmse``, ``*_force_rel_pct``: the force the model computes from the measured
    displacement against the measured force, filtered rows) instead of position simulations.
    """
    if method not in METHODS:
        raise AnalysisError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    run = check_run(run)
    if validate is not None:
        validate = check_run(validate)
        if validate.axis != run.axis:
            raise AnalysisError(f"validation run axis {validate.axis!r} differs from {run.axis!r}")
    s = settings or LipSettings()
    force_mode = _force_mode(record, s, method)
    t0 = time.perf_counter()
    extra: dict = {}
    lip = fit_lip(run.position, run.torque, run.fs, run.axis, s)
    model = lip.model
    if method == "oe":
        model, extra = refine_output_error(
            model, run.position, run.torque, run.fs, timing=s.timing, max_nfev=oe_max_nfev
        )
    elif method == "paper":
        from hilbench.analysis.identification.paper_baseline import fit_paper

        model, extra = fit_paper(
            run.position, run.torque, run.fs, run.axis, timing=s.timing, **(paper_options or {})
        )
    wall = time.perf_counter() - t0
    curves: dict = {}
    figures = {
        "wall_time_s": wall,
        "cutoff_hz": lip.cutoff,
        "decimation": lip.decimation,
        "n_eff": lip.n_eff,
        "condition_number": lip.condition_number,
        **extra,
    }
    figures.update(_figures(model, run, lip, s.timing, "train", curves, segment, force_mode))
    if validate is not None:
        figures.update(_figures(model, validate, lip, s.timing, "validation", curves, segment, force_mode))
    settings_dict = {
        "method": method,
        **s.to_dict(),
        "segment_s": float(segment),
        "record": record,
        "candidate_deltas": lip.candidate_deltas.tolist(),
    }
    if method == "paper":
        settings_dict["paper_options"] = dict(paper_options or {})
    return Identification(model, method, settings_dict, figures, wall, lip, curves)


def identify_chunks(
    source,
    fs: float,
    *,
    axis: str = "rotary",
    validate=None,
    settings: LipSettings | None = None,
    segment: float = 1.0,
    record: str = "torque-driven",
    method: str = "lip",
    oe_max_iterations: int = 20,
    validate_samples: int | None = None,
) -> Identification:
    """:func:`identify` with the ``lip`` or ``oe`` method on records read chunk by chunk, in memory bounded by
    the block size (docs/long-runs.md; ``oe``: output_error.refine_output_error_chunks). ``validate_samples``:
    the validation run's sample count when known (else one more pass counts it). ``source`` and
    ``validate`` are chunk sources (``chunked``: callables returning a fresh iterator of ``(position, torque)``
    pairs, in order) sampled uniformly at ``fs`` Hz; the caller checks the time stamps. The figures are
    :func:`identify`'s; no curves are kept (``curves`` is empty)."""
    from hilbench.analysis.identification.chunked import scan
    from hilbench.analysis.identification.maxwell_fit import fit_lip_chunks, grid_from_scan
    from hilbench.analysis.identification.output_error import refine_output_error_chunks
    from hilbench.analysis.scoring import score_chunks

    check_axis(axis)
    if method not in ("lip", "oe"):
        raise AnalysisError(f"method must be lip or oe for a record read chunk by chunk, got {method!r}")
    s = settings or LipSettings()
    force_mode = _force_mode(record, s, method)
    t0 = time.perf_counter()
    sc = scan(source)
    if sc.n < 200:
        raise AnalysisError(f"run too short to identify ({sc.n} samples, need >= 200)")
    if sc.position_range == 0:
        raise AnalysisError("the position never changes; nothing is identifiable (no motion)")
    if sc.torque_range == 0:
        raise AnalysisError("the torque is constant; J and the friction are unidentifiable")
    grid = grid_from_scan(sc, s.n_thresholds, s.delta_range) if s.n_thresholds > 0 else np.empty(0)
    lip = fit_lip_chunks(source, fs, axis, s, grid=grid, n_samples=sc.n)
    model = lip.model
    extra: dict = {}
    if method == "oe":
        model, extra = refine_output_error_chunks(model, source, fs, timing=s.timing,
                                                  max_iterations=oe_max_iterations)
    wall = time.perf_counter() - t0
    figures = {"wall_time_s": wall, "cutoff_hz": lip.cutoff, "decimation": lip.decimation, "n_eff": lip.n_eff,
               "condition_number": lip.condition_number, **extra}
    scoring = _score_settings(lip, segment, force_mode)
    params = model.plant_params()
    train = score_chunks(params, source, fs, timing=s.timing, settings=scoring, n=sc.n)
    figures.update(train.prefixed("train", _NOT_REPORTED))
    if validate is not None:
        val = score_chunks(params, validate, fs, timing=s.timing, settings=scoring, n=validate_samples)
        figures.update(val.prefixed("validation", _NOT_REPORTED))
    settings_dict = {"method": method, **s.to_dict(), "segment_s": float(segment), "record": record,
                     "candidate_deltas": lip.candidate_deltas.tolist()}
    return Identification(model, method, settings_dict, figures, wall, lip, {})
