"""Start the residual loop from an identified Maxwell-slip model (``hilbench identify``'s fit, or its model file)
instead of refitting the start terms, so the start model the loop reports is the model identify reports (issue #24).

The model's friction (its Maxwell-slip elements, Coulomb term and spring, with their identified k_i, Delta_i) enters
the loop as one fixed-shape column with a scale >= 0, as a start family does
(:class:`hilbench.analysis.residual.family_start.FamilyFriction`); J and b stay the loop's own linear terms. The
model's own figures, unrefitted, are scored as identify scores them (:func:`start_figures`, analysis.scoring) at
identify's cutoff, order and row thinning, on the runs the loop reads.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.residual.candidates import register
from hilbench.analysis.residual.family_start import FamilyFriction, _friction_only

if TYPE_CHECKING:
    from hilbench.analysis.models.friction_model import FrictionModel
    from hilbench.analysis.record import Record

NAME = "model"  # the term is ``family_model``


class ModelFriction(FamilyFriction):
    """An identified model's friction along the measured path, one column with a scale >= 0."""

    def __init__(self) -> None:
        super().__init__(NAME)
        self.physics = "the start model's friction (Maxwell-slip elements, Coulomb, spring; shape fixed, scale fitted)"
        self.replaces = ("coulomb", "maxwell_slip")


    def plant(self, fit, nl):
        """The model's elements, Coulomb term and spring, times the fitted scale (coefficient / static level)."""
        p, scale = nl["_plant"], float(fit.term_coef(self.name)[0]) / nl["_static"]
        return {"ms_stiffness": tuple(scale * k for k in p.ms_stiffness),
                "ms_slip": tuple(scale * w for w in p.ms_slip), "coulomb": scale * p.coulomb,
                "spring": scale * p.spring}


register(ModelFriction())


def model_start(model: FrictionModel) -> list:
    """Start entries for the residual loop: inertia, the model's friction column, viscous."""
    plant = _friction_only(model.plant_params())
    static = float(model.breakaway)
    if not static > 0:
        raise AnalysisError(f"the start model has no friction level ({static:g} at break-away); nothing to start from")
    ident = {"parameters": model.to_dict(), "std_errors": {}, "units": {}}
    return ["inertia", (f"family_{NAME}", {"_plant": plant, "_static": static, "_identified": ident}), "viscous"]


def start_figures(model: FrictionModel, records: dict[str, Record], cutoff: float, order: int,
                  decimation: int) -> dict:
    """The model's torque NRMSE on each record (name -> record), unrefitted, scored by the one scoring function
    (:mod:`hilbench.analysis.scoring`) at identify's cutoff, order and row thinning (``{name}_torque_nrmse``, a
    fraction): rms(L[tau] - L[tau_model]) / std(L[tau]), a held-out tail from the state the run before it left."""
    from hilbench.analysis.scoring import ScoreSettings, score_run, scored_run

    settings = ScoreSettings(cutoff=cutoff, order=order, decimation=decimation, simulate=False)
    return {f"{name}_torque_nrmse": score_run(model.plant_params(), scored_run(rec), settings).figures["torque_nrmse"]
            for name, rec in records.items()}


def document_settings(doc: dict, fs: float) -> tuple[float, int, int]:
    """(cutoff Hz, order, decimation) identify used for a model file's figures; at another rate than the file's
    training run, identify's defaults at ``fs`` (cutoff fs/20, order 4, thinning fs/(2.5 cutoff))."""
    figures, settings = doc.get("figures") or {}, doc.get("settings") or {}
    train = (doc.get("data") or {}).get("train") or {}
    rate = train.get("sample_rate_hz")
    if rate is not None and np.isclose(float(rate), fs) and "cutoff_hz" in figures and "decimation" in figures:
        return float(figures["cutoff_hz"]), int(settings.get("order", 4)), int(figures["decimation"])
    from hilbench.analysis.identification.maxwell_fit import LipSettings

    cutoff, decimation = LipSettings().resolved(fs)
    return cutoff, LipSettings().order, decimation
