"""The error vocabulary: one definition of every error figure and its name (docs/metrics.md, the glossary).

Every command, report, GUI table, campaign row and page names its figures with these words and shows them in
percent (:func:`percent`, :data:`UNIT`), so that the same run reads the same everywhere:

- **torque NRMSE** (%): ``100 * rms(L[tau] - L[tau_model]) / std(L[tau])`` over the filtered rows of the record,
  where ``L`` is the analysis' zero-phase low-pass (cutoff fs/20 by default) and ``tau_model`` the model's torque
  along the measured path (the equation error). On a linear axis the same figure is the **force NRMSE**.
- **position NRMSE** (%): ``100 * rms(x - x_sim) / std(x)``, the open-loop simulation from the measured torque
  over the whole record.
- **position NRMSE (segmented)** (%): the same with the simulation restarted from the measured state every
  ``segment`` s (1 s by default). Its computation needs the plant, so it lives in analysis
  (``hilbench.analysis.identification.output_error.segmented_simulation_error``); its definition and name live here.
- **relative error** (%): ``100 * ||e|| / ||y||``, reported beside the NRMSE where a published figure uses it
  (the EMPS benchmark).
- prefixed **train**, **validation** (a held-out span or run, never fitted) or **cross-validation** (blocked folds
  of the training run), by where the figure is computed.

Data files (JSON, Parquet) keep the dimensionless fraction under ``*_nrmse`` keys and ``*_rel_pct`` percentages
where their schemas always had them; every human-facing text shows percent.

The verdict bands grade a fit on these figures (``hilbench.bench.verdict.judge`` words the verdict).
"""

from __future__ import annotations

import math

import numpy as np

from hilbench.common.errors import InputError

__all__ = [
    "DRIFT_POSITION_PCT", "FAIR_TORQUE_PCT", "FORCE_NRMSE", "GOOD_TORQUE_PCT", "POSITION_NRMSE", "RELATIVE_ERROR",
    "RunningNrmse", "SEGMENTED_POSITION_NRMSE", "SEGMENT_S", "TORQUE_NRMSE", "UNIT", "grade", "label", "nrmse",
    "percent", "relative_error",
]

#: the names used in every text a person reads (docs/metrics.md, the glossary)
TORQUE_NRMSE = "torque NRMSE"
FORCE_NRMSE = "force NRMSE"
POSITION_NRMSE = "position NRMSE"
SEGMENTED_POSITION_NRMSE = "position NRMSE (segmented)"
RELATIVE_ERROR = "relative error"
#: the unit every text shows an error figure in
UNIT = "%"
#: the segmented position NRMSE restarts its simulation from the measured state every this many seconds
SEGMENT_S = 1.0

#: verdict bands on the torque NRMSE, %: at most GOOD is a good fit, at most FAIR a fair one, above it poor
GOOD_TORQUE_PCT = 10.0
FAIR_TORQUE_PCT = 30.0
#: a position NRMSE above this (%) means the open-loop simulation is worse than a constant at the mean position:
#: it drifts, and the segmented figure is the one to judge
DRIFT_POSITION_PCT = 100.0


def nrmse(y: np.ndarray, y_hat: np.ndarray) -> float:
    """Normalised RMS error ``rms(y - y_hat) / std(y)`` (a fraction; NMSE in % = 100*nrmse^2).

    A constant reference ``y`` (std 0) cannot normalise the error: :class:`InputError` in one line."""
    y = np.asarray(y, float)
    s = float(np.std(y))
    if s == 0:
        raise InputError("cannot normalise the error: the reference signal is constant")
    return float(np.sqrt(np.mean((y - np.asarray(y_hat, float)) ** 2)) / s)


class RunningNrmse:
    """:func:`nrmse` (and the relative error ``||e|| / ||y||``) over a signal read in blocks: running sums of the
    squared error, of y and of y shifted by its first value (so a large constant offset costs no precision)."""

    def __init__(self) -> None:
        self.n = 0
        self.e2 = self.y2 = self.s1 = self.s2 = 0.0
        self.ref: float | None = None

    def add(self, y: np.ndarray, e: np.ndarray) -> None:
        """One block: the reference ``y`` and the error ``e = y - y_hat`` (same shape)."""
        if y.size == 0:
            return
        if self.ref is None:
            self.ref = float(y[0])
        d = y - self.ref
        self.n += y.size
        self.e2 += float(e @ e)
        self.y2 += float(y @ y)
        self.s1 += float(np.sum(d))
        self.s2 += float(d @ d)

    def nrmse(self, where: str = "") -> float:
        """rms(e) / std(y) over every block; a constant reference is :class:`InputError` in one line (``where``
        ends it, e.g. " over the scored span")."""
        var = self.s2 / self.n - (self.s1 / self.n) ** 2 if self.n else 0.0
        if not var > 0:
            raise InputError(f"cannot normalise the error: the reference signal is constant{where}")
        return float(np.sqrt(self.e2 / self.n / var))

    def relative(self) -> float:
        """||e|| / ||y|| over every block (NaN when y is all zero)."""
        return float(np.sqrt(self.e2 / self.y2)) if self.y2 > 0 else math.nan


def relative_error(y: np.ndarray, e: np.ndarray) -> float | None:
    """``||e|| / ||y||`` (a fraction; the EMPS benchmark's metric in % is 100x this); None when ``y`` is all zero."""
    ny = float(np.linalg.norm(np.asarray(y, float)))
    return float(np.linalg.norm(np.asarray(e, float))) / ny if ny > 0 else None


def percent(fraction: float | None) -> float:
    """A dimensionless figure in percent (None -> NaN)."""
    return math.nan if fraction is None else 100.0 * float(fraction)


def is_fraction(key: str) -> bool:
    """Whether a figure's key (a summary's, a table column's) names an NRMSE, kept as a fraction in data files and
    shown in percent in every text: ``validation_torque_nrmse``, ``train_position_nrmse_segmented``..."""
    return "_nrmse" in key or key == "nrmse"


def label(where: str, quantity: str = TORQUE_NRMSE) -> str:
    """``validation torque NRMSE`` and the like: where the figure is computed, then what it is."""
    return f"{where} {quantity}"


def grade(torque_pct: float) -> str:
    """``good``, ``fair`` or ``poor`` for a torque NRMSE in % (the verdict bands)."""
    if torque_pct <= GOOD_TORQUE_PCT:
        return "good"
    return "fair" if torque_pct <= FAIR_TORQUE_PCT else "poor"
