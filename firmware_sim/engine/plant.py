"""The simulation engine: a C plant (cffi) with a checked Python face.

One engine serves the simulated device and the analysis. Equations, integration scheme, stability limit
and sampling convention are in ``docs/plant.md``. Every parameter is validated here, before any C code
runs, and a bad one raises :class:`PlantParameterError` with a one-line message.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, fields

import numpy as np

from hilbench.firmware_sim.engine._plant import ffi, lib

MAX_ELEMENTS: int = lib.HB_MAX_ELEMENTS
MAX_DELAY_SAMPLES: int = lib.HB_MAX_DELAY
MAX_GMS_ELEMENTS: int = lib.HB_MAX_GMS
MAX_STACK: int = lib.HB_MAX_STACK
MODES = {"current": lib.HB_MODE_CURRENT, "velocity": lib.HB_MODE_VELOCITY}
#: |lambda*h| bound for the RK4 sub-step; RK4's stability region contains the closed left half-disc of
#: radius 2.5 (checked in tests/firmware_sim/test_plant_validation.py).
RK4_STABLE_RADIUS = 2.5

OUTPUT_UNITS = {
    "theta": "rad",
    "omega": "rad/s",
    "friction": "N*m",
    "current_cmd": "A",
    "current_meas": "A",
    "torque": "N*m",
    "position_meas": "rad",
    "counts": "count",
}


class PlantParameterError(ValueError):
    """A plant parameter, input or step size that the engine refuses."""


@dataclass(frozen=True)
class Cogging:
    """One harmonic of position-periodic torque: ``amplitude*sin(order*theta + phase)`` (N*m),
    acting against the motor like a load torque."""

    order: float
    amplitude: float
    phase: float = 0.0


@dataclass(frozen=True)
class LuGre:
    """LuGre friction (Canudas de Wit, Olsson, Astrom, Lischinsky 1995), docs/plant.md "Friction models":
    ``F = sigma0*z + sigma1*dz/dt + sigma2*omega``, ``dz/dt = omega - sigma0*|omega|*z/g(omega)``,
    ``g(omega) = coulomb + (static - coulomb)*exp(-|omega/stribeck_velocity|**exponent)``.
    Steady sliding at omega gives ``F = sgn(omega)*g(omega) + sigma2*omega``."""

    sigma0: float                 # bristle stiffness, N*m/rad
    coulomb: float                # Fc, N*m
    sigma1: float = 0.0           # bristle damping, N*m*s/rad
    sigma2: float = 0.0           # viscous, N*m*s/rad
    static: float | None = None   # Fs, N*m (None: Fc, no Stribeck)
    stribeck_velocity: float = 0.0  # vs, rad/s
    exponent: float = 2.0         # delta


@dataclass(frozen=True)
class GMS:
    """Generalized Maxwell-slip (Al-Bender, Lampaert, Swevers 2005), docs/plant.md "Friction models".
    N elements k_i, alpha_i; an element sticks (dF_i/dt = k_i*omega) until |F_i| = alpha_i*s(omega), then
    slips with ``dF_i/dt = attraction*(sgn(omega) - F_i/(alpha_i*s(omega)))`` until the motion reverses;
    ``F = sum(F_i) + viscous*omega``, ``s(omega) = coulomb + (static - coulomb)*exp(-|omega/vs|**exponent)``.
    With ``attraction = inf`` and no Stribeck it is the Maxwell-slip model with W_i = alpha_i*coulomb."""

    stiffness: Sequence[float]    # k_i, N*m/rad
    fractions: Sequence[float]    # alpha_i, dimensionless (sum 1 for s(omega) to be the total)
    coulomb: float                # Fc, N*m
    static: float | None = None   # Fs, N*m (None: Fc)
    stribeck_velocity: float = 0.0  # vs, rad/s
    exponent: float = 2.0         # delta
    attraction: float = math.inf  # C, N*m/s
    viscous: float = 0.0          # sigma2, N*m*s/rad


@dataclass(frozen=True)
class Hysteresis:
    """Continuous rate-independent hysteresis on the rolling-friction virgin curve
    ``phi(x) = h*(1 - (d/(d+|x|))**2)*sgn(x)`` with Masing branches and wiping-out over a stack of at most
    ``stack`` reversal points; when full, the newest (smallest) loop is closed (docs/plant.md)."""

    h: float          # limit force, N*m
    d: float          # characteristic displacement, rad
    stack: int = 64   # reversal points kept, 1..MAX_STACK


_MODEL_TYPES = {"lugre": LuGre, "gms": GMS, "hysteresis": Hysteresis}


@dataclass(frozen=True)
class PlantParams:
    """Physical parameters and injectable effects of the plant (SI units; rotary names, a linear axis
    reads m, m/s, N and kg)."""

    inertia: float
    spring: float = 0.0
    ms_stiffness: Sequence[float] = ()
    ms_slip: Sequence[float] = ()
    viscous: float = 0.0
    viscous_neg: float | None = None
    coulomb: float = 0.0
    coulomb_neg: float | None = None
    static: float | None = None
    stribeck_velocity: float = 0.0
    torque_constant: float = 1.0
    cogging: Sequence[Cogging] = ()
    delay_samples: int = 0
    current_lag: float = 0.0
    torque_constant_error: float = 0.0
    torque_offset: float = 0.0
    torque_drift: float = 0.0
    counts_per_rev: int = 0
    noise_current: float = 0.0
    noise_position: float = 0.0
    seed: int = 0
    velocity_kp: float = 0.0
    velocity_ki: float = 0.0
    current_limit: float = math.inf
    restoring_table: tuple[Sequence[float], Sequence[float]] | None = None
    damping_table: tuple[Sequence[float], Sequence[float]] | None = None
    lugre: LuGre | None = None
    gms: GMS | None = None
    hysteresis: Hysteresis | None = None

    @property
    def n_elements(self) -> int:
        return len(self.ms_stiffness)

    @property
    def ms_delta(self) -> np.ndarray:
        """Slip displacements Delta_i = W_i / k_i (rad)."""
        return np.asarray(self.ms_slip, float) / np.asarray(self.ms_stiffness, float)

    @property
    def breakaway(self) -> float:
        """Total Maxwell-slip slip force sum(W_i) plus Coulomb (N*m)."""
        return float(np.sum(self.ms_slip)) + self.coulomb

    def replace(self, **changes) -> PlantParams:
        """A copy with some fields changed (validated when a Plant is built)."""
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        values.update(changes)
        return PlantParams(**values)

    def to_dict(self) -> dict:
        """JSON-friendly dict (arrays as lists); inverse of :meth:`from_dict`."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "cogging":
                v = [{"order": c.order, "amplitude": c.amplitude, "phase": c.phase} for c in v]
            elif f.name in _MODEL_TYPES and v is not None:
                v = {m.name: (np.asarray(getattr(v, m.name), float).tolist()
                              if m.name in ("stiffness", "fractions") else
                              ("inf" if getattr(v, m.name) == math.inf else getattr(v, m.name)))
                     for m in fields(v)}
            elif f.name in ("restoring_table", "damping_table") and v is not None:
                v = [np.asarray(v[0], float).tolist(), np.asarray(v[1], float).tolist()]
            elif isinstance(v, (np.ndarray, tuple, list)):
                v = np.asarray(v, float).tolist()
            elif isinstance(v, float) and math.isinf(v):
                v = "inf"
            out[f.name] = v
        return out

    @classmethod
    def from_dict(cls, data: dict) -> PlantParams:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise PlantParameterError(f"unknown plant parameter(s): {', '.join(unknown)}")
        values = dict(data)
        if "cogging" in values:
            values["cogging"] = tuple(
                c if isinstance(c, Cogging) else Cogging(**c) for c in values["cogging"]
            )
        for name in ("ms_stiffness", "ms_slip"):
            if name in values:
                values[name] = tuple(float(x) for x in values[name])
        for name in ("restoring_table", "damping_table"):
            if values.get(name) is not None:
                values[name] = (tuple(values[name][0]), tuple(values[name][1]))
        for name, kind in _MODEL_TYPES.items():
            if isinstance(values.get(name), dict):
                model = {key: (math.inf if val == "inf" else val) for key, val in values[name].items()}
                for key in ("stiffness", "fractions"):
                    if key in model:
                        model[key] = tuple(float(x) for x in model[key])
                try:
                    values[name] = kind(**model)
                except TypeError as exc:
                    raise PlantParameterError(f"{name}: {exc}") from None
        if values.get("current_limit") == "inf":
            values["current_limit"] = math.inf
        return cls(**values)


@dataclass
class PlantOutput:
    """Per-sample outputs of :meth:`Plant.run`; see ``OUTPUT_UNITS`` and docs/plant.md for timing."""

    theta: np.ndarray
    omega: np.ndarray
    friction: np.ndarray
    current_cmd: np.ndarray
    current_meas: np.ndarray
    torque: np.ndarray
    position_meas: np.ndarray
    counts: np.ndarray = field(repr=False)

    @classmethod
    def empty(cls, n: int) -> PlantOutput:
        return cls(**{name: np.empty(n, np.float64) for name in OUTPUT_UNITS if name != "counts"},
                   counts=np.empty(n, np.int64))

    @classmethod
    def concatenate(cls, parts: Sequence[PlantOutput]) -> PlantOutput:
        return cls(**{name: np.concatenate([getattr(p, name) for p in parts]) for name in OUTPUT_UNITS})

    def as_dict(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name in OUTPUT_UNITS}


def _finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise PlantParameterError(f"{name} must be finite, got {value}")
    return value


def _non_negative(name: str, value: float, allow_inf: bool = False) -> float:
    value = float(value)
    if math.isnan(value) or value < 0 or (math.isinf(value) and not allow_inf):
        raise PlantParameterError(f"{name} must be >= 0{'' if allow_inf else ' and finite'}, got {value}")
    return value


def _table(name: str, table) -> tuple[np.ndarray, np.ndarray] | None:
    if table is None:
        return None
    x = np.ascontiguousarray(table[0], dtype=np.float64)
    f = np.ascontiguousarray(table[1], dtype=np.float64)
    if x.ndim != 1 or x.shape != f.shape or x.size < 2:
        raise PlantParameterError(f"{name} needs two 1-D arrays of equal length >= 2")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(f))):
        raise PlantParameterError(f"{name} contains NaN or inf")
    if x[0] != 0.0 or np.any(np.diff(x) <= 0):
        raise PlantParameterError(f"{name} grid must start at 0 and increase strictly")
    if f[0] != 0.0:
        raise PlantParameterError(f"{name} must be 0 at 0 (it is extended as an odd function)")
    return x, f


def _max_slope(table: tuple[np.ndarray, np.ndarray] | None) -> float:
    if table is None:
        return 0.0
    return float(np.max(np.abs(np.diff(table[1]) / np.diff(table[0]))))


def stiffest_eigenvalue(params: PlantParams) -> float:
    """Largest |lambda| (1/s) of the linearised mechanics with every element sticking:
    J*s^2 + B*s + K = 0 with K = spring + sum(k_i) + cogging and table slopes, B = max viscous + damping slope."""
    J = params.inertia
    K = params.spring + float(np.sum(params.ms_stiffness))
    K += sum(abs(c.amplitude * c.order) for c in params.cogging)
    K += _max_slope(_table("restoring_table", params.restoring_table))
    viscous_neg = params.viscous if params.viscous_neg is None else params.viscous_neg
    B = max(params.viscous, viscous_neg) + _max_slope(_table("damping_table", params.damping_table))
    # state-variable models, linearised at rest: LuGre sigma0 and sigma1*dz/dt (slope up to 2*sigma1 in
    # sliding, since |sigma0*z| <= g), GMS sum(k_i), the hysteresis' initial slope 2h/d
    if params.lugre is not None:
        K += params.lugre.sigma0
        B += 2.0 * params.lugre.sigma1 + params.lugre.sigma2
    if params.gms is not None:
        K += float(np.sum(params.gms.stiffness))
        B += params.gms.viscous
    if params.hysteresis is not None:
        K += 2.0 * params.hysteresis.h / params.hysteresis.d
    # s^2 + (B/J) s + K/J, as numpy.roots normalises [J, B, K] (the same companion matrix, bit for bit); an inertia
    # so small that B/J or K/J overflow (1e-308 kg*m^2 in a model file) is refused here in one line, not as a
    # LinAlgError from the eigenvalue solver
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        b, k = B / J, K / J
    if not (math.isfinite(b) and math.isfinite(k)):
        raise PlantParameterError(f"inertia {J:g} is too small for the model's damping {B:g} and stiffness {K:g}: "
                                  "its modes are infinitely fast")
    roots = np.roots([1.0, b, k]) if (B > 0 or K > 0) else np.zeros(1)
    return float(np.max(np.abs(roots)))


def _positive(name: str, value: float, allow_inf: bool = False) -> float:
    value = _non_negative(name, value, allow_inf)
    if value == 0:
        raise PlantParameterError(f"{name} must be > 0, got {value}")
    return value


def _stribeck(name: str, model) -> None:
    _positive(f"{name}.coulomb", model.coulomb)
    if model.static is not None:
        _positive(f"{name}.static", model.static)
    _non_negative(f"{name}.stribeck_velocity", model.stribeck_velocity)
    _positive(f"{name}.exponent", model.exponent)


def validate_models(params: PlantParams) -> None:
    """Raise :class:`PlantParameterError` for a bad LuGre, GMS or hysteresis parameter."""
    for name, kind in _MODEL_TYPES.items():
        model = getattr(params, name)
        if model is not None and not isinstance(model, kind):
            raise PlantParameterError(f"{name} must be {kind.__name__} or None, got {type(model).__name__}")
    if params.lugre is not None:
        lg = params.lugre
        _positive("lugre.sigma0", lg.sigma0)
        _non_negative("lugre.sigma1", lg.sigma1)
        _non_negative("lugre.sigma2", lg.sigma2)
        _stribeck("lugre", lg)
    if params.gms is not None:
        g = params.gms
        k = np.asarray(g.stiffness, float)
        a = np.asarray(g.fractions, float)
        if k.ndim != 1 or k.shape != a.shape or not 1 <= k.size <= MAX_GMS_ELEMENTS:
            raise PlantParameterError(
                f"gms.stiffness and gms.fractions must be 1-D of equal length 1..{MAX_GMS_ELEMENTS}")
        if not (np.all(np.isfinite(k)) and np.all(np.isfinite(a)) and np.all(k > 0) and np.all(a > 0)):
            raise PlantParameterError("gms.stiffness and gms.fractions must be > 0 and finite")
        _positive("gms.attraction", g.attraction, allow_inf=True)
        _non_negative("gms.viscous", g.viscous)
        _stribeck("gms", g)
    if params.hysteresis is not None:
        hy = params.hysteresis
        _positive("hysteresis.h", hy.h)
        _positive("hysteresis.d", hy.d)
        if int(hy.stack) != hy.stack or not 3 <= hy.stack <= MAX_STACK:
            raise PlantParameterError(f"hysteresis.stack must be an integer in 3..{MAX_STACK}, got {hy.stack}")


def validate(params: PlantParams, dt: float, substeps: int = 1, mode: str = "current") -> None:
    """Raise :class:`PlantParameterError` for any parameter the C engine must not see."""
    if not isinstance(params, PlantParams):
        raise PlantParameterError(f"params must be PlantParams, got {type(params).__name__}")
    J = float(params.inertia)
    if not (math.isfinite(J) and J > 0):
        raise PlantParameterError(f"inertia must be > 0 and finite, got {params.inertia}")
    k = np.asarray(params.ms_stiffness, float)
    w = np.asarray(params.ms_slip, float)
    if k.ndim != 1 or k.shape != w.shape:
        raise PlantParameterError(
            f"ms_stiffness and ms_slip must be 1-D of equal length, got {k.shape} and {w.shape}"
        )
    if k.size > MAX_ELEMENTS:
        raise PlantParameterError(f"{k.size} Maxwell-slip elements is above the limit of {MAX_ELEMENTS}")
    if not (np.all(np.isfinite(k)) and np.all(np.isfinite(w))):
        raise PlantParameterError("Maxwell-slip parameters contain NaN or inf")
    if np.any(k <= 0):
        i = int(np.argmax(k <= 0))
        raise PlantParameterError(f"ms_stiffness[{i}] = {k[i]}: element stiffness must be > 0")
    if np.any(w <= 0):
        i = int(np.argmax(w <= 0))
        raise PlantParameterError(f"ms_slip[{i}] = W_{i} = {w[i]}: slip force must be > 0")
    for name in ("spring", "viscous", "coulomb", "stribeck_velocity", "current_lag", "noise_current",
                 "noise_position", "velocity_kp", "velocity_ki"):
        _non_negative(name, getattr(params, name))
    for name in ("viscous_neg", "coulomb_neg", "static"):
        if getattr(params, name) is not None:
            _non_negative(name, getattr(params, name))
    if params.static is not None:
        fc_min = min(params.coulomb, params.coulomb if params.coulomb_neg is None else params.coulomb_neg)
        if params.static < fc_min:
            raise PlantParameterError(f"static friction {params.static} is below Coulomb {fc_min}")
        if params.stribeck_velocity <= 0:
            raise PlantParameterError("Stribeck needs stribeck_velocity > 0 when static is set")
    _non_negative("current_limit", params.current_limit, allow_inf=True)
    if params.current_limit == 0:
        raise PlantParameterError("current_limit must be > 0")
    for name in ("torque_offset", "torque_drift", "torque_constant_error"):
        _finite(name, getattr(params, name))
    kt = _finite("torque_constant", params.torque_constant)
    if kt <= 0:
        raise PlantParameterError(f"torque_constant must be > 0, got {kt}")
    if 1.0 + params.torque_constant_error <= 0:
        raise PlantParameterError("torque_constant_error must be > -1")
    if not (0 <= int(params.delay_samples) <= MAX_DELAY_SAMPLES) or int(params.delay_samples) != params.delay_samples:
        raise PlantParameterError(f"delay_samples must be an integer in 0..{MAX_DELAY_SAMPLES}")
    if int(params.counts_per_rev) != params.counts_per_rev or params.counts_per_rev < 0:
        raise PlantParameterError("counts_per_rev must be an integer >= 0")
    if not (0 <= int(params.seed) < 2**64):
        raise PlantParameterError("seed must be an integer in [0, 2**64)")
    for c in params.cogging:
        if not isinstance(c, Cogging):
            raise PlantParameterError("cogging entries must be Cogging(order, amplitude, phase)")
        for name in ("order", "amplitude", "phase"):
            _finite(f"cogging {name}", getattr(c, name))
        if c.order <= 0:
            raise PlantParameterError(f"cogging order must be > 0, got {c.order}")
    _table("restoring_table", params.restoring_table)
    _table("damping_table", params.damping_table)
    validate_models(params)
    if mode not in MODES:
        raise PlantParameterError(f"mode must be one of {sorted(MODES)}, got {mode!r}")
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0):
        raise PlantParameterError(f"dt must be > 0 and finite, got {dt}")
    if int(substeps) != substeps or substeps < 1:
        raise PlantParameterError(f"substeps must be an integer >= 1, got {substeps}")
    h = dt / substeps
    lam = stiffest_eigenvalue(params)
    if lam * h > RK4_STABLE_RADIUS:
        need = math.ceil(lam * dt / RK4_STABLE_RADIUS)
        while lam * dt / need > RK4_STABLE_RADIUS:  # guard the rounding of the division
            need += 1
        raise PlantParameterError(
            f"unstable step: |lambda|*h = {lam * h:.3g} > {RK4_STABLE_RADIUS} for the stiffest mode "
            f"({lam:.4g} 1/s); use substeps >= {need} or a smaller dt"
        )


class _CParams:
    """Keeps the numpy buffers alive for as long as the C struct points into them."""

    def __init__(self, params: PlantParams):
        p = params
        self.buffers = []
        self.struct = ffi.new("hb_params *")
        s = self.struct
        s.n_elements = p.n_elements
        s.ms_stiffness = self._ptr(p.ms_stiffness)
        s.ms_delta = self._ptr(p.ms_delta if p.n_elements else ())
        s.inertia = p.inertia
        s.spring = p.spring
        s.viscous_pos = p.viscous
        s.viscous_neg = p.viscous if p.viscous_neg is None else p.viscous_neg
        s.coulomb_pos = p.coulomb
        s.coulomb_neg = p.coulomb if p.coulomb_neg is None else p.coulomb_neg
        s.stribeck_excess = 0.0 if p.static is None else p.static - p.coulomb
        s.stribeck_velocity = p.stribeck_velocity if p.static is not None else 0.0
        s.torque_constant = p.torque_constant
        s.torque_constant_error = p.torque_constant_error
        s.torque_offset = p.torque_offset
        s.torque_drift = p.torque_drift
        s.n_cogging = len(p.cogging)
        s.cogging_order = self._ptr([c.order for c in p.cogging])
        s.cogging_amplitude = self._ptr([c.amplitude for c in p.cogging])
        s.cogging_phase = self._ptr([c.phase for c in p.cogging])
        s.delay_samples = int(p.delay_samples)
        s.current_lag = p.current_lag
        s.counts_per_rev = int(p.counts_per_rev)
        s.noise_current = p.noise_current
        s.noise_position = p.noise_position
        s.velocity_kp = p.velocity_kp
        s.velocity_ki = p.velocity_ki
        s.current_limit = p.current_limit
        for prefix, table, xname, fname in (
            ("restoring", p.restoring_table, "restoring_x", "restoring_f"),
            ("damping", p.damping_table, "damping_v", "damping_f"),
        ):
            t = _table(prefix, table)
            setattr(s, f"n_{prefix}", 0 if t is None else t[0].size)
            setattr(s, xname, self._ptr(() if t is None else t[0]))
            setattr(s, fname, self._ptr(() if t is None else t[1]))
        if p.lugre is not None:
            lg = p.lugre
            s.lugre = 1
            s.lg_sigma0, s.lg_sigma1, s.lg_sigma2 = lg.sigma0, lg.sigma1, lg.sigma2
            s.lg_coulomb = lg.coulomb
            s.lg_static = lg.coulomb if lg.static is None else lg.static
            s.lg_stribeck_velocity, s.lg_exponent = lg.stribeck_velocity, lg.exponent
        if p.gms is not None:
            g = p.gms
            s.gms_n = len(g.stiffness)
            s.gms_k = self._ptr(g.stiffness)
            s.gms_alpha = self._ptr(g.fractions)
            s.gms_attraction = g.attraction
            s.gms_coulomb = g.coulomb
            s.gms_static = g.coulomb if g.static is None else g.static
            s.gms_stribeck_velocity, s.gms_exponent, s.gms_sigma2 = g.stribeck_velocity, g.exponent, g.viscous
        if p.hysteresis is not None:
            s.hy_stack = int(p.hysteresis.stack)
            s.hy_h, s.hy_d = p.hysteresis.h, p.hysteresis.d

    def _ptr(self, values):
        arr = np.ascontiguousarray(values, dtype=np.float64)
        if arr.size == 0:
            return ffi.NULL
        self.buffers.append(arr)
        return ffi.cast("const double *", ffi.from_buffer(arr))


class Plant:
    """A stateful plant. ``run(u)`` processes a whole input array in one C call; consecutive calls continue
    from the state the previous one left, so a run split into blocks is bit-identical to one call.

    Args:
        params: physical parameters and injected effects.
        dt: sample period (s); each input sample is held for ``dt``.
        substeps: RK4 sub-steps per sample (see the stability limit in docs/plant.md).
        mode: ``"current"`` (u is the current command, A) or ``"velocity"`` (u is the velocity command,
            rad/s, tracked by the built-in PI loop).
        theta0, omega0: initial angle (rad) and velocity (rad/s); element deflections start at zero.
    """

    def __init__(self, params: PlantParams, dt: float, substeps: int = 1, mode: str = "current",
                 theta0: float = 0.0, omega0: float = 0.0):
        validate(params, dt, substeps, mode)
        _finite("theta0", theta0)
        _finite("omega0", omega0)
        self.params = params
        self.dt = float(dt)
        self.substeps = int(substeps)
        self._mode = mode
        self._c = _CParams(params)
        self._state = ffi.new("hb_state *")
        self._loop = ffi.new("hb_position_loop *")  # run_position's loop, its velocity estimate kept between calls
        lib.hb_state_init(self._state, self._c.struct, float(theta0), float(omega0), int(params.seed))

    @property
    def mode(self) -> str:
        return self._mode

    @mode.setter
    def mode(self, value: str) -> None:
        if value not in MODES:
            raise PlantParameterError(f"mode must be one of {sorted(MODES)}, got {value!r}")
        self._mode = value

    @property
    def theta(self) -> float:
        return float(self._state.theta)

    @property
    def omega(self) -> float:
        return float(self._state.omega)

    @property
    def time(self) -> float:
        return float(self._state.time)

    @property
    def deflections(self) -> np.ndarray:
        """Maxwell-slip spring deflections delta_i (rad), a copy."""
        out = np.empty(self.params.n_elements)
        if out.size:
            lib.hb_deflections(self._c.struct, self._state, ffi.cast("double *", ffi.from_buffer(out)))
        return out

    def set_deflections(self, values: np.ndarray) -> None:
        """Set the Maxwell-slip spring deflections delta_i (rad), shape (n_elements,), e.g. from
        ``stop_operator`` of a measured path; each is clipped to its slip displacement +-Delta_i."""
        v = np.asarray(values, dtype=float)
        if v.shape != (self.params.n_elements,):
            raise PlantParameterError(f"deflections must have shape ({self.params.n_elements},), got {v.shape}")
        if not np.all(np.isfinite(v)):
            raise PlantParameterError("deflections must be finite")
        v = np.clip(v, -self.params.ms_delta, self.params.ms_delta)
        self._state.ms_offset = 0.0
        for i, value in enumerate(v):
            self._state.deflection[i] = float(value)

    @property
    def hysteresis_stack(self) -> dict[str, int]:
        """Reversal stack of the continuous hysteresis: ``depth`` (points held now), ``depth_max`` (most ever
        held) and ``dropped`` (reversals forgotten because the stack was full)."""
        s = self._state
        return {"depth": int(s.hy_m), "depth_max": int(s.hy_depth_max), "dropped": int(s.hy_dropped)}

    def friction_path(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Friction (N*m) along an imposed motion: positions ``x`` (rad) and velocities ``v`` (rad/s), shape (n,),
        one sample every ``dt``, the path linear between samples. Continues from the plant's state (the first
        sample moves the plant to x[0] without committing the step). See docs/plant.md."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        v = np.ascontiguousarray(v, dtype=np.float64)
        if x.ndim != 1 or x.shape != v.shape:
            raise PlantParameterError(f"x and v must be 1-D of equal length, got {x.shape} and {v.shape}")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(v))):
            raise PlantParameterError("x or v contains NaN or inf")
        out = np.empty(x.size)
        lib.hb_friction_path(self._c.struct, self._state, ffi.cast("const double *", ffi.from_buffer(x)),
                             ffi.cast("const double *", ffi.from_buffer(v)), x.size, self.dt,
                             ffi.cast("double *", ffi.from_buffer(out)))
        return out

    def get_state(self) -> bytes:
        """The complete state (mechanics, effects, generator) as bytes."""
        return bytes(ffi.buffer(self._state))

    def set_state(self, state: bytes) -> None:
        if len(state) != ffi.sizeof("hb_state"):
            raise PlantParameterError(f"state must be {ffi.sizeof('hb_state')} bytes, got {len(state)}")
        ffi.memmove(self._state, state, len(state))
        if self._state.n_elements != self.params.n_elements:
            raise PlantParameterError("state was saved from a plant with a different number of elements")

    def run(self, u: np.ndarray) -> PlantOutput:
        """Simulate ``len(u)`` samples. Returns per-sample outputs (timing: docs/architecture.md)."""
        u = np.ascontiguousarray(u, dtype=np.float64)
        if u.ndim != 1:
            raise PlantParameterError(f"input must be 1-D, got shape {u.shape}")
        if not np.all(np.isfinite(u)):
            bad = int(np.argmax(~np.isfinite(u)))
            raise PlantParameterError(f"input contains NaN or inf (first at sample {bad})")
        return self._run(lambda c_u, c_out: lib.hb_run(self._c.struct, self._state, c_u, u.size, self.dt,
                                                       self.substeps, MODES[self._mode], c_out), u)

    def run_position(self, target: np.ndarray, kp: float, kd: float, velocity: float = 0.0,
                     feedforward: float = 0.0, torque_limit: float = math.inf, pll_hz: float = 0.0,
                     ki: float = 0.0, ilimit: float = 0.0) -> PlantOutput:
        """Simulate ``len(target)`` samples with a position PID loop closed at every sample (at 1/dt), as a drive
        closes it inside its controller (moteus's): ``e = target[k] - pos[k]``, ``I = clip(I + ki*e*dt,
        +-ilimit)``, ``torque = kp*e + I + kd*(velocity - v[k]) + feedforward`` clipped to +-``torque_limit``,
        then ``current = torque/torque_constant`` clipped to the current limit. ``pos`` is the measured
        (quantised, noisy) position; ``v`` its backward difference over one sample, or with ``pll_hz`` > 0 the
        estimate of a critically damped second-order tracking loop of that natural frequency (Hz) on ``pos`` (an
        encoder PLL, as moteus's). ``I`` and the estimate are kept by this plant from one call to the next and
        restart (I = 0) after the plant ran otherwise (plant.h, ``hb_position_loop``). A NaN ``target`` turns the
        proportional and integral terms off (I held). Units: target rad, kp N*m/rad, ki N*m/(rad*s), ilimit N*m,
        kd N*m*s/rad, velocity rad/s, feedforward N*m. ``current_cmd`` of the outputs is the loop's current."""
        target = np.ascontiguousarray(target, dtype=np.float64)
        if target.ndim != 1:
            raise PlantParameterError(f"target must be 1-D, got shape {target.shape}")
        if np.any(np.isinf(target)):
            raise PlantParameterError(f"target contains inf (first at sample {int(np.argmax(np.isinf(target)))})")
        for name, value in (("kp", kp), ("kd", kd), ("pll_hz", pll_hz), ("ki", ki), ("ilimit", ilimit)):
            _non_negative(name, value)
        _finite("velocity", velocity)
        _finite("feedforward", feedforward)
        _positive("torque_limit", torque_limit, allow_inf=True)
        if pll_hz * self.dt > 0.1:  # 2w*dt <= 1.26: the estimator's discrete loop well inside its stable range
            raise PlantParameterError(f"pll_hz must be at most 0.1/dt = {0.1 / self.dt:g} Hz, got {pll_hz:g}")
        loop = self._loop
        loop.kp, loop.kd, loop.velocity, loop.feedforward = kp, kd, velocity, feedforward
        loop.torque_limit, loop.pll_hz, loop.ki, loop.ilimit = torque_limit, pll_hz, ki, ilimit
        return self._run(lambda c_u, c_out: lib.hb_run_position(self._c.struct, self._state, loop, c_u,
                                                                target.size, self.dt, self.substeps, c_out), target)

    def _run(self, call, u: np.ndarray) -> PlantOutput:
        """``call(input pointer, hb_outputs pointer)`` into outputs of ``u.size`` samples."""
        out = PlantOutput.empty(u.size)
        c_out = ffi.new("hb_outputs *")
        for name in OUTPUT_UNITS:
            ctype = "int64_t *" if name == "counts" else "double *"
            setattr(c_out, name, ffi.cast(ctype, ffi.from_buffer(getattr(out, name))))
        rc = call(ffi.cast("const double *", ffi.from_buffer(u)), c_out)
        if rc != 0:
            raise FloatingPointError("plant state became non-finite; check parameters and input size")
        return out


def simulate(params: PlantParams, u: np.ndarray, dt: float, substeps: int = 1, mode: str = "current",
             theta0: float = 0.0, omega0: float = 0.0) -> PlantOutput:
    """Simulate ``u`` from rest (or ``theta0``, ``omega0``) in one C call. See :class:`Plant`."""
    return Plant(params, dt, substeps, mode, theta0, omega0).run(u)


def stop_operator(x: np.ndarray, deltas: np.ndarray, initial: np.ndarray | None = None) -> np.ndarray:
    """Stop (play) operator deflections S_Delta[x] for every threshold.

    ``d_j[0] = initial_j`` (zeros by default) and ``d_j[i] = clip(d_j[i-1] + x[i] - x[i-1], -Delta_j, Delta_j)``.
    The Maxwell-slip force is then ``sum_j k_j * d_j``, linear in the k_j (science.md §1).

    Args:
        x: path, shape (n,), rad.
        deltas: thresholds Delta_j > 0, shape (m,), rad.
        initial: deflections at x[0], shape (m,), rad.
    Returns:
        array (n, m) of deflections, rad.
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    d = np.ascontiguousarray(deltas, dtype=np.float64)
    if x.ndim != 1 or d.ndim != 1:
        raise PlantParameterError("stop_operator needs 1-D x and deltas")
    if not np.all(np.isfinite(x)):
        raise PlantParameterError("stop_operator: x contains NaN or inf")
    if d.size and not np.all((d > 0) & np.isfinite(d)):
        raise PlantParameterError("stop_operator: every threshold must be > 0 and finite")
    state = np.zeros(d.size) if initial is None else np.array(initial, dtype=np.float64).copy()
    if state.shape != d.shape:
        raise PlantParameterError("stop_operator: initial must have the shape of deltas")
    state = np.clip(state, -d, d)
    out = np.empty((x.size, d.size), dtype=np.float64)
    if x.size and d.size:
        lib.hb_stop_operator(ffi.cast("const double *", ffi.from_buffer(x)), x.size,
                             ffi.cast("const double *", ffi.from_buffer(d)), d.size,
                             ffi.cast("double *", ffi.from_buffer(state)),
                             ffi.cast("double *", ffi.from_buffer(out)))
    return out
