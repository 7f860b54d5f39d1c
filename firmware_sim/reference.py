"""Slow pure-Python twin of the C plant. A test oracle only: never used by the device or the analysis.

It performs the same floating-point operations in the same order as ``plant.c`` (which is built with
``-ffp-contract=off``), including the xoshiro256** generator and Box-Muller deviates, so the two agree
to rounding.
"""

from __future__ import annotations

import math

import numpy as np

from hilbench.firmware_sim.plant import MODES, PlantOutput, PlantParams, validate

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


def reference_simulate(params: PlantParams, u, dt: float, substeps: int = 1, mode: str = "current",
                       theta0: float = 0.0, omega0: float = 0.0) -> PlantOutput:
    """Pure-Python simulation with the semantics of :func:`firmware_sim.plant.simulate`."""
    validate(params, dt, substeps, mode)
    p = params
    k = [float(v) for v in p.ms_stiffness]
    delta = [float(v) for v in p.ms_delta] if k else []
    defl = [0.0] * len(k)
    vpos = float(p.viscous)
    vneg = vpos if p.viscous_neg is None else float(p.viscous_neg)
    fcp = float(p.coulomb)
    fcn = fcp if p.coulomb_neg is None else float(p.coulomb_neg)
    s_excess = 0.0 if p.static is None else p.static - p.coulomb
    s_vel = p.stribeck_velocity if p.static is not None else 0.0
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

    def smooth_force(th: float, om: float, th0: float) -> float:
        dx = th - th0
        f = 0.0
        for i in range(len(k)):
            f += k[i] * _clip(defl[i] + dx, -delta[i], delta[i])
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
        def force(x: float, v: float) -> float:
            f = smooth_force(x, v, th)
            if direction != 0.0:
                f += direction * level(direction, v)
            return f

        k1x = om
        k1v = (tau - force(th, om)) / J
        k2x = om + 0.5 * h * k1v
        k2v = (tau - force(th + 0.5 * h * k1x, k2x)) / J
        k3x = om + 0.5 * h * k2v
        k3v = (tau - force(th + 0.5 * h * k2x, k3x)) / J
        k4x = om + h * k3v
        k4v = (tau - force(th + h * k3x, k4x)) / J
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
            if not dry:
                th_new, om_new = rk4(th, om, tau, 0.0)
                coulomb_force = 0.0
            else:
                direction = 1.0 if om > 0.0 else (-1.0 if om < 0.0 else 0.0)
                sliding = False
                hs = h
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
            theta, omega = th_new, om_new
        time_ += dt
    return out


def reference_stop_operator(x, deltas, initial=None) -> np.ndarray:
    """Pure-Python stop operator with the semantics of :func:`firmware_sim.plant.stop_operator`."""
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
