"""Output-error (simulation-error) evaluation and refinement with the C engine (firmware_sim.engine.plant).

The model is driven open-loop by the measured torque, held over each sample (the plant's input
convention; hilbench.analysis.identification.regressors.held_torque converts other timings), from the measured initial
position, a filtered initial velocity and relaxed elements (zero deflections). The simulation error
is theta_meas - theta_sim; its figure is NRMSE = rms(error)/std(theta_meas).

Refinement minimises that error with scipy.optimize.least_squares over log J, log k_i, log Delta_i
(and b, Fc, c0 when present), starting from a given model (normally the NNLS fit).
"""

from __future__ import annotations

import math

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.identification.regressors import held_torque, zero_phase_lowpass
from hilbench.analysis.models.friction_model import FrictionModel
from hilbench.common.metrics import RunningNrmse, nrmse

#: Stop-operator values held at once by segmented_simulation_error (16 MiB of float64).
CHUNK_VALUES = 1 << 21
#: Samples per call of the C plant in simulate_position.
SIM_BLOCK = 1 << 16
#: More sub-steps per sample than this means a broken model, not a stiff plant (the C engine takes an int).
MAX_SUBSTEPS = 100_000


def stable_substeps(model: FrictionModel, dt: float) -> int:
    """RK4 sub-steps that keep |lambda|*h at 80 % of the engine's stability radius."""
    from hilbench.firmware_sim.engine.plant import RK4_STABLE_RADIUS, stiffest_eigenvalue

    try:
        lam = stiffest_eigenvalue(model.plant_params())
    except ValueError as exc:
        raise AnalysisError(f"model cannot be simulated: {exc}") from None
    sub = max(1, math.ceil(lam * dt / (0.8 * RK4_STABLE_RADIUS)))
    if sub > MAX_SUBSTEPS:
        raise AnalysisError(
            f"model cannot be simulated: its stiffest mode ({lam:.3g} 1/s) needs {sub} RK4 sub-steps per sample "
            f"(limit {MAX_SUBSTEPS}); an element is implausibly stiff"
        )
    return sub


def initial_velocity(position: np.ndarray, fs: float) -> float:
    """Velocity at the first sample from a zero-phase low-pass (fs/20) of the first samples, rad/s."""
    x = np.asarray(position, float)[: max(64, int(fs / 5))]
    if x.size < 8:
        return 0.0
    xf = zero_phase_lowpass(x, fs, min(fs / 20.0, 0.45 * fs))
    return float((xf[1] - xf[0]) * fs)


def simulate_position(
    model: FrictionModel,
    torque: np.ndarray,
    fs: float,
    *,
    timing: str = "hold_next",
    theta0: float = 0.0,
    omega0: float = 0.0,
    substeps: int | None = None,
) -> np.ndarray:
    """Simulated position theta_sim[k] (rad or m), shape (n,), of the model under the torque record."""
    from hilbench.firmware_sim.engine.plant import Plant, PlantParameterError

    dt = 1.0 / fs
    u = held_torque(torque, timing)
    theta = np.empty(u.size)
    try:
        sub = substeps or stable_substeps(model, dt)
        plant = Plant(model.plant_params(), dt, sub, theta0=theta0, omega0=omega0)
        # in blocks, keeping the angle only: one call would hold all eight output channels (64 bytes per
        # sample); consecutive runs continue from the plant's state, bit for bit the same as one call
        for k0 in range(0, u.size, SIM_BLOCK):
            theta[k0 : k0 + SIM_BLOCK] = plant.run(u[k0 : k0 + SIM_BLOCK]).theta
    except (PlantParameterError, FloatingPointError) as exc:
        raise AnalysisError(f"model cannot be simulated: {exc}") from None
    return theta


def simulation_error(
    model: FrictionModel,
    position: np.ndarray,
    torque: np.ndarray,
    fs: float,
    *,
    timing: str = "hold_next",
) -> tuple[float, np.ndarray]:
    """(NRMSE of position, simulated position) for a run started from its first sample."""
    x = np.asarray(position, float)
    sim = simulate_position(
        model, torque, fs, timing=timing, theta0=float(x[0]), omega0=initial_velocity(x, fs)
    )
    return nrmse(x, sim), sim


def path_deflections(position: np.ndarray, deltas: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Stop-operator deflections S_Delta_j[x](k) of the path from relaxed elements, at the sample ``indices``
    (increasing), shape (len(indices), len(deltas)), in the units of x. Evaluated in chunks of at most
    ``CHUNK_VALUES`` values: the full (n, N) array of a long record would not fit in memory."""
    from hilbench.firmware_sim.engine.plant import stop_operator

    x = np.asarray(position, float)
    d = np.asarray(deltas, float)
    idx = np.asarray(indices, dtype=np.int64)
    out = np.empty((idx.size, d.size))
    if d.size == 0 or idx.size == 0:
        return out
    chunk = max(1, CHUNK_VALUES // d.size)
    state = None
    for c0 in range(0, int(idx[-1]) + 1, chunk):
        lo = max(c0 - 1, 0)  # one sample of overlap: the chunk continues from the deflection at x[c0-1]
        s_op = stop_operator(x[lo : c0 + chunk], d, initial=state)[c0 - lo :]
        state = s_op[-1]
        inside = (idx >= c0) & (idx < c0 + chunk)
        out[inside] = s_op[idx[inside] - c0]
    return out


def segmented_simulation_error(
    model: FrictionModel,
    position: np.ndarray,
    torque: np.ndarray,
    fs: float,
    *,
    timing: str = "hold_next",
    segment: float = 1.0,
) -> tuple[float, np.ndarray]:
    """(NRMSE of position, simulated position) with the simulation restarted every ``segment`` seconds from the
    measured state.

    An open-loop simulation of a drive without a spring integrates the torque-measurement noise into a random
    walk in position, so its error over a long record varies several-fold between noise realisations even
    for the true model (docs/model-file.md). Restarting from the measured state bounds that accumulation
    while every segment is still a free-run simulation. The state at a segment start k0 is: position
    x[k0]; velocity from the zero-phase low-pass (fs/20) of the whole record, differentiated; element
    deflections S_Delta_i[x](k0), the stop operators of the measured path from relaxed elements (the
    Maxwell-slip state is a function of the path alone). NRMSE = rms(x - sim)/std(x) over the whole record.
    """
    from hilbench.firmware_sim.engine.plant import Plant, PlantParameterError

    x = np.asarray(position, float)
    if not segment > 0:
        raise AnalysisError(f"segment must be positive, got {segment} s")
    dt = 1.0 / fs
    n_seg = max(2, int(round(segment * fs)))
    params = model.plant_params()
    u = held_torque(torque, timing) / params.torque_constant
    xf = zero_phase_lowpass(x, fs, min(fs / 20.0, 0.45 * fs))
    v = np.gradient(xf, dt)
    starts = np.arange(0, x.size, n_seg)
    deflections = path_deflections(x, params.ms_delta, starts) if params.n_elements else None
    sim = np.empty_like(x)
    try:
        sub = stable_substeps(model, dt)
        for j, k0 in enumerate(starts):
            plant = Plant(params, dt, sub, theta0=float(x[k0]), omega0=float(v[k0]))
            if deflections is not None:
                plant.set_deflections(deflections[j])
            sim[k0 : k0 + n_seg] = plant.run(u[k0 : k0 + n_seg]).theta
    except (PlantParameterError, FloatingPointError) as exc:
        raise AnalysisError(f"model cannot be simulated: {exc}") from None
    return nrmse(x, sim), sim


class _Packing:
    """Map a model to and from the optimiser's vector (logs for the positive scale parameters)."""

    def __init__(self, model: FrictionModel):
        self.template = model
        self.n = model.ms_stiffness.size
        self.use_b = model.viscous > 0
        self.use_fc = model.coulomb > 0
        self.use_c0 = model.offset != 0.0
        self.scale_c0 = max(abs(model.offset), 1e-12)

    def pack(self, m: FrictionModel) -> np.ndarray:
        v = [np.log(m.inertia), *np.log(m.ms_stiffness), *np.log(m.ms_delta)]
        if self.use_b:
            v.append(np.log(m.viscous))
        if self.use_fc:
            v.append(np.log(m.coulomb))
        if self.use_c0:
            v.append(m.offset / self.scale_c0)
        return np.asarray(v, float)

    def unpack(self, v: np.ndarray) -> FrictionModel:
        n = self.n
        i = 1 + 2 * n
        t = self.template
        b = np.exp(v[i]) if self.use_b else t.viscous
        i += int(self.use_b)
        fc = np.exp(v[i]) if self.use_fc else t.coulomb
        i += int(self.use_fc)
        c0 = v[i] * self.scale_c0 if self.use_c0 else t.offset
        return FrictionModel(
            axis=t.axis,
            inertia=float(np.exp(v[0])),
            ms_stiffness=np.exp(v[1 : 1 + n]),
            ms_delta=np.exp(v[1 + n : 1 + 2 * n]),
            viscous=float(b),
            coulomb=float(fc),
            offset=float(c0),
            spring=t.spring,
        )


def refine_output_error(
    model: FrictionModel,
    position: np.ndarray,
    torque: np.ndarray,
    fs: float,
    *,
    timing: str = "hold_next",
    max_nfev: int = 200,
) -> tuple[FrictionModel, dict]:
    """Least-squares refinement of every parameter on the simulation error, from ``model``.

    Returns the refined model (standard errors from the Jacobian at the optimum, sigma^2 (J^T J)^-1,
    inflated by n/n_eff like the NNLS ones) and a dict of figures (nrmse before/after, nfev).
    """
    from scipy.optimize import least_squares

    from hilbench.analysis.identification.regressors import effective_sample_count

    x = np.asarray(position, float)
    omega0 = initial_velocity(x, fs)
    pk = _Packing(model)
    scale = float(np.std(x)) or 1.0
    sub = stable_substeps(model, 1.0 / fs) * 2  # room for stiffer elements during the search

    def residual(v: np.ndarray) -> np.ndarray:
        m = pk.unpack(v)
        try:
            sim = simulate_position(
                m,
                torque,
                fs,
                timing=timing,
                theta0=float(x[0]),
                omega0=omega0,
                substeps=max(sub, stable_substeps(m, 1.0 / fs)),
            )
        except AnalysisError:
            return np.full(x.size, 1e3)
        return (sim - x) / scale

    v0 = pk.pack(model)
    before = float(np.sqrt(np.mean(residual(v0) ** 2)) * scale / np.std(x))
    sol = least_squares(residual, v0, method="trf", x_scale=1.0, diff_step=1e-4, max_nfev=max_nfev)
    refined = pk.unpack(sol.x)
    r = sol.fun
    n, p = r.size, sol.x.size
    s2 = float(r @ r) / max(1, n - p)
    infl = max(1.0, n / effective_sample_count(r))
    cov_v = np.linalg.pinv(sol.jac.T @ sol.jac) * s2 * infl
    se_v = np.sqrt(np.clip(np.diag(cov_v), 0, None))
    nn = pk.n
    refined.std_errors = {
        "inertia": float(refined.inertia * se_v[0]),  # d exp(u) = exp(u) du
        "ms_stiffness": refined.ms_stiffness * se_v[1 : 1 + nn],
        "ms_delta": refined.ms_delta * se_v[1 + nn : 1 + 2 * nn],
    }
    i = 1 + 2 * nn
    if pk.use_b:
        refined.std_errors["viscous"] = float(refined.viscous * se_v[i])
        i += 1
    if pk.use_fc:
        refined.std_errors["coulomb"] = float(refined.coulomb * se_v[i])
        i += 1
    if pk.use_c0:
        refined.std_errors["offset"] = float(pk.scale_c0 * se_v[i])
    after = float(np.sqrt(np.mean(r**2)) * scale / np.std(x))
    return refined, {"position_nrmse_before": before, "position_nrmse_after": after, "nfev": int(sol.nfev)}


def simulation_error_chunks(model: FrictionModel, source, fs: float, *, timing: str = "hold_next") -> float:
    """:func:`simulation_error` (the NRMSE) on a record read chunk by chunk (``chunked``): the plant runs block by
    block from its own state, so the simulation is the one-call simulation bit for bit; nothing of the record's
    length is kept."""
    from hilbench.analysis.identification.chunked import BLOCK, windows
    from hilbench.firmware_sim.engine.plant import Plant, PlantParameterError

    dt = 1.0 / fs
    spread = RunningNrmse()
    plant = None
    try:
        sub = stable_substeps(model, dt)
        for w in windows(source, BLOCK, 2):  # one sample ahead: a held torque may be the next sample's
            if plant is None:
                plant = Plant(model.plant_params(), dt, sub, theta0=float(w.x[0]),
                              omega0=initial_velocity(w.x, fs))
            u = held_torque(w.tau, timing)[w.a - w.wa : w.b - w.wa]
            x = w.x[w.a - w.wa : w.b - w.wa]
            spread.add(x, x - plant.run(u).theta)
    except (PlantParameterError, FloatingPointError) as exc:
        raise AnalysisError(f"model cannot be simulated: {exc}") from None
    return spread.nrmse()


def segmented_simulation_error_chunks(model: FrictionModel, source, fs: float, *, timing: str = "hold_next",
                                      segment: float = 1.0) -> float:
    """:func:`segmented_simulation_error` (the NRMSE) on a record read chunk by chunk. Blocks are whole segments;
    each window reaches the filter's margin beyond its block, so the restart velocity is the whole-record
    low-pass's to e^-40 of its start-up transient, and the deflections are the stop operator carried exactly."""
    from hilbench.analysis.identification.chunked import BLOCK, StopCarry, default_margin, windows
    from hilbench.firmware_sim.engine.plant import Plant, PlantParameterError

    if not segment > 0:
        raise AnalysisError(f"segment must be positive, got {segment} s")
    dt = 1.0 / fs
    n_seg = max(2, int(round(segment * fs)))
    cutoff = min(fs / 20.0, 0.45 * fs)
    margin = default_margin(fs, cutoff)
    block = max(1, -(-max(BLOCK, 2 * margin) // n_seg)) * n_seg  # whole segments, at least 2 margins
    params = model.plant_params()
    carry = StopCarry(params.ms_delta, margin) if params.n_elements else None
    spread = RunningNrmse()
    try:
        sub = stable_substeps(model, dt)
        for w in windows(source, block, margin):
            lo, hi = w.a - w.wa, w.b - w.wa
            xf = zero_phase_lowpass(w.x, fs, cutoff)
            v = np.gradient(xf, dt) if xf.size > 1 else np.zeros_like(xf)
            u = held_torque(w.tau, timing) / params.torque_constant
            s = carry.window(w) if carry is not None else None
            sim = np.empty(hi - lo)
            for k0 in range(lo, hi, n_seg):
                plant = Plant(params, dt, sub, theta0=float(w.x[k0]), omega0=float(v[k0]))
                if s is not None:
                    plant.set_deflections(s[k0])
                sim[k0 - lo : k0 - lo + n_seg] = plant.run(u[k0 : min(k0 + n_seg, hi)]).theta
            spread.add(w.x[lo:hi], w.x[lo:hi] - sim)
    except (PlantParameterError, FloatingPointError) as exc:
        raise AnalysisError(f"model cannot be simulated: {exc}") from None
    return spread.nrmse()


class _Autocorrelation:
    """Residual sums for ``regressors.effective_sample_count`` over a record read in blocks: sum r, the lagged
    products sum r_i*r_(i+k) for k < max_lag, and the first and last max_lag values (for the mean's terms)."""

    def __init__(self, max_lag: int = 200):
        self.max_lag = max_lag
        self.n = 0
        self.total = 0.0
        self.lagged = np.zeros(max_lag)
        self.head = np.empty(0)
        self.tail = np.empty(0)

    def add(self, r: np.ndarray) -> None:
        joined = np.concatenate([self.tail, r])
        t = self.tail.size
        for k in range(min(self.max_lag, joined.size)):
            # products whose later factor is in this block: i + k >= t
            lo = max(t - k, 0)
            self.lagged[k] += float(joined[lo : joined.size - k] @ joined[lo + k :])
        self.n += r.size
        self.total += float(np.sum(r))
        if self.head.size < self.max_lag:
            self.head = np.concatenate([self.head, r[: self.max_lag - self.head.size]])
        self.tail = joined[-self.max_lag :]

    def n_eff(self) -> float:
        """n / (1 + 2*sum rho_k), summed up to the first lag with rho_k <= 0 (as effective_sample_count)."""
        n = self.n
        m = self.total / n if n else 0.0
        denom = self.lagged[0] - n * m * m
        if n < 3 or denom <= 0:
            return float(n)
        acc = 0.0
        for k in range(1, min(self.max_lag, n - 1)):
            a = self.total - float(np.sum(self.tail[self.tail.size - k :])) if k else self.total
            b = self.total - float(np.sum(self.head[:k]))
            rho = (self.lagged[k] - m * (a + b) + (n - k) * m * m) / denom
            if rho <= 0:
                break
            acc += rho
        return float(n / (1.0 + 2.0 * acc))


def refine_output_error_chunks(model: FrictionModel, source, fs: float, *, timing: str = "hold_next",
                               max_iterations: int = 20, tolerance: float = 1e-8) -> tuple[FrictionModel, dict]:
    """:func:`refine_output_error` on a record read chunk by chunk (``chunked``), in memory bounded by the block.

    Levenberg-Marquardt on the same parameters (``_Packing``) and the same residual, (theta_sim - theta)/std(theta)
    of the open-loop simulation from the first sample. Each pass runs the plant of the current parameters and
    one per parameter step (forward differences, step 1e-4 in the packed values) through the record block by
    block, every plant from its own state, and accumulates J^T J, J^T r and r^T r; a trial step is one more pass.
    Standard errors are sigma^2 (J^T J)^-1, inflated by n/n_eff as in the array version (the residual's
    autocorrelation accumulated block by block)."""
    from hilbench.analysis.identification.chunked import BLOCK, windows
    from hilbench.firmware_sim.engine.plant import Plant, PlantParameterError

    dt = 1.0 / fs
    pk = _Packing(model)
    base_sub = stable_substeps(model, dt) * 2  # room for stiffer elements during the search
    first = next(iter(windows(source, BLOCK, 2)), None)
    if first is None:
        raise AnalysisError("the record is empty")
    theta0, omega0 = float(first.x[0]), initial_velocity(first.x, fs)
    spread = RunningNrmse()
    for w in windows(source, BLOCK, 2):
        xs = w.x[w.a - w.wa : w.b - w.wa]
        spread.add(xs, xs)
    scale = float(np.sqrt(spread.s2 / spread.n - (spread.s1 / spread.n) ** 2)) or 1.0

    def sweep(vectors: list[np.ndarray], steps: np.ndarray | None = None, corr: _Autocorrelation | None = None):
        """r^T r of vectors[0]; with ``steps``, also J^T J and J^T r from the others (vectors[0] + step_i e_i)."""
        try:
            plants = []
            for v in vectors:
                m = pk.unpack(v)
                plants.append(Plant(m.plant_params(), dt, max(base_sub, stable_substeps(m, dt)), theta0=theta0,
                                    omega0=omega0))
        except (AnalysisError, PlantParameterError, FloatingPointError):
            return math.inf, None, None
        p = len(vectors) - 1
        jtj, jtr, rtr = np.zeros((p, p)), np.zeros(p), 0.0
        try:
            for w in windows(source, BLOCK, 2):
                u = held_torque(w.tau, timing)[w.a - w.wa : w.b - w.wa]
                xs = w.x[w.a - w.wa : w.b - w.wa]
                sims = [pl.run(u).theta for pl in plants]
                r = (sims[0] - xs) / scale
                if not np.all(np.isfinite(r)):
                    return math.inf, None, None
                rtr += float(r @ r)
                if corr is not None:
                    corr.add(r)
                if p:
                    jac = np.column_stack([(s - sims[0]) / (scale * h) for s, h in zip(sims[1:], steps, strict=True)])
                    jtj += jac.T @ jac
                    jtr += jac.T @ r
        except (PlantParameterError, FloatingPointError):
            return math.inf, None, None
        return rtr, jtj, jtr

    def linearise(v: np.ndarray, corr: _Autocorrelation | None = None):
        steps = 1e-4 * np.maximum(1.0, np.abs(v))
        return sweep([v, *(v + h * e for h, e in zip(steps, np.eye(v.size), strict=True))], steps, corr)

    v = pk.pack(model)
    cost, jtj, jtr = linearise(v)
    if not math.isfinite(cost):
        raise AnalysisError("model cannot be simulated from its start")
    before = cost
    lam = 1e-3
    passes = v.size + 1
    for _ in range(max_iterations):
        d = np.diag(jtj).copy()
        d[d == 0] = 1.0
        improved = False
        while lam < 1e12:
            step = np.linalg.solve(jtj + lam * np.diag(d), -jtr)
            trial, _, _ = sweep([v + step])
            passes += 1
            if trial < cost:
                improved = True
                break
            lam *= 4.0
        if not improved:
            break
        v = v + step
        lam = max(lam / 3.0, 1e-12)
        done = cost - trial <= tolerance * cost
        cost, jtj, jtr = linearise(v)
        passes += v.size + 1
        if done:
            break
    corr = _Autocorrelation()
    cost, jtj, jtr = linearise(v, corr)
    refined = pk.unpack(v)
    n, p = corr.n, v.size
    s2 = cost / max(1, n - p)
    infl = max(1.0, n / corr.n_eff())
    se_v = np.sqrt(np.clip(np.diag(np.linalg.pinv(jtj) * s2 * infl), 0, None))
    nn = pk.n
    refined.std_errors = {"inertia": float(refined.inertia * se_v[0]),
                          "ms_stiffness": refined.ms_stiffness * se_v[1 : 1 + nn],
                          "ms_delta": refined.ms_delta * se_v[1 + nn : 1 + 2 * nn]}
    i = 1 + 2 * nn
    if pk.use_b:
        refined.std_errors["viscous"] = float(refined.viscous * se_v[i])
        i += 1
    if pk.use_fc:
        refined.std_errors["coulomb"] = float(refined.coulomb * se_v[i])
        i += 1
    if pk.use_c0:
        refined.std_errors["offset"] = float(pk.scale_c0 * se_v[i])
    norm = float(np.sqrt(n)) if n else 1.0
    return refined, {"position_nrmse_before": float(np.sqrt(before)) / norm,
                     "position_nrmse_after": float(np.sqrt(cost)) / norm, "passes": passes}
