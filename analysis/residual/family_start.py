"""Start the residual loop from any friction family of :mod:`analysis.models.families`.

The loop's design is linear in its parameters; a family whose friction has an internal state (Dahl, LuGre,
GMS, the continuous virgin-curve model) enters it as one fixed-shape column. The family is first identified on
the training run (``families.fit_family``: a linear start, then output-error refinement with the C engine), its
friction force F_fam[theta] along the measured path is computed by the C plant (``Plant.friction_path``, the
family's own state following the path), and the column L[F_fam] enters with a scale s >= 0 (s = 1 when the
identified family is right). Its viscous term and its load offset stay separate linear terms, so the loop can
add an offset or a drift as it would to any start.

| family | start terms |
|---|---|
| ``coulomb_viscous`` | inertia, coulomb, viscous |
| ``stribeck`` | inertia, coulomb, stribeck (v_s of the linear start's grid search), viscous |
| ``maxwell_slip`` | inertia, maxwell_slip, viscous |
| ``dahl``, ``lugre``, ``gms``, ``continuous`` | inertia, ``family_<name>`` (the column above), viscous |

A family that contains a Stribeck curve (stribeck, LuGre, GMS) is not offered the ``stribeck`` candidate, and a
stateful family is not offered ``maxwell_slip`` (each is part of the family); every other candidate is. The
friction parameters of a stateful family are refined once more on the loop's own criterion
(:func:`refine_on_equation_error`) before the column is built.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.regressors import zero_phase_lowpass
from hilbench.analysis.residual.candidates import Term, _units, register
from hilbench.analysis.residual.rundata import FAST_VELOCITY_FACTOR, RunData

STATEFUL = ("dahl", "lugre", "gms", "continuous")


class FamilyFriction(Term):
    """The friction force of an identified family along the measured path, one column with a scale >= 0."""

    candidate = False
    main = "scale"

    def __init__(self, family: str):
        self.family = family
        self.name = f"family_{family}"
        self.physics = f"{family} friction identified on the training run (shape fixed; scale fitted)"
        self.replaces = ("coulomb", "maxwell_slip") + (("stribeck",) if family in ("lugre", "gms") else ())

    def _force(self, run: RunData, nl: dict) -> np.ndarray:
        from hilbench.analysis.models.families import substeps_for
        from hilbench.firmware_sim.engine.plant import Plant

        plant = nl["_plant"]
        xf, v = _path(run)
        return Plant(plant, 1.0 / run.fs, substeps_for(plant, run.fs)).friction_path(xf, v)

    # the column is F_fam / F_static, so the coefficient is the model's static level (N*m or N)
    def _unit_force(self, run: RunData, nl: dict) -> np.ndarray:
        return run.cached((self.name, "raw", repr(nl["_plant"])), lambda: self._force(run, nl) / nl["_static"])

    def columns(self, run, nl, setting):
        return run.cached((self.name, repr(nl["_plant"])), lambda: run.filt(self._unit_force(run, nl))[:, None])

    def raw_force(self, run, nl, coef, setting):
        return self._unit_force(run, nl) * coef[0]

    def static_level(self, coef):
        return float(coef[0])

    def parameters(self, fit, nl, axis):
        c, se = fit.term_coef(self.name), fit.term_se(self.name)
        ident = nl["_identified"]
        params = {"scale": float(c[0]) / nl["_static"], "static_level": float(c[0]), "family": self.family,
                  "identified": ident["parameters"],
                  "units": {"scale": "1", "static_level": _units(axis)["torque"], **ident["units"]}}
        return params, {"scale": float(se[0]) / nl["_static"], "static_level": float(se[0]),
                        "identified": ident["std_errors"]}

    def plant(self, fit, nl):
        p = nl["_plant"]
        return {k: getattr(p, k) for k in ("lugre", "gms", "hysteresis") if getattr(p, k) is not None}


for _f in STATEFUL:
    register(FamilyFriction(_f))


LINEAR = ("inertia", "viscous", "offset")  # solved linearly in every evaluation (variable projection)


def _friction_only(plant):
    return replace(plant, viscous=0.0, viscous_neg=None, torque_offset=0.0)


def _path(run: RunData) -> tuple[np.ndarray, np.ndarray]:
    """The path the family's state follows: the position low-passed at the cutoff of ``velocity_fast`` (8x the
    regression cutoff), and its velocity. At the regression cutoff itself the smoothing spreads every reversal
    over a filter period and the presliding of a stateful family (a few encoder steps) is lost: on clean Dahl and
    LuGre records the torque error was 4.8 % and 4.6 % that way, 0.9 % and 0.8 % this way."""
    cutoff = min(FAST_VELOCITY_FACTOR * run.data.cutoff, 0.4 * run.fs)
    xf = zero_phase_lowpass(run.position, run.fs, cutoff, run.data.order)
    return xf, np.gradient(xf, 1.0 / run.fs)


def refine_on_equation_error(builder, params: dict, run: RunData, max_nfev: int = 40) -> tuple[dict, dict]:
    """Refine a family's friction parameters (log scale) on the loop's own criterion: the equation error
    L[tau] - J*L[theta''] - L[F_fam] - b*L[theta'] on the rows not at rest, with J and b solved linearly for
    each trial (variable projection). The output-error fit of ``families`` weighs position; the loop judges
    torque, and a family left at its position optimum shows a torque residual the loop would otherwise sell as
    a missing effect. Returns (parameters, standard errors of the refined ones)."""
    from scipy.optimize import least_squares

    from hilbench.analysis.models.families import substeps_for
    from hilbench.firmware_sim.engine.plant import Plant, PlantParameterError

    names = [n for n in builder.names if n not in LINEAR]
    xf, v = _path(run)
    keep = ~run.rest if run.rest is not None else np.ones(run.n_rows, bool)
    y = run.data.torque[keep]
    lin = np.column_stack([run.data.acceleration, run.data.velocity])[keep]
    bad = np.full(int(keep.sum()), 10.0 * float(np.std(y)))

    def unpack(vec):
        return {**params, **{n: float(np.exp(vec[i])) for i, n in enumerate(names)}}

    def residual(vec):
        try:
            plant = _friction_only(builder.plant(unpack(vec)))
            f = Plant(plant, 1.0 / run.fs, substeps_for(plant, run.fs)).friction_path(xf, v)
        except (PlantParameterError, FloatingPointError, AnalysisError):
            return bad
        yf = y - run.filt(f)[keep]  # the family's own level: no free scale (it would make the fit degenerate)
        coef, *_ = np.linalg.lstsq(lin, yf, rcond=None)
        r = yf - lin @ coef
        return r if np.all(np.isfinite(r)) else bad

    v0 = np.log([max(float(params[n]), 1e-300) for n in names])
    sol = least_squares(residual, v0, method="trf", diff_step=1e-3, max_nfev=max_nfev)
    out = unpack(sol.x)
    r = sol.fun
    s2 = float(r @ r) / max(1, r.size - sol.x.size - lin.shape[1])
    from hilbench.analysis.identification.regressors import effective_sample_count

    cov = np.linalg.pinv(sol.jac.T @ sol.jac) * s2 * max(1.0, r.size / effective_sample_count(r))
    se = {n: float(np.sqrt(max(cov[i, i], 0.0)) * out[n]) for i, n in enumerate(names)}
    return out, se


def family_start(family: str, train: list[RunData], output_error: bool = True) -> list:
    """Start entries (term name, or (name, settings)) for the residual loop from ``family``, identified on the
    first training run. Raises AnalysisError for an unknown family.

    ``output_error=False`` skips the output-error fit (``families.fit_family``): the family starts from the
    Maxwell-slip fit's gross-sliding limit (F_c = sum W_i, sigma0 = sum k_i, the same virgin stiffness) and is refined
    on the loop's equation error only. The loop's presliding check uses it: the output-error fit simulates the whole
    record per evaluation and took 4-5 minutes on some 10 s records (a stiff sigma0 needing many substeps), the
    equation-error refinement follows the measured path and takes about a second."""
    from hilbench.analysis.models import families as fam

    if family not in fam.FAMILIES:
        raise AnalysisError(f"start family must be one of {', '.join(fam.FAMILIES)}, got {family!r}")
    if family == "coulomb_viscous":
        return ["inertia", "coulomb", "viscous"]
    if family == "maxwell_slip":
        return ["inertia", "maxwell_slip", "viscous"]
    run = train[0]
    frun = fam.RunData.from_arrays(run.name, run.axis, run.fs, run.position, run.torque, run.timing)
    if family == "stribeck":
        return ["inertia", "coulomb", ("stribeck", {"v_s": float(fam.stribeck_start(frun)["stribeck_velocity"])}),
                "viscous"]
    ms_fit = fam.maxwell_slip_start(frun, run.timing, run.position, run.torque)
    builder = fam._build_families(ms_fit.model)[family]
    if output_error:
        fitted = fam.fit_family(family, frun, timing=run.timing, position=run.position, torque=run.torque,
                                ms_fit=ms_fit)
        p0, se0, units = dict(fitted.params), fitted.std_errors, fitted.units
    else:
        base = fam._starts(frun, ms_fit.model)
        p0 = dict(fam._sliding_starts(frun, ms_fit.model, base).get(family, base[family]))
        se0 = {}
        units = {n: fam._unit(run.axis, key) for n, key in zip(builder.names, builder.unit_keys, strict=True)}
    p, se = refine_on_equation_error(builder, p0, run)
    # the column is the family's friction alone: its viscous term and offset are the loop's own terms
    plant = _friction_only(builder.plant(p))
    static = float(p["coulomb"] + p.get("static_excess", 0.0)) if "coulomb" in p else float(p["h"])
    if not static > 0:
        raise AnalysisError(f"the identified {family} model has no friction level ({static:g}); nothing to start from")
    ident = {"parameters": p, "std_errors": {**se0, **se}, "units": units, "output_error_start": p0}
    return ["inertia", (f"family_{family}", {"_plant": plant, "_static": static, "_identified": ident}), "viscous"]
