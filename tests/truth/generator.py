"""An independent truth generator for the residual loop: friction systems integrated by scipy's ODE
solvers from band-limited inputs, sharing no code with ``hilbench.firmware_sim`` or ``hilbench.analysis``.

Torque-driven records (rotary: rad, N*m, kg*m^2):

    J_m*theta_m'' = tau_a(t) - F(state) - tau_cog(theta_m) - c0 - c1*t - tau_belt        (motor)
    J_l*theta_l'' = tau_belt,  tau_belt = k_b*dz(theta_m - theta_l) + c_b*(omega_m - omega_l)  (belt, optional)
    T_c*tau_a' = tau(t) - tau_a                                         (first-order current loop, optional)

dz is the backlash dead zone (half gap g/2). The input tau(t) is a continuous multisine (band-limited,
no sample-and-hold) times a three-term square-wave envelope; the record holds tau(t_k) (instant
timing) with current-sensor noise and ADC quantisation, and the encoder-quantised motor angle.

Friction families F (all state-based, so sticking needs no switching logic):

- ``maxwell``: N elastoplastic elements (stiffness k_i, slip force W_i), z_i' = v unless saturated, plus b*v;
- ``lugre``: z' = v - |v|*z*sigma0/g(v), F = sigma0*z + sigma1*z' + b*v, g(v) = Fc + (Fs - Fc)*exp(-|v/vs|^delta);
- ``dahl``: F' = sigma*(v - |v|*F/Fc) (exponent 1), plus b*v;
- ``gms``: N elements, stick F_i' = k_i*v while F_i*sign(v) < alpha_i*s(v), else slip
  F_i' = C*(alpha_i*s(v)*sign(v) - F_i); s(v) the Stribeck curve g(v); plus b*v.

Effects: Stribeck (any exponent; LuGre/GMS use their own g, Maxwell-slip/Dahl scale the level by g/Fc),
direction asymmetry (level x (1 + a*sign(v))), angle-modulated level (x (1 + m*sin(k*theta + phi))), cogging
(a non-sinusoidal profile: fundamental plus a 2nd harmonic of a third of its amplitude), constant and
drifting load, belt compliance, backlash, current-loop lag.

Displacement-driven records (linear: m, N): the displacement x(t) is imposed, the force is the friction
of the Maxwell-slip element set (exact stop operators: the path is monotonic between samples) or the ODE of the other
families along x(t), recorded with noise and quantisation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import integrate

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class Truth:
    """One true system (rotary units). Zero/None switches an effect off."""

    family: str = "maxwell"
    inertia: float = 0.0022  # kg*m^2 (motor)
    coulomb: float = 0.6  # N*m, kinetic level Fc
    viscous: float = 0.004  # N*m*s/rad
    presliding: float = 0.6e-3  # rad, characteristic presliding distance (largest Maxwell-slip element)
    n_elements: int = 40
    stribeck_excess: float = 0.0  # N*m, Fs - Fc
    stribeck_velocity: float = 2.0  # rad/s
    stribeck_exponent: float = 2.0
    asymmetry: float = 0.0  # relative: level x (1 + asymmetry*sign(v))
    angle_level: tuple[float, float, float] | None = None  # (order, relative depth m, phase)
    level_slope: float = 0.0  # relative level change per unit position: level x (1 + level_slope*theta)
    stroke: float | None = None  # rad: a position loop keeps the motor within +-stroke/2 (see simulate_torque_driven)
    stroke_period: float = 2.5  # s, period of the position loop's sine reference across the stroke
    axis: str = "rotary"  # units of the record: "linear" reads the same numbers as m, N, kg
    cogging: tuple[float, float, float] | None = None  # (order, amplitude N*m, phase)
    offset: float = 0.0  # N*m constant load c0
    drift: float = 0.0  # N*m/s load drift c1
    current_lag: float = 0.0  # s, first-order time constant T_c
    belt: tuple[float, float, float] | None = None  # (k_b N*m/rad, c_b N*m*s/rad, J_l kg*m^2)
    backlash: float = 0.0  # rad, total gap (needs belt)
    gms_rate: float = 2000.0  # 1/s, GMS slip relaxation C / level
    counts_per_rev: int = 20000
    torque_noise: float = 0.004  # N*m rms on the recorded torque
    torque_lsb: float = 10.0 / 2048  # N*m, 12-bit ADC over +-10 N*m
    effects: frozenset = field(default_factory=frozenset)  # the truth's effects in library names

    def with_(self, **kw) -> Truth:
        return replace(self, **kw)


def elements(total: float, presliding: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(k_i, W_i): n elements on the virgin curve F(x) = total*(1 - (1 - x/presliding)^2) for
    x <= presliding (a parabolic rolling-friction curve), breakpoints uniform in x^(1/2)."""
    d = presliding * (np.arange(1, n + 1) / n) ** 2
    f = total * (1 - (1 - d / presliding) ** 2)
    slope = np.diff(np.concatenate([[0.0], f])) / np.diff(np.concatenate([[0.0], d]))
    k = slope - np.concatenate([slope[1:], [0.0]])
    return k, k * d


def virgin_curve(k: np.ndarray, w: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Maxwell-slip virgin curve sum_i min(k_i*x, W_i), x >= 0."""
    return np.minimum(np.outer(x, k), w[None, :]).sum(axis=1)


def stribeck_curve(tr: Truth, v: np.ndarray | float) -> np.ndarray | float:
    """g(v) = Fc + (Fs - Fc)*exp(-|v/vs|^delta), N*m."""
    return tr.coulomb + tr.stribeck_excess * np.exp(-np.abs(np.asarray(v) / tr.stribeck_velocity)
                                                    ** tr.stribeck_exponent)


def multisine(seed: int, duration: float, amplitude: float = 5.0, f_lo: float = 0.3, f_hi: float = 25.0,
              n_lines: int = 40, period: float = 5.0):
    """A band-limited torque input u(t), N*m: random-phase multisine on [f_lo, f_hi] Hz normalised to unit
    peak, times the envelope (4/pi)(sin wt + sin 3wt/3 + sin 5wt/5). Returns a vectorised callable."""
    rng = np.random.default_rng(seed)
    f = np.sort(rng.uniform(f_lo, f_hi, n_lines))
    ph = rng.uniform(0, TWO_PI, n_lines)
    a = 1.0 / np.sqrt(f / f_lo)  # pink-ish: more low-frequency motion
    tt = np.linspace(0, duration, int(duration * 2000))
    peak = np.max(np.abs(np.sin(np.outer(tt, TWO_PI * f) + ph) @ a))
    w = TWO_PI / period

    def u(t):
        t = np.asarray(t, float)
        env = 4 / np.pi * (np.sin(w * t) + np.sin(3 * w * t) / 3 + np.sin(5 * w * t) / 5)
        return amplitude * env * (np.sin(np.multiply.outer(t, TWO_PI * f) + ph) @ a) / peak
    return u


class _Friction:
    """Friction of one family. ``lugre`` and ``dahl`` are smooth ODEs (``rate``: F and dz/dt from the state);
    ``maxwell`` and ``gms`` are element sets stepped along the path (``step``: element update over a fine
    fixed step, exact for the Maxwell-slip stop operators)."""

    def __init__(self, tr: Truth):
        self.tr = tr
        fam = tr.family
        if fam in ("maxwell", "gms"):
            self.k, self.w = elements(tr.coulomb, tr.presliding, tr.n_elements)
            self.d = self.w / self.k
            self.n = tr.n_elements
        elif fam in ("lugre", "dahl"):
            self.n = 1
            self.sigma0 = 2.0 * tr.coulomb / tr.presliding  # initial slope: F reaches ~Fc at the presliding distance
            self.sigma1 = 2.0 * math.sqrt(self.sigma0 * tr.inertia) * 0.3  # 30 % of critical damping
        else:
            raise ValueError(f"unknown friction family {fam!r}")

    def level(self, v: float, theta: float) -> float:
        """The friction level g(v) (N*m) with direction asymmetry and angle modulation."""
        tr = self.tr
        g = tr.coulomb
        if tr.stribeck_excess:
            g += tr.stribeck_excess * math.exp(-abs(v / tr.stribeck_velocity) ** tr.stribeck_exponent)
        if tr.asymmetry:
            g *= 1.0 + tr.asymmetry * (1.0 if v > 0 else -1.0 if v < 0 else 0.0)
        if tr.angle_level is not None:
            order, depth, phase = tr.angle_level
            g *= 1.0 + depth * math.sin(order * theta + phase)
        if tr.level_slope:
            g *= 1.0 + tr.level_slope * theta
        return g

    def rate(self, z: float, v: float, theta: float) -> tuple[float, float]:
        """(F, dz/dt) of the smooth families (z: LuGre bristle deflection, rad; Dahl: the force, N*m)."""
        g = self.level(v, theta)
        if self.tr.family == "lugre":
            dz = v - abs(v) * self.sigma0 * z / g
            return self.sigma0 * z + self.sigma1 * dz + self.tr.viscous * v, dz
        df = self.sigma0 * (v - abs(v) * z / g)  # Dahl, exponent 1
        return z + self.tr.viscous * v, df

    def step(self, z: np.ndarray, dtheta: float, v: float, theta: float, h: float) -> float:
        """Advance the elements in place over a step h (path increment dtheta) and return F (N*m)."""
        scale = self.level(v, theta) / self.tr.coulomb
        if self.tr.family == "maxwell":  # z: element deflections; force k_i*z_i scaled by the level
            np.clip(z + dtheta, -self.d, self.d, out=z)
            return scale * float(self.k @ z) + self.tr.viscous * v
        cap = self.w * scale  # gms: z holds the element forces; stick k_i*dtheta, slip relaxes to the cap
        sv = 1.0 if v > 0 else -1.0 if v < 0 else 0.0
        slip = z * sv >= cap
        # a sticking element that reaches its cap within the step slides on it from there (the stick phase ends
        # at the cap): without the clip it overshot by up to k_i*v*h whenever the cap rose along the motion (a
        # level growing along the travel), a direction-dependent excess of 20-64 mN at 0.5-4 m/s (issue 29)
        stuck = z + self.k * dtheta
        stick = np.where(stuck * sv > cap, cap * sv, stuck)
        z[:] = np.where(slip, z + self.tr.gms_rate * h * (cap * sv - z), stick)
        return float(z.sum()) + self.tr.viscous * v


@dataclass
class Record:
    """A sampled record: t (s), position (rad or m), torque (N*m or N), fs (Hz), the truth."""

    t: np.ndarray
    position: np.ndarray
    torque: np.ndarray
    fs: float
    truth: Truth
    position_true: np.ndarray | None = None
    torque_true: np.ndarray | None = None
    kind: str = "torque-driven"


class _Body:
    """Motor (+ belt and load, + current loop): the accelerations from the state and the friction torque."""

    def __init__(self, tr: Truth):
        self.tr = tr
        self.half_gap = tr.backlash / 2

    def load(self, theta: float, t: float) -> float:
        tr = self.tr
        out = tr.offset + tr.drift * t
        if tr.cogging is not None:
            order, amp, phase = tr.cogging
            out += amp * (math.sin(order * theta + phase) + math.sin(2 * order * theta + 2 * phase) / 3)
        return out

    def belt(self, th: float, om: float, thl: float, oml: float) -> float:
        kb, cb, _ = self.tr.belt
        rel = th - thl
        if self.half_gap:
            rel = rel - min(max(rel, -self.half_gap), self.half_gap)
            return kb * rel + (cb * (om - oml) if rel != 0 else 0.0)
        return kb * rel + cb * (om - oml)


STROKE_BANDWIDTH = 10.0  # Hz, the position loop of a stroke-limited record
STROKE_DITHER = 0.8  # N*m, peak of the multisine added to the position loop's torque


def position_loop(tr: Truth):
    """(kp N*m/rad, kd N*m*s/rad, reference x_r(t) rad) of the stroke-limited record: a PD loop of bandwidth
    STROKE_BANDWIDTH (damping 0.7) on the motor inertia, tracking (stroke/2)*sin(2 pi t/stroke_period)."""
    w = TWO_PI * STROKE_BANDWIDTH
    kp, kd = tr.inertia * w * w, 2 * 0.7 * tr.inertia * w
    half, wr = tr.stroke / 2, TWO_PI / tr.stroke_period
    return kp, kd, (lambda t: half * np.sin(wr * np.asarray(t, float)))


def simulate_torque_driven(tr: Truth, seed: int, duration: float = 10.0, fs: float = 1000.0,
                           amplitude: float = 2.5, substeps: int = 10, rtol: float = 1e-7,
                           torque=None) -> Record:
    """The record of ``tr`` under the multisine of ``seed``, sampled at fs (Hz).

    LuGre and Dahl: LSODA (scipy.integrate.odeint, max step 1/(4 fs)). Maxwell-slip and GMS (element sets
    whose laws switch): fine fixed step h = 1/(substeps*fs), semi-implicit Euler for the bodies, the
    elements stepped along the path; the current loop is discretised exactly over h. ``torque``: a
    vectorised callable u(t) (N*m) replacing the multisine.

    ``tr.stroke``: the torque command is kp*(x_r(t) - theta) - kd*omega + the multisine scaled to a peak of
    STROKE_DITHER (:func:`position_loop`, a continuous-time loop on the true state), so the motor sweeps
    about +-stroke/2 back and forth; the record holds that command (what a bench's current loop receives)."""
    if tr.stroke is not None:
        amplitude = STROKE_DITHER
    u = torque if torque is not None else multisine(seed, duration, amplitude)
    if tr.stroke is not None:
        kp, kd, ref = position_loop(tr)

        def feedback(t, th, om):
            return kp * (ref(t) - th) - kd * om
    else:
        def feedback(t, th, om):
            return 0.0 * th
    grid_dt = 1.0 / 20000.0  # the input on a 20 kHz grid, linearly interpolated (band limit 25 Hz: error < 1e-5)
    u_grid = u(np.arange(int(duration / grid_dt) + 2) * grid_dt)

    def u_at(t):
        i = min(int(t / grid_dt), u_grid.size - 2)
        a = t / grid_dt - i
        return (1 - a) * u_grid[i] + a * u_grid[i + 1]

    fr, body = _Friction(tr), _Body(tr)
    belt, lag = tr.belt is not None, tr.current_lag > 0
    n = int(round(duration * fs))
    t = np.arange(n) / fs
    if tr.family in ("lugre", "dahl"):
        i_fr = 2 + (2 if belt else 0) + (1 if lag else 0)

        def rhs(tt, y):
            th, om = y[0], y[1]
            tau = y[i_fr - 1] if lag else u_at(tt) + feedback(tt, th, om)
            f, dz = fr.rate(y[i_fr], om, th)
            load = body.load(th, tt)
            out = np.empty_like(y)
            out[0] = om
            if belt:
                tb = body.belt(th, om, y[2], y[3])
                out[2], out[3] = y[3], tb / tr.belt[2]
                load += tb
            out[1] = (tau - f - load) / tr.inertia
            if lag:
                out[i_fr - 1] = (u_at(tt) + feedback(tt, th, om) - tau) / tr.current_lag
            out[i_fr] = dz
            return out

        y, info = integrate.odeint(rhs, np.zeros(i_fr + 1), t, rtol=rtol, atol=1e-10, hmax=0.25 / fs,
                                   mxstep=200_000, tfirst=True, full_output=True)
        if info["message"] != "Integration successful.":
            raise RuntimeError(f"truth integration failed: {info['message']}")
        theta = y[:, 0]
        command = u(t) + feedback(t, theta, y[:, 1])
    else:
        h = 1.0 / (fs * substeps)
        z = np.zeros(fr.n)
        th = om = thl = oml = tau_a = 0.0
        f = 0.0
        decay = math.exp(-h / tr.current_lag) if lag else 0.0
        theta = np.empty(n)
        command = np.empty(n)
        for i in range(n * substeps):
            tt = i * h
            uu = u_at(tt) + feedback(tt, th, om)
            if i % substeps == 0:
                theta[i // substeps] = th
                command[i // substeps] = uu
            tau = tau_a if lag else uu
            load = body.load(th, tt)
            if belt:
                tb = body.belt(th, om, thl, oml)
                oml += h * tb / tr.belt[2]
                thl += h * oml
                load += tb
            om += h * (tau - f - load) / tr.inertia
            th += h * om
            f = fr.step(z, h * om, om, th, h)
            if lag:
                tau_a = uu + (tau_a - uu) * decay
    rng = np.random.default_rng(10_000 + seed)
    step = TWO_PI / tr.counts_per_rev
    pos = np.floor(theta / step + 0.5) * step
    if tr.stroke is None:
        command = u(t)  # exact at the samples (the loop above used the 20 kHz interpolant)
    tau_rec = command + tr.torque_noise * rng.standard_normal(t.size)
    tau_rec = np.round(tau_rec / tr.torque_lsb) * tr.torque_lsb
    return Record(t, pos, tau_rec, fs, tr, theta, command)


def stop_operator_forces(k: np.ndarray, w: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Exact Maxwell-slip force sum_i k_i*z_i along a path x (each z_i the stop operator of width W_i/k_i,
    starting relaxed); on a sampled path this is exact for the piecewise-linear interpolant."""
    d = w / k
    z = np.zeros(k.size)
    out = np.empty(x.size)
    prev = x[0]
    for i, xi in enumerate(x):
        z = np.clip(z + (xi - prev), -d, d)
        prev = xi
        out[i] = k @ z
    return out


def imposed_displacement(seed: int, duration: float, fs: float, stroke: float, reversals: int) -> np.ndarray:
    """A band-limited displacement, m: a smooth random walk of turning points with amplitudes between 10 %
    and 100 % of half the stroke (nested minor loops), ``reversals`` reversals, cosine segments."""
    rng = np.random.default_rng(seed)
    n = int(round(duration * fs))
    half = stroke / 2
    turning = [0.0]
    for i in range(reversals):
        sgn = 1 if i % 2 == 0 else -1
        turning.append(sgn * half * rng.uniform(0.1, 1.0))
    turning[1] = half  # the first stroke is the virgin curve to the full half stroke
    seg = np.linspace(0, n, reversals + 1).astype(int)
    x = np.empty(n)
    for j in range(reversals):
        m = seg[j + 1] - seg[j]
        s = 0.5 * (1 - np.cos(np.pi * np.arange(m) / m))
        x[seg[j]:seg[j + 1]] = turning[j] + (turning[j + 1] - turning[j]) * s
    return x


def displacement_driven(seed: int, *, duration: float = 100.0, fs: float = 200.0, stroke: float = 0.24e-3,
                        reversals: int = 100, breakaway: float = 40.0, presliding: float = 0.1e-3,
                        n_elements: int = 40, force_noise: float = 0.05, force_lsb: float = 0.01,
                        position_lsb: float = 0.05e-6) -> tuple[Record, np.ndarray, np.ndarray]:
    """A tribometer record (linear: m, N): force of a Maxwell-slip element set (``n_elements``, break-away
    ``breakaway`` N over ``presliding`` m) against an imposed displacement, with force noise (N rms) and
    quantisation of force and displacement. Returns (record, k_i N/m, W_i N)."""
    k, w = elements(breakaway, presliding, n_elements)
    t = np.arange(int(round(duration * fs))) / fs
    x = imposed_displacement(seed, duration, fs, stroke, reversals)
    # exact: every turning point of the path lies on a sample, so the path is monotonic between samples and
    # the stop operators at the samples depend only on the sampled values
    f_true = stop_operator_forces(k, w, x)
    rng = np.random.default_rng(20_000 + seed)
    f = np.round((f_true + force_noise * rng.standard_normal(t.size)) / force_lsb) * force_lsb
    xq = np.round(x / position_lsb) * position_lsb
    tr = Truth(family="maxwell", coulomb=breakaway, presliding=presliding, n_elements=n_elements)
    return Record(t, xq, f, fs, tr, x, f_true, kind="displacement-driven"), k, w


def displacement_ode(tr: Truth, x: np.ndarray, fs: float) -> np.ndarray:
    """Friction force (N) along an imposed sampled displacement x (m) for the LuGre and Dahl families, by LSODA
    on the linearly interpolated path (the Maxwell-slip force is :func:`stop_operator_forces`)."""
    fr = _Friction(tr)
    t = np.arange(x.size) / fs
    v_seg = np.diff(x) * fs

    def rhs(tt, z):
        i = min(int(tt * fs), v_seg.size - 1)
        xx = x[i] + v_seg[i] * (tt - t[i])
        return [fr.rate(z[0], v_seg[i], xx)[1]]

    z = integrate.odeint(rhs, [0.0], t, rtol=1e-9, atol=1e-14, hmax=0.25 / fs, tfirst=True)[:, 0]
    return np.array([fr.rate(z[i], v_seg[min(i, v_seg.size - 1)], x[i])[0] for i in range(x.size)])
