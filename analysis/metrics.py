"""The error vocabulary: one definition of every figure an analysis reports (docs/metrics.md).

Every command, report, GUI table and campaign row names its figures with these words and shows them in the unit
given here, so that the same run reads the same everywhere:

- **torque NRMSE** (%): ``100 * rms(L[tau] - L[tau_model]) / std(L[tau])`` over the filtered rows of the record,
  where ``L`` is the analysis' zero-phase low-pass (cutoff fs/20 by default) and ``tau_model`` the model's torque
  along the measured path (the equation error). On a linear axis the same figure is the force NRMSE.
- **position NRMSE** (%): ``100 * rms(x - x_sim) / std(x)``, the open-loop simulation from the measured torque over
  the whole record; **segmented** when the simulation restarts from the measured state every ``segment`` s.
- **relative error** (%): ``100 * ||e|| / ||y||``, reported beside the NRMSE where a published figure uses it.
- prefixed **train**, **validation** (a held-out run, never fitted) or **cross-validation** (blocked folds of the
  training run), by where the figure is computed.

JSON documents keep the dimensionless fraction under ``*_nrmse`` keys (as their schemas have always done) and the
percentage under ``*_pct`` keys where they give one; every human-facing text shows percent.
"""

from __future__ import annotations

import math

# the one definition of the NRMSE, rms(y - y_hat)/std(y) (a constant reference is refused in one line)
from hilbench.analysis.identification.maxwell_fit import nrmse

__all__ = ["POSITION_NRMSE", "TORQUE_NRMSE", "UNIT", "label", "nrmse", "percent"]
#: the names used in every text a person reads
TORQUE_NRMSE = "torque NRMSE"
POSITION_NRMSE = "position NRMSE"
UNIT = "%"


def percent(fraction: float | None) -> float:
    """A dimensionless figure in percent (None -> NaN)."""
    return math.nan if fraction is None else 100.0 * float(fraction)


def label(where: str, quantity: str = TORQUE_NRMSE) -> str:
    """``validation torque NRMSE`` and the like: where the figure is computed, then what it is."""
    return f"{where} {quantity}"
