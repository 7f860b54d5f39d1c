"""Published benchmark metrics next to the loop's own figures.

Where a data set has a published metric, the report also gives the loop's models (before and after) in
that metric, computed the published way. EMPS (Janot, Gautier, Brunot 2019): the relative force error
100*|F - F_hat|/|F| on the IDIM-LS observation (4th-order zero-phase Butterworth at 100 Hz, decimation
10), published 4.08 % (DATA_EMPS) and 5.98 % (DATA_EMPS_PULSES, parameters fixed). The loop's parameters
are fitted with its own filter; only the evaluation uses the published filtering.
"""

from __future__ import annotations

from hilbench.analysis.reproductions.emps import PUBLISHED as EMPS_PUBLISHED
from hilbench.analysis.residual.design import Fit, predict
from hilbench.analysis.residual.rundata import RunData, prepare_run
from hilbench.common.metrics import percent, relative_error

METRICS = {
    "import:emps": {
        "metric": "relative force error 100*|F - F_hat|/|F|, %, IDIM-LS filtering (4th-order zero-phase "
                  "Butterworth 100 Hz, decimation 10)",
        "cutoff_hz": 100.0,
        "decimation": 10,
        "published": {"train": EMPS_PUBLISHED["relative_error_train"],
                      "validation": EMPS_PUBLISHED["relative_error_test"]},
        "reference": "EMPS IDIM-LS reference model (Janot, Gautier, Brunot 2019); train DATA_EMPS, "
                     "validation DATA_EMPS_PULSES",
    },
}


def _relative_error(fit: Fit, runs: list[RunData], cutoff: float, decimation: int) -> float:
    again = [prepare_run(r.position, r.torque, r.fs, axis=r.axis, name=r.name, cutoff=cutoff,
                         decimation=decimation, timing=r.timing, max_rate=None) for r in runs]
    y, e = predict(fit, again)
    return percent(relative_error(y, e))


def published_metric(source: str, fit_before: Fit, fit_after: Fit, train: list[RunData],
                     validation: list[RunData] | None) -> dict | None:
    """The published metric of the data set ``source`` (a run file's ``source``, e.g. ``import:emps``) for
    the models before and after the loop, or None when the data set has none."""
    spec = METRICS.get(source)
    if spec is None:
        return None
    out = {k: spec[k] for k in ("metric", "published", "reference")}
    for label, fit in (("before", fit_before), ("after", fit_after)):
        out[label] = {"train": _relative_error(fit, train, spec["cutoff_hz"], spec["decimation"]),
                      "validation": (_relative_error(fit, validation, spec["cutoff_hz"], spec["decimation"])
                                     if validation else None)}
    return out
