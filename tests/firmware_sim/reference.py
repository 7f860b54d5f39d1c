"""Slow pure-Python twin of the C plant. A test oracle only: never used by the device or the analysis.

It performs the same floating-point operations in the same order as ``plant.c`` (which is built with
``-ffp-contract=off``), including the xoshiro256** generator and Box-Muller deviates, so the two agree
to rounding.
"""

from __future__ import annotations

import math

import numpy as np

from hilbench.firmware_sim.engine.plant import MODES, PlantOutput, PlantParams, validate

_MASK = (1 << 64) - 1
_TWO_PI = 6.283185307179586


def _splitmix64(x: int) -> tuple[int, int]:
    x = (x + 0x9E3779B97F4A7C15) & _MASK
    z = x
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK
    return x, z ^ (z >> 31)


def _rotl(x: int, k: int) -> int:
    return ((x << k) | (x >> (64 - k))) & _MASK


class ReferenceRng:
    """xoshiro256** seeded by splitmix64, with cached Box-Muller pairs (as in plant.c)."""

    def __init__(self, seed: int):
        x = seed & _MASK
        self.s = []
        for _ in range(4):
            x, z = _splitmix64(x)
            self.s.append(z)
        self.spare: float | None = None

    def next_u64(self) -> int:
        s = self.s
        result = (_rotl((s[1] * 5) & _MASK, 7) * 9) & _MASK
        t = (s[1] << 17) & _MASK
        s[2] ^= s[0]
        s[3] ^= s[1]
        s[1] ^= s[2]
        s[0] ^= s[3]
        s[2] ^= t
        s[3] = _rotl(s[3], 45)
        return result

    def normal(self) -> float:
        if self.spare is not None:
            z, self.spare = self.spare, None
            return z
        u1 = float((self.next_u64() >> 11) + 1) * 2.0**-53
        u2 = float(self.next_u64() >> 11) * 2.0**-53
        r = math.sqrt(-2.0 * math.log(u1))
        a = _TWO_PI * u2
        self.spare = r * math.sin(a)
        return r * math.cos(a)


def _clip(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else (hi if v > hi else v)


def _table_odd(x: float, gx: list[float], gf: list[float]) -> float:
    ax = abs(x)
    n = len(gx)
    if ax >= gx[n - 1]:
        f = gf[n - 1]
    else:
        lo, hi = 0, n - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if gx[mid] <= ax:
                lo = mid
            else:
                hi = mid
        w = (ax - gx[lo]) / (gx[hi] - gx[lo])
        f = gf[lo] + w * (gf[hi] - gf[lo])
    return -f if x < 0.0 else f


def _stribeck_curve(fc: float, fs: float, vs: float, delta: float, v: float) -> float:
    if vs <= 0.0 or fs == fc:
        return fc
    r = abs(v / vs)
    if delta == 2.0:
        e = r * r
    elif delta == 1.0:
        e = r
    else:
        try:
            e = r**delta
        except OverflowError:  # C's pow() returns inf here
            e = math.inf
    return fc + (fs - fc) * math.exp(-e)


class ReferenceModels:
    """LuGre, GMS and the continuous hysteresis, written from docs/plant.md ("Friction models") with the
    operation order of plant.c. The state is committed by :meth:`commit`; :meth:`force` only looks ahead."""

    def __init__(self, params: PlantParams):
        self.lugre = params.lugre
        self.gms = params.gms
        self.hy = params.hysteresis
        if self.lugre is not None:
            lg = self.lugre
            self.lg = (float(lg.sigma0), float(lg.sigma1), float(lg.sigma2), float(lg.coulomb),
                       float(lg.coulomb if lg.static is None else lg.static), float(lg.stribeck_velocity),
                       float(lg.exponent))
        self.z = 0.0
        if self.gms is not None:
            g = self.gms
            self.gk = [float(v) for v in g.stiffness]
            self.ga = [float(v) for v in g.fractions]
            self.gs = (float(g.coulomb), float(g.coulomb if g.static is None else g.static),
                       float(g.stribeck_velocity), float(g.exponent))
            self.gc = float(g.attraction)
            self.gf = [0.0] * len(self.gk)
            self.gslip = [0] * len(self.gk)
        self.hx = 0.0
        self.hdir = 0
        self.stack: list[tuple[float, float]] = []
        self.depth_max = 0
        self.dropped = 0

    @property
    def active(self) -> bool:
        return self.lugre is not None or self.gms is not None or self.hy is not None

    # LuGre
    def _g(self, v: float) -> float:
        s0, s1, s2, fc, fs, vs, delta = self.lg
        return _stribeck_curve(fc, fs, vs, delta, v)

    def _z(self, dx: float, g: float) -> float:
        s0 = self.lg[0]
        if dx == 0.0:
            return self.z
        zs = (g if dx > 0.0 else -g) / s0
        return zs + (self.z - zs) * math.exp(-(s0 * abs(dx) / g))

    # GMS
    def _element(self, i: int, dx: float, t: float, sv: float) -> tuple[float, int]:
        f0, slip0 = self.gf[i], self.gslip[i]
        if dx == 0.0:
            return f0, slip0
        direction = 1 if dx > 0.0 else -1
        cap = self.ga[i] * sv
        if slip0 == direction:
            target = cap if direction > 0 else -cap
            if math.isinf(self.gc):
                return target, slip0
            return target + (f0 - target) * math.exp(-(self.gc * t / cap)), slip0
        f = f0 + self.gk[i] * dx
        if f >= cap:
            return cap, 1
        if f <= -cap:
            return -cap, -1
        return f, 0

    # hysteresis
    def _phi(self, x: float) -> float:
        r = self.hy.d / (self.hy.d + abs(x))
        f = self.hy.h * (1.0 - r * r)
        return -f if x < 0.0 else f

    def _branch(self, stack: list[tuple[float, float]], x: float) -> float:
        if not stack:
            return self._phi(x)
        xr, fr = stack[-1]
        return fr + 2.0 * self._phi(0.5 * (x - xr))

    def _walk(self, dx: float) -> tuple[list[tuple[float, float]], int, bool]:
        """Stack after the monotone displacement dx, the depth reached, and whether a reversal was dropped."""
        stack = list(self.stack)
        depth, dropped = 0, False
        if dx == 0.0:
            return stack, depth, dropped
        direction = 1 if dx > 0.0 else -1
        if self.hdir != 0 and direction != self.hdir:
            f = self._branch(stack, self.hx)
            if len(stack) == self.hy.stack:
                del stack[-2:]
                dropped = True
            stack.append((self.hx, f))
            depth = len(stack)
        xe = self.hx + dx
        while stack:
            wipe = -stack[0][0] if len(stack) == 1 else stack[-2][0]
            if (xe - wipe) * direction < 0.0:
                break
            del stack[-2 if len(stack) > 1 else -1:]
        return stack, depth, dropped

    def force(self, dx: float, t: float, om: float) -> float:
        f = 0.0
        if self.lugre is not None:
            s0, s1, s2 = self.lg[:3]
            g = self._g(om)
            z = self._z(dx, g)
            zdot = om - s0 * abs(om) * z / g
            f += s0 * z + s1 * zdot + s2 * om
        if self.gms is not None:
            sv = _stribeck_curve(*self.gs, om)
            fg = 0.0
            for i in range(len(self.gk)):
                fg += self._element(i, dx, t, sv)[0]
            f += fg + float(self.gms.viscous) * om
        if self.hy is not None:
            stack = self._walk(dx)[0]
            f += self._branch(stack, self.hx + dx)
        return f

    def commit(self, dx: float, t: float, om: float) -> None:
        if self.lugre is not None:
            self.z = self._z(dx, self._g(om))
        if self.gms is not None:
            sv = _stribeck_curve(*self.gs, om)
            for i in range(len(self.gk)):
                self.gf[i], self.gslip[i] = self._element(i, dx, t, sv)
        if self.hy is not None and dx != 0.0:
            stack, depth, dropped = self._walk(dx)
            self.stack = stack
            self.depth_max = max(self.depth_max, depth)
            self.dropped += dropped
            self.hx += dx
            self.hdir = 1 if dx > 0.0 else -1


def _friction_terms(p: PlantParams) -> tuple:
    """Maxwell-slip k_i and Delta_i, viscous (+, -), Coulomb (+, -), Stribeck excess and velocity, as floats."""
    k = [float(v) for v in p.ms_stiffness]
    delta = [float(v) for v in p.ms_delta] if k else []
    vpos = float(p.viscous)
    vneg = vpos if p.viscous_neg is None else float(p.viscous_neg)
    fcp = float(p.coulomb)
    fcn = fcp if p.coulomb_neg is None else float(p.coulomb_neg)
    s_excess = 0.0 if p.static is None else p.static - p.coulomb
    s_vel = p.stribeck_velocity if p.static is not None else 0.0
    return k, delta, vpos, vneg, fcp, fcn, s_excess, s_vel


def reference_simulate(params: PlantParams, u, dt: float, substeps: int = 1, mode: str = "current",
                       theta0: float = 0.0, omega0: float = 0.0) -> PlantOutput:
    """Pure-Python simulation with the semantics of :func:`firmware_sim.engine.plant.simulate`."""
    validate(params, dt, substeps, mode)
    p = params
    k, delta, vpos, vneg, fcp, fcn, s_excess, s_vel = _friction_terms(p)
    defl = [0.0] * len(k)
    cog = [(float(c.order), float(c.amplitude), float(c.phase)) for c in p.cogging]
    rt = None if p.restoring_table is None else ([float(v) for v in p.restoring_table[0]],
                                                 [float(v) for v in p.restoring_table[1]])
    dtab = None if p.damping_table is None else ([float(v) for v in p.damping_table[0]],
                                                 [float(v) for v in p.damping_table[1]])
    J = float(p.inertia)
    rng = ReferenceRng(int(p.seed))
    theta, omega, time_, current = float(theta0), float(omega0), 0.0, 0.0
    prev_pos, has_prev, integral, coulomb_force = 0.0, False, 0.0, 0.0
    delay = [0.0] * int(p.delay_samples)
    delay_pos = 0
    h = dt / substeps
    kt_true = p.torque_constant * (1.0 + p.torque_constant_error)
    lag_a = math.exp(-dt / p.current_lag) if p.current_lag > 0.0 else 0.0
    lag_avg = p.current_lag / dt * (1.0 - lag_a) if p.current_lag > 0.0 else 0.0

    models = ReferenceModels(p)

    def smooth_force(th: float, om: float, th0: float, t: float) -> float:
        dx = th - th0
        f = 0.0
        for i in range(len(k)):
            f += k[i] * _clip(defl[i] + dx, -delta[i], delta[i])
        if models.active:
            f += models.force(dx, t, om)
        f += p.spring * th
        f += (vpos if om >= 0.0 else vneg) * om
        for order, amp, phase in cog:
            f += amp * math.sin(order * th + phase)
        if rt is not None:
            f += _table_odd(th, *rt)
        if dtab is not None:
            f += _table_odd(om, *dtab)
        return f

    dry = fcp > 0.0 or fcn > 0.0 or s_excess > 0.0

    def level(direction: float, om: float) -> float:
        lv = fcp if direction > 0.0 else fcn
        if s_vel > 0.0:
            r = om / s_vel
            lv += s_excess * math.exp(-(r * r))
        return lv

    def rk4(th: float, om: float, tau: float, direction: float, h: float = h) -> tuple[float, float]:
        def force(x: float, v: float, t: float) -> float:
            f = smooth_force(x, v, th, t)
            if direction != 0.0:
                f += direction * level(direction, v)
            return f

        k1x = om
        k1v = (tau - force(th, om, 0.0)) / J
        k2x = om + 0.5 * h * k1v
        k2v = (tau - force(th + 0.5 * h * k1x, k2x, 0.5 * h)) / J
        k3x = om + 0.5 * h * k2v
        k3v = (tau - force(th + 0.5 * h * k2x, k3x, 0.5 * h)) / J
        k4x = om + h * k3v
        k4v = (tau - force(th + h * k3x, k4x, h)) / J
        return (th + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x),
                om + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v))

    u = np.asarray(u, dtype=float)
    n = u.size
    out = PlantOutput.empty(n)
    for kk in range(n):
        i_meas = current
        if p.noise_current > 0.0:
            i_meas += p.noise_current * rng.normal()
        th_noisy = theta
        if p.noise_position > 0.0:
            th_noisy += p.noise_position * rng.normal()
        counts = 0
        if p.counts_per_rev > 0:
            cpr = float(p.counts_per_rev)
            counts = math.floor(th_noisy * cpr / _TWO_PI + 0.5)
            pos = float(counts) * _TWO_PI / cpr
        else:
            pos = th_noisy
        friction = 0.0
        for i in range(len(k)):
            friction += k[i] * defl[i]
        friction += (vpos if omega >= 0.0 else vneg) * omega
        friction += coulomb_force
        if rt is not None:
            friction += _table_odd(theta, *rt)
        if dtab is not None:
            friction += _table_odd(omega, *dtab)
        friction += models.force(0.0, 0.0, omega)

        if MODES[mode] == MODES["velocity"]:
            v_est = (pos - prev_pos) / dt if has_prev else 0.0
            err = float(u[kk]) - v_est
            new_integral = integral + err * dt
            i_cmd = p.velocity_kp * err + p.velocity_ki * new_integral
            if i_cmd > p.current_limit:
                i_cmd = p.current_limit
                if err < 0.0:
                    integral = new_integral
            elif i_cmd < -p.current_limit:
                i_cmd = -p.current_limit
                if err > 0.0:
                    integral = new_integral
            else:
                integral = new_integral
        else:
            i_cmd = _clip(float(u[kk]), -p.current_limit, p.current_limit)
        prev_pos, has_prev = pos, True

        i_del = i_cmd
        if delay:
            i_del = delay[delay_pos]
            delay[delay_pos] = i_cmd
            delay_pos = (delay_pos + 1) % len(delay)
        if p.current_lag > 0.0:
            i_avg = i_del + (current - i_del) * lag_avg
            current = i_del + (current - i_del) * lag_a
        else:
            i_avg = i_del
            current = i_del
        tau = kt_true * i_avg + p.torque_offset + p.torque_drift * time_

        out.theta[kk] = theta
        out.omega[kk] = omega
        out.friction[kk] = friction
        out.current_cmd[kk] = i_cmd
        out.current_meas[kk] = i_meas
        out.torque[kk] = tau
        out.position_meas[kk] = pos
        out.counts[kk] = counts

        for _ in range(substeps):
            th, om = theta, omega
            hs = h
            if not dry:
                th_new, om_new = rk4(th, om, tau, 0.0)
                coulomb_force = 0.0
            else:
                direction = 1.0 if om > 0.0 else (-1.0 if om < 0.0 else 0.0)
                sliding = False
                if direction != 0.0:
                    th_new, om_new = rk4(th, om, tau, direction)
                    sliding = om_new * direction > 0.0
                    if sliding:
                        coulomb_force = direction * level(direction, om_new)
                    else:
                        # zero velocity inside the step: slide to it, stop, decide on the rest (plant.c)
                        t1 = h * om / (om - om_new)
                        if 0.0 < t1 < h:
                            th1, _ = rk4(th, om, tau, direction, t1)
                            for i in range(len(k)):
                                defl[i] = _clip(defl[i] + th1 - th, -delta[i], delta[i])
                            if models.active:
                                models.commit(th1 - th, t1, 0.0)
                            th, om = th1, 0.0
                            coulomb_force = direction * level(direction, 0.0)
                            hs = h - t1
                if not sliding:
                    th_new, om_new = rk4(th, om, tau, 0.0, hs)
                    free_dir = 1.0 if om_new >= 0.0 else -1.0
                    dv = hs * level(free_dir, om) / J
                    om_free = om_new
                    om_new = 0.0 if abs(om_free) <= dv else om_free - free_dir * dv
                    th_new -= 0.5 * hs * (om_free - om_new)
                    coulomb_force = J * (om_free - om_new) / hs
            dx = th_new - th
            for i in range(len(k)):
                defl[i] = _clip(defl[i] + dx, -delta[i], delta[i])
            if models.active:
                models.commit(dx, hs, om_new)
            theta, omega = th_new, om_new
        time_ += dt
    return out


def reference_friction_path(params: PlantParams, x, v, dt: float) -> np.ndarray:
    """Pure-Python twin of :meth:`firmware_sim.engine.plant.Plant.friction_path` from rest, for Maxwell-slip, viscous,
    Coulomb/Stribeck and the state-variable models (no tables)."""
    p = params
    k, delta, vpos, vneg, fcp, fcn, s_excess, s_vel = _friction_terms(p)
    defl = [0.0] * len(k)
    models = ReferenceModels(p)
    x = np.asarray(x, float)
    v = np.asarray(v, float)
    out = np.empty(x.size)
    for kk in range(x.size):
        om = float(v[kk])
        if kk > 0:
            dx = float(x[kk] - x[kk - 1])
            for i in range(len(k)):
                defl[i] = _clip(defl[i] + dx, -delta[i], delta[i])
            models.commit(dx, dt, om)
        f = 0.0
        for i in range(len(k)):
            f += k[i] * defl[i]
        f += (vpos if om >= 0.0 else vneg) * om
        if om != 0.0:
            direction = 1.0 if om > 0.0 else -1.0
            lv = fcp if direction > 0.0 else fcn
            if s_vel > 0.0:
                r = om / s_vel
                lv += s_excess * math.exp(-(r * r))
            f += direction * lv
        f += models.force(0.0, 0.0, om)
        out[kk] = f
    return out


def reference_stop_operator(x, deltas, initial=None) -> np.ndarray:
    """Pure-Python stop operator with the semantics of :func:`firmware_sim.engine.plant.stop_operator`."""
    x = np.asarray(x, dtype=float)
    d = np.asarray(deltas, dtype=float)
    state = np.zeros(d.size) if initial is None else np.clip(np.asarray(initial, float), -d, d)
    out = np.empty((x.size, d.size))
    if x.size:
        out[0] = state
    for i in range(1, x.size):
        state = np.clip(state + (x[i] - x[i - 1]), -d, d)
        out[i] = state
    return out
