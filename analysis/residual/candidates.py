"""Model terms of the residual loop: a registry of named, parameterised effects.

Each term contributes columns to the joint linear design (``analysis.residual.design``); a few carry
nonlinear settings searched in 1-D over the linear solve (delay, Stribeck velocity) or read from a
diagnostic (harmonic orders from the angle-domain spectrum). Conventions (rotary names; a linear axis
reads m, m/s, N, kg):

    J*theta'' + F(theta, theta', t) = tau_applied = (1 + eps)*tau(t - d)      (F: every friction/load term)

| term | columns (each L[.] at the rows) | parameters | sign |
|---|---|---|---|
| inertia | theta'' | J | >= 0 |
| maxwell_slip | S_Delta_j[theta] on the threshold grid | k_j (W_j = k_j*Delta_j) | >= 0 |
| coulomb | sign(v) | F_c | >= 0 |
| viscous | v | b | >= 0 |
| offset | 1 | c0 (constant load; plant torque_offset = -c0) | free |
| offset_drift | 1, t | c0, c1 (load c0 + c1*t) | free |
| stribeck | sign(v)*exp(-(v/v_s)^2) | F_s - F_c; v_s searched | >= 0 |
| asymmetric_friction | max(v,0), min(v,0), [v>0], -[v<0], sign(v)*F_el[theta] | b+-, F_c+- (>= 0), a | free a |
| position_periodic | sin(k_n theta), cos(k_n theta) | A_n, phi_n: A_n*sin(k_n theta + phi_n) | free |
| position_dependent_friction | g*sin(k_n theta), g*cos(k_n theta); g = F_level[theta]/F_slide | A_n, phi_n | free |
| preload_variation | g*sin(theta), g*cos(theta) (rotary, travel < 1 rev); g*P_1(xi), g*P_2(xi) (linear) | a, c | free |
| delay | (shifts the torque: tau(t - d)) | d, searched | >= 0 |
| torque_gain | tau(t - d) | eps: applied torque (1 + eps)*tau | free |

F_level is the current model's level force (Maxwell-slip elements and Coulomb element, Coulomb, Stribeck, or a
start family's force) with its fitted coefficients held (``Term.bind``); F_el the same without the Coulomb-like
part; F_slide its value while sliding. While sliding g = sign(v); in presliding g follows the elements.

k_n is the spatial angular frequency in rad per unit position: on a rotary axis the harmonic order
(cycles/rev); on a linear axis 2*pi/wavelength.
"""

from __future__ import annotations

import numpy as np

from hilbench.analysis.residual.design import Fit, Setting
from hilbench.analysis.residual.rundata import RunData
from hilbench.common.units import AXIS_UNITS as AXES

FREE = -np.inf


def _units(axis: str) -> dict:
    u = AXES[axis]
    return {"torque": u["torque"], "position": u["position"], "velocity": f"{u['position']}/s",
            "viscous": u["viscous"], "inertia": u["inertia"], "stiffness": u["stiffness"]}


class Term:
    """A named model term. Subclasses define ``columns``; the defaults describe a plain term."""

    name: str = ""
    physics: str = ""  # what it is physically, one line
    diagnostics: tuple[str, ...] = ()  # diagnostics whose significance points to this term
    replaces: tuple[str, ...] = ()  # terms this one contains (removed from the model when it is added)
    main: str = ""  # the main parameter's key in ``parameters``
    candidate: bool = True  # offered by the loop (inertia is not)

    def columns(self, run: RunData, nl: dict, setting: Setting) -> np.ndarray:
        raise NotImplementedError

    def lower(self, nl: dict, q: int) -> np.ndarray:
        return np.zeros(q)

    def delay(self, nl: dict) -> float:
        return 0.0

    def static_level(self, coef: np.ndarray) -> float:
        """Static (set-valued at rest) friction level this term contributes, N*m or N."""
        return 0.0

    def applicable(self, setting: Setting, model_names: list[str]) -> str | None:
        """None if the term can be fitted, else the reason it cannot."""
        return None

    def settings(self, runs: list[RunData], diagnostics: dict) -> list[dict]:
        """Nonlinear settings to try (a 1-D grid), or [{}]; an empty list means nothing to fit."""
        return [{}]

    @staticmethod
    def unfit_reason(runs: list[RunData]) -> str | None:
        """None if the training runs can identify the term, else why not (one line)."""
        return None

    needs_fit: bool = False  # settings depend on the current model's fit (``bind``)
    local_presliding: bool = False  # fitted with the Maxwell-slip thresholds limited to a fraction of the travel

    def bind(self, nl: dict, model: list, fit: Fit) -> dict:
        """A setting completed from the current model and its fit (for ``needs_fit`` terms)."""
        return nl

    def raw_force(self, run: RunData, nl: dict, coef: np.ndarray, setting: Setting) -> np.ndarray:
        """This term's force at full rate, unfiltered, shape (n,), N*m or N (level terms only)."""
        raise NotImplementedError(f"{self.name} has no raw force")

    refine_key: str | None = None  # scalar nonlinear setting refined by a parabola through the grid minimum
    refine_log: bool = False

    def parameters(self, fit: Fit, nl: dict, axis: str) -> tuple[dict, dict]:
        """(parameters, standard errors) as JSON-friendly dicts with a ``units`` entry."""
        raise NotImplementedError

    def plant(self, fit: Fit, nl: dict) -> dict:
        """PlantParams fields this term sets (``stribeck_excess`` is resolved against ``coulomb``)."""
        return {}


def _sym_col(run: RunData, key: str, fn) -> np.ndarray:
    return run.cached((key,), lambda: run.filt(fn(run.velocity_fast))[:, None])


class Inertia(Term):
    name, physics, main, candidate = "inertia", "rigid-body inertia J", "inertia", False

    def columns(self, run, nl, setting):
        if setting.fixed_inertia is not None:
            return np.zeros((run.n_rows, 0))
        return run.data.acceleration[:, None]

    def parameters(self, fit, nl, axis):
        u = _units(axis)
        if fit.setting.fixed_inertia is not None:
            return {"inertia": fit.setting.fixed_inertia, "fixed": True, "units": {"inertia": u["inertia"]}}, {}
        return ({"inertia": float(fit.term_coef(self.name)[0]), "units": {"inertia": u["inertia"]}},
                {"inertia": float(fit.term_se(self.name)[0])})

    def plant(self, fit, nl):
        if fit.setting.fixed_inertia is not None:
            return {"inertia": fit.setting.fixed_inertia}
        return {"inertia": float(fit.term_coef(self.name)[0])}


class MaxwellSlip(Term):
    """Stop-operator columns on the threshold grid, plus the Delta -> 0 element: below the encoder
    resolution (where the grid starts) an element slips after an unmeasurably small travel, which is
    Coulomb friction W_0*sign(v). Without it every real Maxwell-slip model with sub-resolution thresholds
    would show a "missing" Coulomb term."""

    name, main = "maxwell_slip", "breakaway"
    physics = "presliding hysteresis: Maxwell-slip elements (stiffness k_i, slip force W_i)"
    diagnostics = ("low_speed", "position")
    replaces = ("coulomb",)

    def columns(self, run, nl, setting):
        return run.cached(("maxwell_slip", setting.thresholds.tobytes()), lambda: np.column_stack(
            [_sym_col(run, "sign", np.sign), run.stop(setting.thresholds)]))

    def static_level(self, coef):
        return float(coef[0])

    def raw_force(self, run, nl, coef, setting):
        return coef[0] * np.sign(run.velocity_fast) + run.stop_raw(setting.thresholds) @ coef[1:]

    def parameters(self, fit, nl, axis):
        u = _units(axis)
        c = fit.term_coef(self.name)
        w0, k = float(c[0]), c[1:]
        d = fit.setting.thresholds
        keep = k > 0
        w = k[keep] * d[keep]
        se_all = fit.term_se(self.name)
        cov = np.nan_to_num(fit.term_cov(self.name))
        grad = np.concatenate([[1.0], d])
        se_b = float(np.sqrt(max(grad @ cov @ grad, 0.0)))
        return ({"n_elements": int(keep.sum()), "breakaway": float(w.sum()) + w0, "coulomb_element": w0,
                 "ms_stiffness": k[keep].tolist(), "ms_delta": d[keep].tolist(), "ms_slip": w.tolist(),
                 "units": {"breakaway": u["torque"], "coulomb_element": u["torque"], "ms_stiffness": u["stiffness"],
                           "ms_delta": u["position"], "ms_slip": u["torque"]}},
                {"breakaway": se_b, "coulomb_element": float(se_all[0]), "ms_stiffness": se_all[1:][keep].tolist()})

    def plant(self, fit, nl):
        c = fit.term_coef(self.name)
        k = c[1:]
        keep = k > 0
        return {"coulomb": float(c[0]), "ms_stiffness": tuple(map(float, k[keep])),
                "ms_slip": tuple(map(float, k[keep] * fit.setting.thresholds[keep]))}


class _Scalar(Term):
    """A term with one column and one parameter ``main``."""

    unit_key = "torque"

    def parameters(self, fit, nl, axis):
        return ({self.main: float(fit.term_coef(self.name)[0]), "units": {self.main: _units(axis)[self.unit_key]}},
                {self.main: float(fit.term_se(self.name)[0])})


class Coulomb(_Scalar):
    name, main = "coulomb", "coulomb"
    physics = "Coulomb friction F_c*sign(v)"
    diagnostics = ("direction",)

    def columns(self, run, nl, setting):
        return _sym_col(run, "sign", np.sign)

    def static_level(self, coef):
        return float(coef[0])

    def raw_force(self, run, nl, coef, setting):
        return coef[0] * np.sign(run.velocity_fast)

    def plant(self, fit, nl):
        return {"coulomb": float(fit.term_coef(self.name)[0])}


class Viscous(_Scalar):
    name, main, unit_key = "viscous", "viscous", "viscous"
    physics = "viscous friction b*v (lubricant shear, back-EMF damping)"
    diagnostics = ("velocity",)

    def columns(self, run, nl, setting):
        return run.data.velocity[:, None]

    def plant(self, fit, nl):
        return {"viscous": float(fit.term_coef(self.name)[0])}


class Offset(_Scalar):
    name, main = "offset", "offset"
    physics = "constant load or torque offset c0 (gravity, current-sensor offset)"
    diagnostics = ("mean_trend",)

    def columns(self, run, nl, setting):
        return np.ones((run.n_rows, 1))

    def lower(self, nl, q):
        return np.full(q, FREE)

    def plant(self, fit, nl):
        return {"torque_offset": -float(fit.term_coef(self.name)[0])}


class OffsetDrift(Term):
    name, main = "offset_drift", "drift"
    physics = "torque offset and its drift in time (thermal drift of the current sensor or amplifier)"
    diagnostics = ("mean_trend",)
    replaces = ("offset",)

    def columns(self, run, nl, setting):
        return np.column_stack([np.ones(run.n_rows), run.t_rows])

    def lower(self, nl, q):
        return np.full(q, FREE)

    def parameters(self, fit, nl, axis):
        c, se = fit.term_coef(self.name), fit.term_se(self.name)
        tu = _units(axis)["torque"]
        return ({"offset": float(c[0]), "drift": float(c[1]), "units": {"offset": tu, "drift": f"{tu}/s"}},
                {"offset": float(se[0]), "drift": float(se[1])})

    def plant(self, fit, nl):
        c = fit.term_coef(self.name)
        return {"torque_offset": -float(c[0]), "torque_drift": -float(c[1])}


STRIBECK_PLATEAU = 0.9  # the speed percentile that must lie at 2 v_s or above: 10 % of the record past the curve


def stribeck_top(speed: np.ndarray) -> float:
    """The largest Stribeck velocity a record identifies: half its 90th speed percentile, so that at least 10 % of
    the rows slide at 2 v_s or faster, where the excess has decayed to exp(-4) = 2 % and the Coulomb level it decays
    to is seen. A v_s near the top of the record's speeds is a curvature over the whole speed range, collinear with
    the Coulomb level and the viscous slope the start model already has: on clean Dahl data over a 4 rad stroke (speeds
    up to 5.4 rad/s) the start model's presliding misfit at the turning points biased b to 0.0071 (truth 0.004,
    0.0040 on the rows above 0.5 rad/s), and a "Stribeck curve" at v_s = 5.1 rad/s, the grid's top, corrected that
    bias with an 11 % held-out gain (issue 29)."""
    return 0.5 * float(np.percentile(speed, 100 * STRIBECK_PLATEAU))


class Stribeck(Term):
    name, main = "stribeck", "stribeck_excess"
    physics = "Stribeck effect: friction above the Coulomb level at low sliding speed, (F_s-F_c)*exp(-(v/v_s)^2)"
    diagnostics = ("low_speed",)
    refine_key, refine_log = "v_s", True

    def columns(self, run, nl, setting):
        vs = float(nl["v_s"])
        return run.cached(("stribeck", vs), lambda: run.filt(
            np.sign(run.velocity_fast) * np.exp(-((run.velocity_fast / vs) ** 2)))[:, None])

    def static_level(self, coef):
        return float(coef[0])

    def raw_force(self, run, nl, coef, setting):
        v = run.velocity_fast
        return coef[0] * np.sign(v) * np.exp(-((v / float(nl["v_s"])) ** 2))

    def settings(self, runs, diagnostics):
        speed = np.abs(np.concatenate([r.velocity_fast for r in runs]))
        lo, hi = np.percentile(speed, 3), stribeck_top(speed)
        if not hi > lo > 0:
            return []
        return [{"v_s": float(v)} for v in np.geomspace(lo, hi, 14)]

    def parameters(self, fit, nl, axis):
        u = _units(axis)
        se = dict(nl.get("_se", {}))
        return ({"stribeck_excess": float(fit.term_coef(self.name)[0]), "stribeck_velocity": float(nl["v_s"]),
                 "units": {"stribeck_excess": u["torque"], "stribeck_velocity": u["velocity"]}},
                {"stribeck_excess": float(fit.term_se(self.name)[0]),
                 "stribeck_velocity": float(se.get("v_s", np.nan))})

    def plant(self, fit, nl):
        return {"stribeck_excess": float(fit.term_coef(self.name)[0]), "stribeck_velocity": float(nl["v_s"])}


#: exponents of the power-law viscous term: 0.2-0.8 (1 is the viscous term itself; elastohydrodynamic theory gives 0.3)
POWER_EXPONENTS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8)


class PowerViscous(Term):
    """Sublinear velocity strengthening c*sign(v)*|v|^n, 0 < n < 1, beside the linear viscous term.

    Why: in an elastohydrodynamic contact (the balls of a screw or a bearing) the film thickness grows with the
    rolling speed as about v^0.7 (Hamrock-Dowson), so the film's shear force eta*v/h grows as about v^0.3, not as v:
    a friction that rises steeply at low sliding speed and flattens at high speed. The coefficient is kept >= 0, so the
    term cannot mimic a Stribeck curve (velocity weakening). The coefficient is the term's force at unit speed
    (1 rad/s or 1 m/s). The simulated plant has no such law: ``plant`` raises, so a model with this term reports no
    simulation error (``simulation_note`` says why) rather than the error of a model without it."""

    name, main = "power_viscous", "power_coefficient"
    physics = "sublinear viscous friction c*sign(v)*|v|^n, 0 < n < 1 (shear of an elastohydrodynamic film)"
    refine_key = "exponent"

    def columns(self, run, nl, setting):
        n = float(nl["exponent"])
        return run.cached(("power_viscous", n), lambda: run.filt(
            np.sign(run.velocity_fast) * np.abs(run.velocity_fast) ** n)[:, None])

    def settings(self, runs, diagnostics):
        return [{"exponent": n} for n in POWER_EXPONENTS]

    def parameters(self, fit, nl, axis):
        u = _units(axis)
        se = dict(nl.get("_se", {}))
        return ({"power_coefficient": float(fit.term_coef(self.name)[0]), "exponent": float(nl["exponent"]),
                 "units": {"power_coefficient": f"{u['torque']} at 1 {u['velocity']}", "exponent": "1"}},
                {"power_coefficient": float(fit.term_se(self.name)[0]), "exponent": float(se.get("exponent", np.nan))})

    def plant(self, fit, nl):
        from hilbench.firmware_sim.engine.plant import PlantParameterError

        raise PlantParameterError("the simulated plant has no power-law viscous friction (power_viscous)")


class AsymmetricFriction(Term):
    """Direction-dependent friction. Two ways a friction level can differ between the directions of motion:

    - additively: Coulomb and viscous levels per direction (columns max(v,0), min(v,0), [v>0], -[v<0]); while
      moving this is a symmetric level plus a constant, so on its own it cannot be told from ``offset``
      except at rest;
    - multiplicatively: the whole friction level scaled by (1 + a*sign(v)), presliding included
      (column sign(v)*F_level[theta], F_level the start model's Coulomb-like and Maxwell-slip force with its
      fitted coefficients held, the ``_level`` setting). Right after a reversal the elements still carry the
      old direction's deflection, so the force there differs from a symmetric level plus a constant by up to
      2*a*F_c: the presliding rows tell the two apart.
    """

    name, main = "asymmetric_friction", "coulomb_difference"
    physics = ("direction-dependent friction: Coulomb level, viscous slope and presliding force differ between "
               "directions")
    diagnostics = ("direction",)
    replaces = ("viscous", "coulomb", "offset")
    needs_fit = True

    def bind(self, nl: dict, model: list, fit: Fit) -> dict:
        return _bind_level(nl, model, fit)

    def columns(self, run, nl, setting):
        level = nl.get("_level", [])

        def make():
            v = run.velocity_fast
            s = np.sign(v)
            cols = [np.maximum(v, 0), np.minimum(v, 0), (v > 0) * 1.0, -1.0 * (v < 0)]
            if level:
                # the Coulomb-like part of F_level is already in the two direction columns
                cols.append(s * (_level_force(run, nl, setting)
                                 - sum(_coulomb_like(n, n_nl, c, s, v) for n, n_nl, c in level)))
            return run.filt(np.column_stack(cols))
        return run.cached(("asym", _level_key(nl, setting)), make)

    def lower(self, nl, q):
        return np.array([0, 0, 0, 0, FREE][:q], float)

    def static_level(self, coef):
        return float(max(coef[2], coef[3]))

    @staticmethod
    def _element_level(nl: dict, setting: Setting) -> float:
        """Sliding force of the held level terms without their Coulomb-like part (the part the scaled column
        multiplies), N*m or N."""
        return _sliding_level(nl, setting) - sum(float(c[0]) for n, _, c in nl.get("_level", [])
                                                 if n in LEVEL_TERMS)

    def _gradients(self, fit, nl) -> dict:
        """Each reported level as a linear function of the term's coefficients: while sliding the scaled column
        adds a*L to the positive direction's level and takes it from the negative one's (L: _element_level)."""
        q = fit.term_coef(self.name).size
        big_l = self._element_level(nl, fit.setting) if q > 4 else 0.0
        g = {"viscous_pos": [1, 0, 0, 0, 0], "viscous_neg": [0, 1, 0, 0, 0], "coulomb_pos": [0, 0, 1, 0, big_l],
             "coulomb_neg": [0, 0, 0, 1, -big_l], "coulomb_difference": [0, 0, 1, -1, 2 * big_l],
             "viscous_difference": [1, -1, 0, 0, 0]}
        return {k: np.array(v[:q], float) for k, v in g.items()}

    def parameters(self, fit, nl, axis):
        u = _units(axis)
        c, cov = fit.term_coef(self.name), np.nan_to_num(fit.term_cov(self.name))
        params, unc = {}, {}
        for key, g in self._gradients(fit, nl).items():
            params[key] = float(g @ c)
            unc[key] = float(np.sqrt(max(g @ cov @ g, 0.0)))
        params["units"] = {"viscous_pos": u["viscous"], "viscous_neg": u["viscous"], "coulomb_pos": u["torque"],
                           "coulomb_neg": u["torque"], "coulomb_difference": u["torque"],
                           "viscous_difference": u["viscous"]}
        if c.size > 4:
            params["presliding_asymmetry"] = float(c[4])
            params["units"]["presliding_asymmetry"] = "1"
            unc["presliding_asymmetry"] = float(fit.term_se(self.name)[4])
        return params, unc

    def plant(self, fit, nl):
        # the C plant has no direction-scaled presliding force: the sliding levels go to its Coulomb element
        c = fit.term_coef(self.name)
        g = self._gradients(fit, nl)
        return {"viscous": float(c[0]), "viscous_neg": float(c[1]), "coulomb": float(g["coulomb_pos"] @ c),
                "coulomb_neg": float(g["coulomb_neg"] @ c)}


LEVEL_TERMS = ("maxwell_slip", "coulomb", "stribeck")


def _bind_level(nl: dict, model: list, fit: Fit) -> dict:
    """``nl`` plus ``_level``: the current model's level terms (name, settings, fitted coefficients), held, and
    ``_grid``: the threshold grid those coefficients were fitted on.

    The held level is a fixed function of the path, built from the setting of the model the term was bound to,
    never from the setting of a later model: the loop changes the grid under a model (the spring element, a
    ``local_presliding`` candidate's shortened grid), and Maxwell-slip coefficients of one grid applied to
    another crashed the loop on a displacement-driven tribometer record (40 coefficients, a 30-threshold grid;
    issue 39)."""
    return {**nl, "_grid": np.array(fit.setting.thresholds, float),
            "_level": [(t.name, dict(n), fit.term_coef(t.name).copy()) for t, n in model
                       if t.name in LEVEL_TERMS or t.name.startswith("family_")]}


def _held(nl: dict, setting: Setting) -> Setting:
    """The setting the held level terms were fitted on: ``setting`` with the bound threshold grid."""
    grid = nl.get("_grid")
    if grid is None or (grid.shape == setting.thresholds.shape and np.array_equal(grid, setting.thresholds)):
        return setting
    return Setting(setting.fixed_inertia, grid, setting.delay)


def _level_key(nl: dict, setting: Setting) -> tuple:
    return tuple((n, c.tobytes()) for n, _, c in nl.get("_level", [])) + (_held(nl, setting).thresholds.tobytes(),)


def _level_force(run: RunData, nl: dict, setting: Setting) -> np.ndarray:
    """The held level terms' force at full rate, unfiltered, shape (n,), N*m or N (zeros without any)."""
    held = _held(nl, setting)
    return sum((REGISTRY[n].raw_force(run, n_nl, c, held) for n, n_nl, c in nl.get("_level", [])),
               np.zeros(run.position.size))


def _sliding_level(nl: dict, setting: Setting) -> float:
    """The held level terms' force while sliding (Maxwell-slip: W_0 + sum k_j*Delta_j), N*m or N."""
    grid = _held(nl, setting).thresholds
    out = 0.0
    for n, _, c in nl.get("_level", []):
        out += float(c[0] + c[1:] @ grid) if n == "maxwell_slip" else float(c[0])
    return out


def _coulomb_like(name: str, nl: dict, coef: np.ndarray, s: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The part of a level term's raw force that is a function of sign(v) alone (the Delta -> 0 element, F_c)."""
    if name in ("maxwell_slip", "coulomb"):
        return coef[0] * s
    return np.zeros_like(v)


def _harmonic_parameters(fit: Fit, name: str, nl: dict, axis: str) -> tuple[dict, dict]:
    c, cov = fit.term_coef(name), np.nan_to_num(fit.term_cov(name))
    harmonics, unc = [], []
    for i, k in enumerate(nl["wavenumbers"]):
        a, b = c[2 * i], c[2 * i + 1]
        amp = float(np.hypot(a, b))
        g = np.array([a, b]) / amp if amp > 0 else np.zeros(2)
        sub = cov[2 * i: 2 * i + 2, 2 * i: 2 * i + 2]
        h = {"amplitude": amp, "phase": float(np.arctan2(b, a))}
        if axis == "rotary":
            h["order"] = float(k)
        else:
            h["wavelength"] = float(2 * np.pi / k)
        harmonics.append(h)
        unc.append({"amplitude": float(np.sqrt(max(g @ sub @ g, 0)))})
    best = int(np.argmax([h["amplitude"] for h in harmonics]))
    u = _units(axis)
    params = {"amplitude": harmonics[best]["amplitude"], "harmonics": harmonics,
              "units": {"amplitude": u["torque"], "phase": "rad",
                        **({"order": "cycles/rev"} if axis == "rotary" else {"wavelength": u["position"]})}}
    return params, {"amplitude": unc[best]["amplitude"], "harmonics": unc}


class PositionPeriodic(Term):
    name, main = "position_periodic", "amplitude"
    physics = "cogging or torque ripple: torque periodic in position, sum A_n*sin(k_n*theta + phi_n)"
    diagnostics = ("angle_spectrum",)
    spectrum = "angle_spectrum"
    max_harmonics = 4

    def _basis(self, run: RunData, k: float) -> np.ndarray:
        return np.column_stack([np.sin(k * run.position), np.cos(k * run.position)])

    def columns(self, run, nl, setting):
        ks = tuple(nl["wavenumbers"])
        return run.cached((self.name, ks), lambda: run.filt(np.column_stack([self._basis(run, k) for k in ks])))

    def lower(self, nl, q):
        return np.full(q, FREE)

    def settings(self, runs, diagnostics):
        diag = diagnostics.get(self.spectrum)
        if diag is None:
            return []
        if diag.detail.get("peaks"):
            # every significant peak of the spectrum (strongest first) enters as one harmonic
            return [{"wavenumbers": [p["wavenumber"] for p in diag.detail["peaks"][: self.max_harmonics]]}]
        spec = diag.detail.get("spectrum")
        if spec is None or not len(spec["effect"]):
            return []
        # no line passed the spectrum's own test: the strongest line is still fitted and judged on held-out
        # data (a line in the angle spectrum always leads to a fitted candidate)
        return [{"wavenumbers": [float(spec["wavenumber"][int(np.argmax(spec["effect"]))])]}]

    def parameters(self, fit, nl, axis):
        return _harmonic_parameters(fit, self.name, nl, axis)

    def plant(self, fit, nl):
        from hilbench.firmware_sim.engine.plant import Cogging

        c = fit.term_coef(self.name)
        return {"cogging": tuple(Cogging(float(k), float(np.hypot(c[2 * i], c[2 * i + 1])),
                                         float(np.arctan2(c[2 * i + 1], c[2 * i])))
                                 for i, k in enumerate(nl["wavenumbers"]))}


class PositionDependentFriction(PositionPeriodic):
    name = "position_dependent_friction"
    physics = ("friction level that varies with position (eccentricity, raceway waviness): the level force "
               "F_level*(1 + (A/F_slide)*sin(k*theta+phi)), A*sin(k*theta+phi)*sign(v) while sliding")
    diagnostics = ("angle_spectrum_direction",)
    spectrum = "angle_spectrum_direction"

    needs_fit = True

    def bind(self, nl, model, fit):
        return _bind_level(nl, model, fit)

    def columns(self, run, nl, setting):
        ks = tuple(nl["wavenumbers"])
        norm = _sliding_level(nl, setting)

        def make():
            # the whole friction level scaled by (1 + m*sin(k*theta + phi)), presliding included: the held level
            # force normalised to 1 while sliding (sign(v) when the model has no level term)
            g = _level_force(run, nl, setting) / norm if norm > 0 else np.sign(run.velocity_fast)
            return run.filt(np.column_stack([g[:, None] * np.column_stack([np.sin(k * run.position),
                                                                           np.cos(k * run.position)])
                                             for k in ks]))
        return run.cached((self.name, ks, _level_key(nl, setting)), make)

    def plant(self, fit, nl):
        return {}  # the C plant has no position-dependent friction level; simulated without it


PRESLIDING_MODES = ("scaled", "slip")  # preload_variation: what of the presliding force follows the level


class PreloadVariation(Term):
    """A friction level that follows a preload varying slowly with position, identifiable from part of its period:
    an eccentric preload once per revolution seen over a stroke of a fraction of a turn, or a preload that changes
    along a linear axis' travel. The whole held level force (presliding included, as ``position_dependent_friction``)
    is scaled by 1 + a*b_1 + c*b_2 with a fixed low-order basis (no search, no spectrum):

    - rotary: b = (sin theta, cos theta), the once-per-revolution harmonic; applicable only when the training
      travel is shorter than a revolution (over whole revolutions ``position_dependent_friction`` at order 1 is the
      same column and is found from the angle spectrum);
    - linear: b = (P_1(xi), P_2(xi)), Legendre polynomials of xi = (x - x_mid)/(half travel), the training runs'
      travel mapped to [-1, 1] (held fixed for the validation runs).

    Two ways a preload can change presliding (the ``_presliding`` setting, the one with the smaller training error
    is kept): ``scaled``, the stiffnesses and slip forces together (the presliding distance fixed, as above), or
    ``slip``, the slip forces alone with the stiffnesses fixed, so the presliding distance grows with the level (GMS,
    and a contact whose stiffness barely follows the load). For ``slip`` the column is the first-order change of the
    held Maxwell-slip force when every threshold becomes Delta_j*(1 + a*b(x)): an element carries the level of the
    position where it last slipped, sum_j W_j*s_j*b(x_slip,j) (s_j the side it slipped on), where ``scaled`` has
    b(x)*F_level. Both agree while sliding. On a GMS truth with the level x (1 + 0.2*x) over a 2 m stroke the
    ``scaled`` form left a mean residual (each reversal at the top of the stroke slips later than the model, each at
    the bottom earlier, and both leave the force above it), which ``asymmetric_friction`` then took up (issue 29).

    Odd in velocity (a friction level), so it is told from cogging (``position_periodic``, a load even in velocity)
    and from an offset drift (a load in time)."""

    name, main = "preload_variation", "level_variation"
    physics = ("friction level that follows a preload varying slowly with position (eccentric preload once per "
               "revolution over part of a turn; preload changing along a linear axis' travel): "
               "F_level*(1 + a*b_1 + c*b_2), b = (sin theta, cos theta) rotary, Legendre P_1, P_2 of the travel linear")
    diagnostics = ("position_level",)
    needs_fit = True
    local_presliding = True  # long elements would mimic the level's variation (selection._local_thresholds)

    def bind(self, nl, model, fit):
        return _bind_level(nl, model, fit)

    @staticmethod
    def unfit_reason(runs: list[RunData]) -> str | None:
        travel = max(float(np.ptp(r.position)) for r in runs)
        if runs[0].axis == "rotary" and travel >= 2 * np.pi:
            return (f"the training travel ({travel:.3g} rad) covers a revolution: a once-per-revolution level is "
                    "position_dependent_friction at order 1")
        return None

    def settings(self, runs, diagnostics):
        lo = min(float(r.position.min()) for r in runs)
        hi = max(float(r.position.max()) for r in runs)
        if not hi > lo:
            return []
        base = {"_axis": runs[0].axis, "_mid": 0.5 * (lo + hi), "_half": 0.5 * (hi - lo)}
        return [{**base, "_presliding": mode} for mode in PRESLIDING_MODES]

    @staticmethod
    def basis(position: np.ndarray, nl: dict) -> np.ndarray:
        """The two basis functions at ``position``, shape (n, 2)."""
        if nl["_axis"] == "rotary":
            return np.column_stack([np.sin(position), np.cos(position)])
        xi = (position - nl["_mid"]) / nl["_half"]
        return np.column_stack([xi, 1.5 * xi**2 - 0.5])

    def columns(self, run, nl, setting):
        norm = _sliding_level(nl, setting)
        mode = nl.get("_presliding", "scaled")

        def make():
            if mode == "slip" and norm > 0:
                return run.filt(self._slip_force(run, nl, setting) / norm)
            g = _level_force(run, nl, setting) / norm if norm > 0 else np.sign(run.velocity_fast)
            return run.filt(g[:, None] * self.basis(run.position, nl))
        return run.cached((self.name, mode, nl["_axis"], nl["_mid"], nl["_half"], _level_key(nl, setting)), make)

    def _slip_force(self, run: RunData, nl: dict, setting: Setting) -> np.ndarray:
        """The held level force's first-order change when the slip forces alone follow the basis, per basis
        function, shape (n, 2): sum_j W_j*s_j*b(x at element j's last slip) for the Maxwell-slip elements (0 before
        an element first slips), b(x)*force for the Coulomb-like terms (always slipping)."""
        setting = _held(nl, setting)
        bx = self.basis(run.position, nl)
        out = np.zeros((run.position.size, 2))
        for name, n_nl, c in nl.get("_level", []):
            if name != "maxwell_slip":
                out += REGISTRY[name].raw_force(run, n_nl, c, setting)[:, None] * bx
                continue
            out += c[0] * np.sign(run.velocity_fast)[:, None] * bx
            use = c[1:] > 0
            if not use.any():
                continue
            delta = setting.thresholds[use]
            z = run.stop_raw(setting.thresholds)[:, use]
            slipping = np.abs(z) >= delta * (1 - 1e-9)
            last = np.maximum.accumulate(np.where(slipping, np.arange(z.shape[0])[:, None], -1), axis=0)
            seen = last >= 0
            last = np.where(seen, last, 0)
            side = np.sign(np.take_along_axis(z, last, axis=0)) * seen
            w = c[1:][use] * delta
            for i in range(2):
                out[:, i] += (w * side * bx[last, i]).sum(axis=1)
        return out

    def lower(self, nl, q):
        return np.full(q, FREE)

    def parameters(self, fit, nl, axis):
        u = _units(axis)
        c, cov = fit.term_coef(self.name), np.nan_to_num(fit.term_cov(self.name))
        mode = nl.get("_presliding", "scaled")  # what of the presliding force follows the level (PRESLIDING_MODES)
        # relative to the sliding level of this fit (not the held start model's, which the unmodelled variation
        # biased: 0.46 against 0.60 N*m on an eccentric preload over 5 rad)
        level = sum(float(fit.term_coef(t.name)[0] + fit.term_coef(t.name)[1:] @ fit.setting.thresholds)
                    if t.name == "maxwell_slip" else float(fit.term_coef(t.name)[0])
                    for t, _ in fit.model if t.name in ("maxwell_slip", "coulomb"))
        if nl["_axis"] == "rotary":
            amp = float(np.hypot(c[0], c[1]))
            g = np.array([c[0], c[1]]) / amp if amp > 0 else np.zeros(2)
            se_amp = float(np.sqrt(max(g @ cov @ g, 0.0)))
            return ({"level_variation": amp, "phase": float(np.arctan2(c[1], c[0])),
                     "relative_depth": amp / level if level > 0 else None, "presliding": mode,
                     "units": {"level_variation": u["torque"], "phase": "rad", "relative_depth": "1"}},
                    {"level_variation": se_amp, "relative_depth": se_amp / level if level > 0 else None})
        # linear: the level's change from one end of the training travel to the other is 2*a (P_1 = -1 .. +1)
        se = fit.term_se(self.name)
        return ({"level_variation": float(2 * c[0]), "slope": float(c[0] / nl["_half"]), "curvature": float(c[1]),
                 "travel_mid": float(nl["_mid"]), "half_travel": float(nl["_half"]), "presliding": mode,
                 "units": {"level_variation": u["torque"], "slope": f"{u['torque']}/{u['position']}",
                           "curvature": u["torque"], "travel_mid": u["position"], "half_travel": u["position"]}},
                {"level_variation": float(2 * se[0]), "slope": float(se[0] / nl["_half"]), "curvature": float(se[1])})

    def plant(self, fit, nl):
        return {}  # the C plant has no position-dependent friction level; simulated without it


class Delay(Term):
    name, main = "delay", "delay"
    physics = "input delay or current-loop lag between the torque command and the torque acting"
    diagnostics = ("input_rate", "input_xcorr")
    refine_key = "samples"
    max_samples = 30

    def columns(self, run, nl, setting):
        return np.zeros((run.n_rows, 0))

    def delay(self, nl):
        return float(nl["samples"])

    def applicable(self, setting, model_names):
        return "a delay is already in the model" if setting.delay else None

    def settings(self, runs, diagnostics):
        fs = runs[0].fs
        return [{"samples": float(s), "_fs": fs} for s in np.arange(0.0, self.max_samples + 0.5, 1.0)]

    def parameters(self, fit, nl, axis):
        dt = 1.0 / nl["_fs"]
        se = nl.get("_se", {}).get("samples", np.nan)
        return ({"delay": float(nl["samples"]) * dt, "delay_samples": float(nl["samples"]),
                 "units": {"delay": "s", "delay_samples": "samples"}},
                {"delay": float(se) * dt, "delay_samples": float(se)})

    def plant(self, fit, nl):
        s = float(nl["samples"])
        whole = int(np.floor(s))
        return {"delay_samples": whole, "current_lag": (s - whole) / nl["_fs"]}


class TorqueGain(Term):
    name, main = "torque_gain", "torque_constant_error"
    physics = "torque-constant error: the applied torque is (1 + eps) times the assumed one"
    diagnostics = ("command", "acceleration")

    def applicable(self, setting, model_names):
        if setting.fixed_inertia is None:
            return ("not identifiable without a known inertia: a torque gain only rescales J and every "
                    "friction parameter (pass a known inertia)")
        if setting.fixed_inertia == 0:
            return "not identifiable with zero inertia: a gain only rescales every friction parameter"
        return None

    def columns(self, run, nl, setting):
        return run.torque_rows(setting.delay)[:, None]

    def lower(self, nl, q):
        return np.full(q, FREE)

    def parameters(self, fit, nl, axis):
        return ({"torque_constant_error": -float(fit.term_coef(self.name)[0]),
                 "units": {"torque_constant_error": "1"}},
                {"torque_constant_error": float(fit.term_se(self.name)[0])})

    def plant(self, fit, nl):
        return {"torque_constant_error": -float(fit.term_coef(self.name)[0])}


REGISTRY: dict[str, Term] = {}


def register(term: Term) -> Term:
    """Add a term to the registry (the set of candidates is open)."""
    if not term.name:
        raise ValueError("a term needs a name")
    REGISTRY[term.name] = term
    return term


for _t in (Inertia(), MaxwellSlip(), Coulomb(), Viscous(), Offset(), OffsetDrift(), Stribeck(), PowerViscous(),
           AsymmetricFriction(), PositionPeriodic(), PositionDependentFriction(), PreloadVariation(), Delay(),
           TorqueGain()):
    register(_t)

CANDIDATE_NAMES = ("viscous", "stribeck", "power_viscous", "asymmetric_friction", "position_periodic",
                   "position_dependent_friction", "preload_variation", "delay", "torque_gain", "offset_drift")


def get_term(name: str) -> Term:
    from hilbench.analysis.errors import AnalysisError

    if name not in REGISTRY:
        raise AnalysisError(f"unknown model term {name!r}; known: {', '.join(REGISTRY)}")
    return REGISTRY[name]
