"""A second independent record generator for the residual loop (issue 39), written for the purpose.

It shares no code with ``hilbench.firmware_sim`` (the plant), ``hilbench.analysis`` (the candidate library) or
``tests/truth/generator.py`` (the first independent generator): its own integrator (a fixed-step classical
Runge-Kutta of order 4 written here, with a scalar state so that it stays exact where the laws are smooth), its own
friction law (Bouc-Wen hysteresis, which is neither Maxwell-slip nor Masing, nor Dahl unless n = 1 and gamma = 0),
its own excitations and its own noise (coloured AR(1) force noise and a sensor quantum).

Bouc-Wen friction (rotary: rad, N*m; linear: m, N):

    F = L(x)*w + b*v,   w' = (v/delta)*(1 - |w|^n*(beta + gamma*sign(v*w))),   beta + gamma = 1

w in [-1, 1] is the hysteretic state (|w| -> 1 while sliding), delta the presliding distance, n the sharpness of
the transition (n = 2 here; Dahl is n = 1, gamma = 0), L(x) the friction level, which may follow the position:
L(x) = F_c*(1 + m*sin(x + phi)) for an eccentric preload once per revolution (rotary), or F_c*(1 + g*x) along a
linear axis. A friction level that follows the position scales the whole force (presliding included).

Records:

- ``displacement_record``: the force against an imposed displacement (a tribometer), linear axis, about 100
  reversals with nested minor loops, the train/validation split in halves of one record;
- ``torque_record``: a motor J*theta'' = tau(t - d) - F under a position loop (PD on the measured angle, run at the
  sample rate, its command held over the sample) tracking a slow sine across a stroke, plus a multisine dither;
  the record holds the command and the encoder angle. ``delay`` d is a pure transport delay of the applied torque
  (whole samples here: the command held over a sample reaches the motor d later).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BoucWen:
    """Bouc-Wen friction: level F_c (N*m or N), presliding distance delta (rad or m), exponent n, beta (gamma =
    1 - beta), viscous b; the level's position dependence: ``eccentric`` (relative depth m, phase phi) once per
    revolution, ``slope`` g per unit position."""

    coulomb: float = 0.6
    delta: float = 0.5e-3
    n: float = 2.0
    beta: float = 0.7
    viscous: float = 0.004
    eccentric: tuple[float, float] | None = None
    slope: float = 0.0

    def level(self, x: float) -> float:
        out = self.coulomb
        if self.eccentric is not None:
            m, phi = self.eccentric
            out *= 1.0 + m * np.sin(x + phi)
        return out * (1.0 + self.slope * x)

    def w_rate(self, w: float, v: float) -> float:
        s = 1.0 if v * w >= 0 else -1.0
        return v / self.delta * (1.0 - abs(w) ** self.n * (self.beta + (1.0 - self.beta) * s))

    def force(self, x: float, v: float, w: float) -> float:
        return self.level(x) * w + self.viscous * v


def rk4(rate, y0: np.ndarray, t0: float, h: float, steps: int) -> np.ndarray:
    """``steps`` classical Runge-Kutta 4 steps of y' = rate(t, y) from y0 at t0; the final state."""
    y = np.array(y0, float)
    t = t0
    for _ in range(steps):
        k1 = rate(t, y)
        k2 = rate(t + 0.5 * h, y + 0.5 * h * k1)
        k3 = rate(t + 0.5 * h, y + 0.5 * h * k2)
        k4 = rate(t + h, y + h * k3)
        y = y + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += h
    return y


def ar1_noise(rng: np.random.Generator, n: int, rms: float, pole: float = 0.6) -> np.ndarray:
    """Coloured sensor noise: AR(1) with the given pole, scaled to ``rms``."""
    e = rng.standard_normal(n) * np.sqrt(1 - pole**2)
    out = np.empty(n)
    acc = 0.0
    for i in range(n):
        acc = pole * acc + e[i]
        out[i] = acc
    return rms * out


def quantise(x: np.ndarray, lsb: float) -> np.ndarray:
    return lsb * np.round(x / lsb)


@dataclass
class Foreign:
    """A record: time (s), position (rad or m), torque or force, rate (Hz), the law, the axis, the truth's force."""

    t: np.ndarray
    position: np.ndarray
    torque: np.ndarray
    fs: float
    law: BoucWen
    axis: str
    kind: str
    friction: np.ndarray

    def half(self, which: int) -> Foreign:
        """The first (0) or second (1) half of the record."""
        n = self.t.size // 2
        sl = slice(0, n) if which == 0 else slice(n, 2 * n)
        return Foreign(self.t[sl], self.position[sl], self.torque[sl], self.fs, self.law, self.axis, self.kind,
                       self.friction[sl])


def _turning_path(rng: np.random.Generator, n: int, amplitude: float, reversals: int) -> np.ndarray:
    """A displacement through random turning points (20-100 % of ``amplitude`` on alternate sides, drifting centre),
    quintic smoothstep between them (zero speed and acceleration at each turning point)."""
    pts = [0.0]
    for i in range(reversals):
        side = 1.0 if i % 2 == 0 else -1.0
        pts.append(side * amplitude * rng.uniform(0.2, 1.0) + 0.15 * amplitude * rng.standard_normal())
    edges = np.round(np.linspace(0, n, reversals + 1)).astype(int)
    x = np.empty(n)
    for j in range(reversals):
        m = edges[j + 1] - edges[j]
        s = np.arange(m) / m
        x[edges[j]:edges[j + 1]] = pts[j] + (pts[j + 1] - pts[j]) * (10 * s**3 - 15 * s**4 + 6 * s**5)
    return x


def displacement_record(seed: int, law: BoucWen, *, duration: float = 100.0, fs: float = 200.0,
                        amplitude: float = 0.3e-3, reversals: int = 100, noise: float = 0.05, lsb: float = 0.01,
                        position_lsb: float = 0.02e-6, substeps: int = 8) -> Foreign:
    """Force (N) of ``law`` against an imposed displacement (m): RK4 on the hysteretic state along the path, the
    path's speed exact between samples (the quintic's derivative by finite differences of a finer grid)."""
    rng = np.random.default_rng(7000 + seed)
    n = int(round(duration * fs))
    x = _turning_path(rng, n, amplitude, reversals)
    t = np.arange(n) / fs
    v = np.gradient(x, 1.0 / fs)
    w = np.zeros(n)
    h = 1.0 / fs / substeps
    state = np.zeros(1)
    for i in range(n - 1):
        vi, dv = v[i], v[i + 1] - v[i]

        def rate(tt, y, vi=vi, dv=dv, t0=t[i]):
            return np.array([law.w_rate(y[0], vi + dv * (tt - t0) * fs)])

        state = rk4(rate, state, t[i], h, substeps)
        w[i + 1] = state[0]
    f_true = np.array([law.level(x[i]) * w[i] for i in range(n)]) + law.viscous * v
    f = quantise(f_true + ar1_noise(rng, n, noise), lsb)
    return Foreign(t, quantise(x, position_lsb), f, fs, law, "linear", "displacement-driven", f_true)


def torque_record(seed: int, law: BoucWen, *, stroke: float = 2.0, duration: float = 10.0, fs: float = 1000.0,
                  inertia: float = 0.0022, delay: int = 0, period: float = 2.5, dither: float = 0.8,
                  counts_per_rev: int = 2**18, noise: float = 0.004, lsb: float = 10.0 / 2048,
                  substeps: int = 10, axis: str = "rotary") -> Foreign:
    """A motor under a sampled position loop tracking (stroke/2)*sin(2*pi*t/period) plus a multisine dither
    (``dither`` N*m peak, 0.5-20 Hz), RK4 on (theta, omega, w) with the command held over each sample and applied
    ``delay`` samples late. Returns the recorded command (with noise and quantum) and the encoder angle."""
    rng = np.random.default_rng(9000 + seed)
    n = int(round(duration * fs))
    t = np.arange(n) / fs
    freqs = np.geomspace(0.5, 20.0, 25)
    phases = rng.uniform(0, 2 * np.pi, freqs.size)
    multi = np.sin(2 * np.pi * freqs[None, :] * t[:, None] + phases).sum(axis=1)
    multi *= dither / np.max(np.abs(multi))
    wn, zeta = 2 * np.pi * 15.0, 0.7
    kp, kd = inertia * wn**2, 2 * zeta * wn * inertia
    enc = 2 * np.pi / counts_per_rev
    state = np.zeros(3)  # theta, omega, w
    theta = np.zeros(n)
    friction = np.zeros(n)
    cmd = np.zeros(n)
    h = 1.0 / fs / substeps
    prev = 0.0
    for k in range(n):
        theta[k] = state[0]
        friction[k] = law.force(state[0], state[1], state[2])
        meas = quantise(np.array([state[0]]), enc)[0]
        ref = 0.5 * stroke * np.sin(2 * np.pi * t[k] / period)
        dref = 0.5 * stroke * 2 * np.pi / period * np.cos(2 * np.pi * t[k] / period)
        speed = (meas - prev) * fs if k else 0.0
        prev = meas
        cmd[k] = kp * (ref - meas) + kd * (dref - speed) + multi[k]
        applied = cmd[k - delay] if k >= delay else 0.0

        def rate(tt, y, applied=applied):
            return np.array([y[1], (applied - law.force(y[0], y[1], y[2])) / inertia, law.w_rate(y[2], y[1])])

        state = rk4(rate, state, t[k], h, substeps)
    if not np.all(np.isfinite(theta)):
        raise ValueError(f"RK4 unstable at {substeps} substeps per sample: raise substeps")
    tau = quantise(cmd + ar1_noise(rng, n, noise, pole=0.3), lsb)
    return Foreign(t, quantise(theta, enc), tau, fs, law, axis, "torque-driven", friction)
