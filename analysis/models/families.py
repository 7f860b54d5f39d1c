"""Friction model families, identified from one run and evaluated on another with the C engine.

Every family is the same equation of motion with a different friction law F:

    J*theta'' + F(theta, theta', state) + c0 = tau

| family | F | parameters |
|---|---|---|
| ``coulomb_viscous`` | Fc*sgn(v) + b*v | J, Fc, b, c0 |
| ``stribeck`` | (Fc + (Fs - Fc)*exp(-(v/vs)^2))*sgn(v) + b*v | J, Fc, Fs, vs, b, c0 |
| ``dahl`` | sigma0*z, dz/dt = v - sigma0*abs(v)*z/Fc; + b*v | J, sigma0, Fc, b, c0 |
| ``lugre`` | LuGre with a Stribeck curve (exponent 2), sigma2 = b | J, sigma0, sigma1, Fc, Fs, vs, b, c0 |
| ``maxwell_slip`` | sum k_i*S_Delta_i[theta] + b*v (``hilbench identify``'s NNLS fit and terms) | J, k_i, Delta_i, b |
| ``gms`` | generalized Maxwell-slip on the Maxwell-slip fit's k_i, alpha_i | J, kappa, Fc, Fs, vs, C, b, c0 |
| ``continuous`` | virgin-curve hysteresis h, d (Masing, wiping-out) + b*v | J, h, d, b, c0 |

(docs/plant.md gives each law; docs/compare.md the procedure.) The identification is two steps. First comes a
linear-in-parameters start on the filtered regressors of ``analysis.identification``:

- Coulomb+viscous: least squares on [theta'', theta', sgn, 1];
- Stribeck: the same plus the column sgn(v)*exp(-(v/vs)^2), for the vs of a grid with the least residual;
- Maxwell-slip: the NNLS fit.

Dahl and LuGre take their static part from these fits and sigma0 from the Maxwell-slip fit's initial
stiffness sum(k_i). The continuous model takes h = sum(W_i) and d = 2h/sum(k_i), which gives the same initial
slope. Second comes output-error refinement: ``scipy.optimize.least_squares`` on the segmented simulation error
of the training run, computed by the C plant. The Maxwell-slip row keeps its NNLS fit. Standard errors are
sigma^2 (J^T J)^-1 at the optimum, inflated by n/n_eff for coloured residuals.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.maxwell_fit import LipSettings, fit_lip
from hilbench.analysis.identification.regressors import (
    FilteredData,
    effective_sample_count,
    filtered_data,
    held_torque,
    triangle_average,
    zero_phase_lowpass,
)
from hilbench.analysis.models.friction_model import check_axis
from hilbench.common.units import AXIS_UNITS as AXES
from hilbench.firmware_sim.engine.plant import (
    GMS,
    RK4_STABLE_RADIUS,
    Hysteresis,
    LuGre,
    Plant,
    PlantParameterError,
    PlantParams,
    stiffest_eigenvalue,
)

FAMILIES = ("coulomb_viscous", "stribeck", "dahl", "lugre", "maxwell_slip", "gms", "continuous")
#: Reversal points of the continuous model's stack in every fit (docs/plant.md: bounded stack).
HYSTERESIS_STACK = 64
#: RK4 sub-steps above this mean a parameter vector the search should not pursue.
MAX_SUBSTEPS = 2000


@dataclass
class RunData:
    """One run as the families see it: the raw position x and the held torque u, both shape (n,);
    the low-passed position xf and its velocity v (zero-phase fs/20, the measured path the friction state
    follows); and the filtered regression rows."""

    name: str
    axis: str
    fs: float
    x: np.ndarray   # rad or m
    u: np.ndarray   # N*m or N, held over [t_k, t_k+1)
    xf: np.ndarray  # rad or m
    v: np.ndarray   # rad/s or m/s
    data: FilteredData

    @classmethod
    def from_arrays(cls, name: str, axis: str, fs: float, position: np.ndarray, torque: np.ndarray,
                    timing: str = "hold_next") -> RunData:
        check_axis(axis)
        x = np.asarray(position, float)
        tau = np.asarray(torque, float)
        if x.shape != tau.shape or x.ndim != 1 or x.size < 200:
            raise AnalysisError(f"{name}: position and torque must be 1-D, equal length >= 200")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(tau))):
            raise AnalysisError(f"{name}: position or torque contains NaN or inf")
        if np.ptp(x) == 0:
            raise AnalysisError(f"{name}: the position never changes; nothing is identifiable (no motion)")
        cutoff = fs / 20.0
        xf = zero_phase_lowpass(x, fs, cutoff)
        data = filtered_data(x, tau, fs, cutoff, decimation=max(1, int(fs / (2.5 * cutoff))), timing=timing)
        return cls(name, axis, float(fs), x, held_torque(tau, timing), xf, np.gradient(xf, 1.0 / fs), data)

    def filtered(self, signal: np.ndarray) -> np.ndarray:
        """L[signal], triangle-averaged at the regression rows (as every regressor column)."""
        return triangle_average(zero_phase_lowpass(signal, self.fs, self.data.cutoff, self.data.order),
                                self.data.rows)


@dataclass
class FamilyFit:
    """An identified family: parameters (SI, per axis) with standard errors, the plant, and the fit's cost."""

    family: str
    axis: str
    params: dict[str, float | list[float]]
    std_errors: dict[str, float | list[float] | None]
    units: dict[str, str]
    plant: PlantParams
    n_parameters: int
    fit_time_s: float
    start: dict[str, float | list[float]] = field(default_factory=dict)
    notes: str = ""

    def to_dict(self) -> dict:
        return {"family": self.family, "axis": self.axis, "parameters": self.params, "std_errors": self.std_errors,
                "units": self.units, "n_parameters": self.n_parameters, "fit_time_s": self.fit_time_s,
                "start": self.start, "notes": self.notes}


# ---- evaluation on any run ----

def substeps_for(params: PlantParams, fs: float) -> int:
    """RK4 sub-steps keeping |lambda|*h at 80 % of the engine's stability radius."""
    lam = stiffest_eigenvalue(params)
    sub = max(1, math.ceil(lam / fs / (0.8 * RK4_STABLE_RADIUS)))
    if sub > MAX_SUBSTEPS:
        raise AnalysisError(f"model too stiff to simulate at {fs:g} Hz ({lam:.3g} 1/s needs {sub} sub-steps)")
    return sub


def path_plant(params: PlantParams, fs: float) -> Plant:
    """A plant for ``Plant.friction_path`` only. An imposed motion is not integrated (every friction state is
    advanced by its exact update over each sample's displacement), so no sub-step count limits it; the plant
    is built with the count its constructor's stability check asks for, which ``friction_path`` never uses."""
    lam = stiffest_eigenvalue(params)
    return Plant(params, 1.0 / fs, max(1, math.ceil(lam / fs / RK4_STABLE_RADIUS) + 1))


def predicted_torque(params: PlantParams, run: RunData) -> np.ndarray:
    """Equation-error prediction J*L[theta''] + L[F along the measured path] + c0 at the regression rows.

    The friction state follows the measured position ``x`` itself (the velocity-driven states take ``v``): along the
    low-passed ``xf`` the presliding loops, narrower than the filter's smoothing, were wiped out, and a Maxwell-slip
    model identified at 0.7 % torque NRMSE read 16 % here (hilbench identify and compare disagreed on one model)."""
    friction = path_plant(params, run.fs).friction_path(run.x, run.v)
    return params.inertia * run.data.acceleration + run.filtered(friction) - params.torque_offset


def segmented_position(params: PlantParams, run: RunData, segment: float = 1.0) -> np.ndarray:
    """Simulated position (rad or m), shape (n,), restarted every ``segment`` s from the measured state.

    Each segment starts at the low-passed measured position and velocity. Its friction state comes from
    ``Plant.friction_path`` along the measured path since the start of the record. Every family is started
    alike: the Maxwell-slip deflections, the LuGre bristle, the GMS element forces and the hysteresis stack all
    follow the path.
    """
    n_seg = max(2, int(round(segment * run.fs)))
    plant = Plant(params, 1.0 / run.fs, substeps_for(params, run.fs))
    sim = np.empty_like(run.x)
    prev = 0
    for k0 in range(0, run.x.size, n_seg):
        plant.friction_path(run.xf[prev:k0 + 1], run.v[prev:k0 + 1])
        state = plant.get_state()
        sim[k0:k0 + n_seg] = plant.run(run.u[k0:k0 + n_seg]).theta
        plant.set_state(state)
        prev = k0
    return sim


def evaluate(params: PlantParams, run: RunData, segment: float = 1.0) -> dict:
    """Figures of a model on a run from its first sample, by the one scoring function (``analysis.scoring``):
    torque (equation-error) NRMSE, segmented position NRMSE and rms error; with the curves of the plots (the
    prediction at the run's regression rows, the segmented simulation)."""
    from hilbench.analysis.scoring import ScoredRun, ScoreSettings, score_run

    scored = ScoredRun(run.x, run.u, run.fs, "hold_next")  # the held torque is its own hold_next record
    try:
        sc = score_run(params, scored, ScoreSettings(segment=segment), keep=True)
        sim = sc.position_sim_segmented
    except AnalysisError:  # a model the plant cannot simulate keeps its torque figure
        sc = score_run(params, scored, ScoreSettings(segment=segment, simulate=False))
        sim = np.full_like(run.x, np.nan)
    f = sc.figures
    return {"torque_nrmse": f["torque_nrmse"], "position_nrmse_segmented": f.get("position_nrmse_segmented", math.nan),
            "position_rms_segmented": f.get("position_rms_segmented", math.nan),
            "torque_measured": run.data.torque, "torque_predicted": predicted_torque(params, run),
            "position_simulated": sim}


# ---- linear-in-parameters starts ----

def _lstsq(columns: list[np.ndarray], y: np.ndarray) -> tuple[np.ndarray, float]:
    a = np.column_stack(columns)
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    r = y - a @ coef
    return coef, float(r @ r)


def _with_inertia(run: RunData, columns: list[np.ndarray], inertia: float | None) -> tuple[np.ndarray, float]:
    """Least squares of L[tau] on [L[theta''], *columns], or of L[tau] - J*L[theta''] on ``columns`` for a
    given J; returns the coefficients with J first, and the residual sum of squares."""
    d = run.data
    if inertia is None:
        return _lstsq([d.acceleration, *columns], d.torque)
    coef, rss = _lstsq(columns, d.torque - inertia * d.acceleration)
    return np.concatenate([[inertia], coef]), rss


def coulomb_viscous_start(run: RunData, inertia: float | None = None) -> dict[str, float]:
    """Least squares on the filtered [theta'', theta', sgn, 1]; with ``inertia`` given, J is held at it."""
    d = run.data
    coef, _ = _with_inertia(run, [d.velocity, d.sign, np.ones_like(d.torque)], inertia)
    return {"inertia": coef[0], "viscous": coef[1], "coulomb": coef[2], "offset": coef[3]}


def stribeck_start(run: RunData, n_grid: int = 16, inertia: float | None = None) -> dict[str, float]:
    """Coulomb+viscous plus sgn(v)*exp(-(v/vs)^2), vs the best of a log grid; ``inertia`` as above."""
    d = run.data
    vmax = float(np.max(np.abs(run.v)))
    best = None
    for vs in np.geomspace(vmax / 1000, vmax / 2, n_grid):
        col = run.filtered(np.sign(run.v) * np.exp(-((run.v / vs) ** 2)))
        coef, rss = _with_inertia(run, [d.velocity, d.sign, col, np.ones_like(d.torque)], inertia)
        if best is None or rss < best[0]:
            best = (rss, vs, coef)
    _, vs, c = best
    return {"inertia": c[0], "viscous": c[1], "coulomb": c[2], "static": c[2] + c[3], "stribeck_velocity": vs,
            "offset": c[4]}


def maxwell_slip_start(run: RunData, timing: str, position: np.ndarray, torque: np.ndarray,
                       settings: LipSettings | None = None):
    """The NNLS fit of ``hilbench identify`` with its terms (``settings``, default identify's: J, k_i, Delta_i, b,
    no offset), so the ``maxwell_slip`` row is identify's model (docs/compare.md)."""
    return fit_lip(position, torque, run.fs, run.axis, replace(settings or LipSettings(), timing=timing))


# ---- family definitions: parameter vector <-> plant ----

@dataclass
class _Family:
    names: tuple[str, ...]          # refined parameters, in vector order
    unit_keys: tuple[str, ...]      # AXES key (or "1", "torque/s") of each
    plant: Callable[[dict], PlantParams]


def _pos(value: float, floor: float) -> float:
    return max(float(value), floor)


def _build_families(ms) -> dict[str, _Family]:
    """The refinable families; ``ms`` is the Maxwell-slip NNLS fit (its k_i and W_i shape GMS)."""
    k = np.asarray(ms.ms_stiffness, float)
    w = np.asarray(ms.ms_slip, float)
    alpha = w / w.sum() if w.size and w.sum() > 0 else np.ones(1)
    k = k if w.size and w.sum() > 0 else np.ones(1)

    def base(p: dict, **kw) -> PlantParams:
        return PlantParams(inertia=p["inertia"], torque_offset=-p["offset"], **kw)

    return {
        "coulomb_viscous": _Family(
            ("inertia", "coulomb", "viscous", "offset"), ("inertia", "torque", "viscous", "torque"),
            lambda p: base(p, coulomb=p["coulomb"], viscous=p["viscous"])),
        "stribeck": _Family(
            ("inertia", "coulomb", "static_excess", "stribeck_velocity", "viscous", "offset"),
            ("inertia", "torque", "torque", "velocity", "viscous", "torque"),
            lambda p: base(p, coulomb=p["coulomb"], static=p["coulomb"] + p["static_excess"],
                           stribeck_velocity=p["stribeck_velocity"], viscous=p["viscous"])),
        "dahl": _Family(
            ("inertia", "sigma0", "coulomb", "viscous", "offset"), ("inertia", "stiffness", "torque", "viscous",
                                                                    "torque"),
            lambda p: base(p, viscous=p["viscous"], lugre=LuGre(sigma0=p["sigma0"], coulomb=p["coulomb"]))),
        "lugre": _Family(
            ("inertia", "sigma0", "sigma1", "coulomb", "static_excess", "stribeck_velocity", "viscous", "offset"),
            ("inertia", "stiffness", "viscous", "torque", "torque", "velocity", "viscous", "torque"),
            lambda p: base(p, lugre=LuGre(sigma0=p["sigma0"], sigma1=p["sigma1"], sigma2=p["viscous"],
                                          coulomb=p["coulomb"], static=p["coulomb"] + p["static_excess"],
                                          stribeck_velocity=p["stribeck_velocity"]))),
        "gms": _Family(
            ("inertia", "stiffness_scale", "coulomb", "static_excess", "stribeck_velocity", "attraction", "viscous",
             "offset"),
            ("inertia", "1", "torque", "torque", "velocity", "torque/s", "viscous", "torque"),
            lambda p: base(p, viscous=p["viscous"], gms=GMS(
                stiffness=tuple(k * p["stiffness_scale"]), fractions=tuple(alpha), coulomb=p["coulomb"],
                static=p["coulomb"] + p["static_excess"], stribeck_velocity=p["stribeck_velocity"],
                attraction=p["attraction"]))),
        "continuous": _Family(
            ("inertia", "h", "d", "viscous", "offset"), ("inertia", "torque", "position", "viscous", "torque"),
            lambda p: base(p, viscous=p["viscous"], hysteresis=Hysteresis(h=p["h"], d=p["d"],
                                                                          stack=HYSTERESIS_STACK))),
    }


def _unit(axis: str, key: str) -> str:
    u = AXES[axis]
    return {"1": "1", "velocity": f"{u['position']}/s", "torque/s": f"{u['torque']}/s"}.get(key) or u[key]


def _starts(run: RunData, ms) -> dict[str, dict[str, float]]:
    # J is the Maxwell-slip fit's for every family. A law without presliding elasticity, fitted with J free,
    # explains the elastic torque k*x of the presliding oscillation (at sqrt(k/J), which the fs/20 filter
    # passes at 10 kHz and stops at 2 kHz) by a negative mass, J_eff = J - k/w^2: on the DC motor at 10 kHz
    # J = -0.00066 kg*m^2 (true 0.0022), which the old floor turned into 1e-12 and a plant with b/J = 1e12 1/s
    j_ms = float(ms.inertia) if ms.inertia > 0 else None
    cv = coulomb_viscous_start(run, j_ms)
    st = stribeck_start(run, inertia=j_ms)
    scale = float(np.std(run.data.torque)) or 1.0
    fc = _pos(cv["coulomb"], 1e-3 * scale)
    fc_st = _pos(st["coulomb"], 1e-3 * scale)
    # floors keep the Stribeck term alive for the refinement: from a vanishing excess (its log far below the
    # data's scale) least squares sees no gradient and never recovers a real one
    excess = _pos(st["static"] - st["coulomb"], 0.1 * fc_st)
    vmax = float(np.max(np.abs(run.v)))
    v_s = float(np.clip(st["stribeck_velocity"], vmax / 100, vmax / 2))
    j = _pos(cv["inertia"], 1e-12)
    b = _pos(cv["viscous"], 1e-9 * scale)
    k_sum = float(np.sum(ms.ms_stiffness))
    w_sum = float(np.sum(ms.ms_slip))
    sigma0 = k_sum if k_sum > 0 else fc / (1e-3 * float(np.ptp(run.x)))
    common = {"inertia": j, "offset": cv["offset"]}
    ms_offset = float(ms.offset) if ms.offset != 0 else float(cv["offset"])  # a fit without the term: least squares
    stb = {"coulomb": fc_st, "static_excess": excess, "stribeck_velocity": v_s,
           "viscous": _pos(st["viscous"], 1e-9 * scale)}
    h = w_sum if w_sum > 0 else fc
    return {
        "coulomb_viscous": {**common, "coulomb": fc, "viscous": b},
        "stribeck": {**common, "inertia": _pos(st["inertia"], 1e-12), "offset": st["offset"], **stb},
        "dahl": {**common, "sigma0": sigma0, "coulomb": fc, "viscous": b},
        "lugre": {**common, "sigma0": sigma0, "sigma1": math.sqrt(sigma0 * j), **stb},
        "gms": {**common, "inertia": _pos(ms.inertia, 1e-12), "stiffness_scale": 1.0, **stb,
                "coulomb": _pos(w_sum, 1e-3 * scale), "attraction": 100.0 * _pos(w_sum, 1e-3 * scale),
                "viscous": _pos(ms.viscous, 1e-9 * scale), "offset": ms_offset},
        "continuous": {**common, "inertia": _pos(ms.inertia, 1e-12), "h": h,
                       "d": 2.0 * h / k_sum if k_sum > 0 else 1e-3 * float(np.ptp(run.x)),
                       "viscous": _pos(ms.viscous, 1e-9 * scale), "offset": ms_offset},
    }


def _sliding_starts(run: RunData, ms, base: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
    """Second starts, from the Maxwell-slip fit's gross-sliding limit: F_c = sum(W_i), its b, J and c0 (the
    Stribeck shape of the least-squares start). The least-squares starts fit the filtered torque; where the
    filter passes the presliding oscillation (10 kHz: fs/20 = 500 Hz, above sqrt(sum(k)/J)/2pi = 186 Hz on
    the DC motor) they take its elastic torque for viscous friction (b = 1.09 against 0.004, F_c = 0.03 against
    0.76 N*m), a start the refinement does not recover from in its budget. ``base``: the ``_starts``."""
    w_sum = float(np.sum(ms.ms_slip))
    if not (w_sum > 0 and ms.inertia > 0):
        return {}
    sliding = {"inertia": float(ms.inertia), "coulomb": w_sum,
               "viscous": _pos(ms.viscous, 1e-9 * (float(np.std(run.data.torque)) or 1.0))}
    if ms.offset != 0:  # else each family keeps its least-squares offset
        sliding["offset"] = float(ms.offset)
    return {name: {**base[name], **sliding} for name in ("coulomb_viscous", "stribeck", "dahl", "lugre")}


def _start_cost(fam: _Family, start: dict[str, float], run: RunData, segment: float) -> float:
    """Sum of squared segmented position errors of a start (inf where it cannot be simulated)."""
    try:
        r = segmented_position(fam.plant(start), run, segment) - run.x
    except (PlantParameterError, FloatingPointError, AnalysisError):
        return math.inf
    cost = float(r @ r)
    return cost if math.isfinite(cost) else math.inf


def _refine(fam: _Family, start: dict[str, float], run: RunData, segment: float, max_nfev: int):
    """least_squares on the segmented position error over log-parameters (the offset linearly, scaled)."""
    from scipy.optimize import least_squares

    names = fam.names
    c0_scale = max(abs(start["offset"]), 1e-3 * float(np.std(run.data.torque)), 1e-12)
    x_scale = float(np.std(run.x)) or 1.0

    def unpack(vec: np.ndarray) -> dict[str, float]:
        with np.errstate(over="ignore"):  # an overflowing step gives inf, which the plant refuses: residual 10
            return {n: float(vec[i] * c0_scale if n == "offset" else np.exp(vec[i])) for i, n in enumerate(names)}

    def residual(vec: np.ndarray) -> np.ndarray:
        try:
            sim = segmented_position(fam.plant(unpack(vec)), run, segment)
        except (PlantParameterError, FloatingPointError, AnalysisError):
            return np.full(run.x.size, 10.0)
        r = (sim - run.x) / x_scale
        return r if np.all(np.isfinite(r)) else np.full(run.x.size, 10.0)

    # (F_s - F_c)*exp(-(v/v_s)^2) with v_s -> 0 and F_s - F_c -> inf changes the model only where |v| < v_s: a
    # degenerate valley the search otherwise follows. Bound both to the data: F_s - F_c <= 3*F_c (start) and
    # v_s in [max|v|/1000, 10*max|v|]
    vmax = float(np.max(np.abs(run.v)))
    limits = {"static_excess": (1e-6 * start.get("coulomb", 1.0), 3.0 * start.get("coulomb", 1.0)),
              "stribeck_velocity": (vmax / 1000, 10 * vmax)}
    lo = np.array([math.log(limits[n][0]) if n in limits else -np.inf for n in names])
    hi = np.array([math.log(limits[n][1]) if n in limits else np.inf for n in names])
    v0 = np.array([start[n] / c0_scale if n == "offset" else math.log(start[n]) for n in names])
    v0 = np.clip(v0, lo + 1e-9, hi - 1e-9)
    sol = least_squares(residual, v0, method="trf", diff_step=1e-3, max_nfev=max_nfev, bounds=(lo, hi))
    p = unpack(sol.x)
    r = sol.fun
    s2 = float(r @ r) / max(1, r.size - sol.x.size)
    infl = max(1.0, r.size / effective_sample_count(r))
    cov = np.linalg.pinv(sol.jac.T @ sol.jac) * s2 * infl
    se_v = np.sqrt(np.clip(np.diag(cov), 0, None))
    se = {n: float(se_v[i] * (c0_scale if n == "offset" else p[n])) for i, n in enumerate(names)}
    return p, se, int(sol.nfev)


def fit_family(family: str, run: RunData, *, timing: str, position: np.ndarray, torque: np.ndarray,
               segment: float = 1.0, max_nfev: int = 60, ms_fit=None) -> FamilyFit:
    """Identify one family on ``run`` (see the module docstring). ``position``/``torque`` are the raw arrays
    (the Maxwell-slip NNLS works on them); ``ms_fit`` reuses an existing Maxwell-slip fit (its time is then
    not counted again)."""
    if family not in FAMILIES:
        raise AnalysisError(f"family must be one of {', '.join(FAMILIES)}, got {family!r}")
    t0 = time.perf_counter()
    ms_fit = ms_fit if ms_fit is not None else maxwell_slip_start(run, timing, position, torque)
    ms = ms_fit.model
    if family == "maxwell_slip":
        u = AXES[run.axis]
        lip = ms_fit.settings
        keep = (ms.ms_stiffness > 0) & (ms.ms_delta > 0)
        params = {"inertia": ms.inertia, "ms_stiffness": ms.ms_stiffness[keep].tolist(),
                  "ms_delta": ms.ms_delta[keep].tolist()}
        units = {"inertia": u["inertia"], "ms_stiffness": u["stiffness"], "ms_delta": u["position"]}
        # identify's terms, no more (an offset only when the settings fit one: issue #37)
        for term, on, unit in (("viscous", lip.viscous, "viscous"), ("coulomb", lip.coulomb, "torque"),
                               ("spring", lip.spring, "stiffness"), ("offset", lip.offset, "torque")):
            if on:
                params[term], units[term] = float(getattr(ms, term)), u[unit]
        se = {key: (np.asarray(val)[keep].tolist() if np.ndim(val) else float(val))
              for key, val in ms.std_errors.items() if key in params}
        n_par = 2 * int(keep.sum()) + len(params) - 2 - int(lip.fixed_inertia is not None)
        return FamilyFit(family, run.axis, params, se, units, ms.plant_params(), n_par,
                         time.perf_counter() - t0, notes="NNLS (lip) fit of hilbench identify; not refined")
    fam = _build_families(ms)[family]
    starts = _starts(run, ms)
    start = starts[family]
    origin = "least squares"
    second = _sliding_starts(run, ms, starts).get(family)
    if second is not None and _start_cost(fam, second, run, segment) < _start_cost(fam, start, run, segment):
        start, origin = second, "sliding limit of the Maxwell-slip fit"
    p, se, nfev = _refine(fam, start, run, segment, max_nfev)
    n_par = len(fam.names) + (2 * int(np.count_nonzero(ms.ms_slip)) if family == "gms" else 0)
    units = {n: _unit(run.axis, key) for n, key in zip(fam.names, fam.unit_keys, strict=True)}
    notes = f"output-error refinement from the {origin} start, {nfev} evaluations"
    if family == "gms":
        notes += "; k_i and alpha_i from the Maxwell-slip NNLS fit, scaled by stiffness_scale"
    return FamilyFit(family, run.axis, p, se, units, fam.plant(p), n_par, time.perf_counter() - t0,
                     start={n: float(start[n]) for n in fam.names}, notes=notes)


def published_plant(inertia: float, viscous: float, coulomb: float, offset: float) -> PlantParams:
    """A Coulomb+viscous model given by its parameters (e.g. a published one), as a plant."""
    return PlantParams(inertia=inertia, viscous=viscous, coulomb=coulomb, torque_offset=-offset)
