"""A plain judgement of a fit, printed under every identify and residual summary.

The metric is the one both commands report: torque NRMSE = rms(measured - model) / std(measured), in %, on the
validation data when there is some (else on the training data), and the open-loop position NRMSE (same
definition on the simulated position). Bands (``hilbench.common.metrics``; docs/cli.md, "Judged results"):

- torque NRMSE <= 10 %: good; <= 30 %: fair; above: poor.
- position NRMSE > 100 % means the open-loop simulation is worse than a constant at the mean position: it
  drifts. Judge the segmented error then (restarted every second from the measured state).
"""

from __future__ import annotations

from hilbench.common.metrics import DRIFT_POSITION_PCT, POSITION_NRMSE, grade, label


def judge(torque_pct: float | None, position_pct: float | None = None, segmented_pct: float | None = None,
          where: str = "validation", residual_hint: bool = True) -> str:
    """One line: ``verdict: <good|fair|poor> ...; <what to try>``. Percentages may be ``None`` (not computed)."""
    if torque_pct is None or torque_pct != torque_pct:
        return ("verdict: no torque error could be computed (the model could not be evaluated): check the run's "
                "channels with `hilbench show`")
    grade_ = grade(torque_pct)
    line = f"verdict: {grade_} torque fit ({label(where)} {torque_pct:.3g} %)"
    drift = position_pct is not None and position_pct > DRIFT_POSITION_PCT
    if drift:
        seg = f", segmented {segmented_pct:.3g} %" if segmented_pct is not None else ""
        line += f"; the open-loop position drifts ({POSITION_NRMSE} {position_pct:.3g} %{seg})"
    if grade_ == "poor":
        line += ("; try: check the units and torque channel (hilbench show; --torque-channel), the torque "
                 "timing (--torque-timing), a Coulomb or spring term (--coulomb, --spring), a longer or richer run")
    elif grade_ == "fair" or drift:
        line += ("; try: `hilbench residual` to find the effect the model lacks" if residual_hint else
                 "; try: more candidate effects (--candidates) or a richer run")
    return line
