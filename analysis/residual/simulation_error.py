"""Simulation error of a fitted residual-loop model in position and velocity, with the one C engine.

The model (every term's plant parameters, ``Term.plant``) is simulated by ``firmware_sim.engine.plant`` under
the run's measured torque (torque_constant 1: the input is the torque). A friction system integrates
every torque error into a drifting position, so a whole-run open-loop simulation of a closed-loop or
long run says little. The run is therefore cut into windows of ``window`` s; each window starts from
the measured position and velocity, and the Maxwell-slip deflections of the stop operators along the
measured path (the elements' state is a function of the path), and is simulated open loop:

    position_nrmse = rms(theta_sim - theta_meas) / std(theta_meas),
    velocity_nrmse = rms(omega_sim - v_meas) / std(v_meas)

over all windows, v_meas being the lightly filtered velocity of the run.
"""

from __future__ import annotations

import numpy as np

from hilbench.analysis.identification.output_error import path_deflections
from hilbench.analysis.identification.regressors import held_torque
from hilbench.analysis.residual.design import Fit
from hilbench.analysis.residual.rundata import RunData

MAX_SUBSTEPS = 64


def plant_params(fit: Fit, inertia: float = 0.0):
    """:class:`firmware_sim.engine.plant.PlantParams` of a fitted model (torque_constant 1); ``inertia`` is J when
    the model has no inertia term (a known J, 0 for a displacement-driven record)."""
    from hilbench.firmware_sim.engine.plant import PlantParams

    fields: dict = {}
    coulomb_others = 0.0  # Coulomb levels of the terms that set no direction-dependent level (both directions)
    for term, nl in fit.model:
        nl = {**nl}
        changes = term.plant(fit, nl)
        if "coulomb_neg" not in changes:
            coulomb_others += changes.get("coulomb", 0.0)
        for key, value in changes.items():
            if key in ("torque_offset", "torque_drift", "coulomb") and key in fields:
                fields[key] += value
            else:
                fields[key] = value
    if "coulomb_neg" in fields:
        # a direction-dependent level adds to the other terms' Coulomb level in both directions; the sliding
        # levels of asymmetric_friction are increments that may be negative, the plant's levels are not
        fields["coulomb_neg"] = max(fields["coulomb_neg"] + coulomb_others, 0.0)
        fields["coulomb"] = max(fields["coulomb"], 0.0)
    excess = fields.pop("stribeck_excess", None)
    if excess is not None and excess > 0:
        fields["static"] = fields.get("coulomb", 0.0) + excess
    elif excess is not None:
        fields.pop("stribeck_velocity", None)
    if "coulomb_neg" in fields and fields.get("static") is not None:
        fields["static"] = max(fields["static"], fields["coulomb_neg"])
    fields.setdefault("inertia", float(inertia))
    return PlantParams(torque_constant=1.0, **fields)


def simulation_error(fit: Fit, run: RunData, window: float = 1.0) -> dict:
    """Windowed simulation error {position_nrmse, velocity_nrmse} of ``fit`` on ``run`` (None if the model
    cannot be simulated; then ``simulation_note`` says why)."""
    from hilbench.firmware_sim.engine.plant import Plant, PlantParameterError, stiffest_eigenvalue

    try:
        params = plant_params(fit)
        dt = 1.0 / run.fs
        lam = stiffest_eigenvalue(params)
        substeps = int(np.clip(np.ceil(lam * dt / 2.0), 1, MAX_SUBSTEPS))
        u = held_torque(run.torque, run.timing)
        n = u.size
        w = max(2, int(round(window * run.fs)))
        theta = np.empty(n)
        omega = np.empty(n)
        offset0 = params.torque_offset
        starts = np.arange(0, n, w)
        deflections = None
        if params.n_elements:
            deflections = path_deflections(run.position, params.ms_delta, starts)
        for j, k0 in enumerate(starts):
            k1 = min(n, k0 + w)
            p = params.replace(torque_offset=offset0 + params.torque_drift * run.time[k0])
            plant = Plant(p, dt, substeps, theta0=float(run.position[k0]), omega0=float(run.velocity_fast[k0]))
            if deflections is not None:
                plant.set_deflections(deflections[j])
            out = plant.run(u[k0:k1])
            theta[k0:k1], omega[k0:k1] = out.theta, out.omega
    except (PlantParameterError, FloatingPointError) as exc:
        return {"position_nrmse": None, "velocity_nrmse": None, "simulation_note": str(exc)}
    x, v = run.position, run.velocity_fast
    return {"position_nrmse": float(np.sqrt(np.mean((theta - x) ** 2)) / np.std(x)),
            "velocity_nrmse": float(np.sqrt(np.mean((omega - v) ** 2)) / np.std(v))}
