"""The default position-loop gains (drivers.protocol.POSITION_GAINS) hold the simulated DC motor: the
discrete closed loop (the loop law of docs/protocol.md on J*x'' = Kt*i - k*x under zero-order hold, built
here with scipy) is stable at 5, 10 and 20 kHz for any presliding stiffness k from 0 to 1e4 N*m/rad."""

import numpy as np
import pytest
from scipy.signal import cont2discrete, ss2tf

from hilbench.drivers.protocol import POSITION_GAINS

J, KT = 0.0022, 0.2  # kg*m^2, N*m/A: firmware_sim.engine.friction_models.dc_motor


def largest_pole(fs: float, k: float) -> float:
    """Largest closed-loop pole modulus of the loop on J*x'' = Kt*i - k*x at sample rate fs."""
    g = POSITION_GAINS
    dt = 1.0 / fs
    a = np.exp(-2 * np.pi * g["position_d_cutoff"] * dt)
    plant = (np.array([[0, 1], [-k / J, 0]]), np.array([[0], [KT / J]]), np.array([[1, 0]]), np.array([[0]]))
    num, den = ss2tf(*cont2discrete(plant, dt, "zoh")[:4])
    gn, gd = np.poly1d(num[0]), np.poly1d(den)
    z = np.poly1d([1, 0])
    cn = g["position_kp"] * (z - 1) * (z - a) + g["position_ki"] * dt * z * (z - a) \
        + g["position_kd"] * (1 - a) / dt * (z - 1) ** 2
    cd = (z - 1) * (z - a)
    return float(np.max(np.abs((cd * gd + cn * gn).roots)))


@pytest.mark.parametrize("fs", [5000, 10000, 20000])
def test_default_gains_are_stable_over_the_presliding_stiffness(fs):
    poles = [largest_pole(fs, k) for k in np.linspace(0, 1e4, 21)]
    assert max(poles) < 1.0
    if fs == 10000:
        assert max(poles) == pytest.approx(0.9994, abs=2e-4)


def test_low_rates_need_lower_gains():
    """docs/protocol.md says so: at 1 kHz the presliding stiffness of the DC motor destabilises them."""
    assert largest_pole(1000, 3000.0) > 1.0
