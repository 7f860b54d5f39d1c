"""Host-side conversion of device samples to SI units at the load.

The device reports encoder counts and motor current; with the configured calibration
(torque constant k_t in N*m/A, encoder counts per motor revolution, ratio = motor revolutions per load
revolution) the host gets

    position [rad, load]  = 2*pi * counts / (counts_per_rev * ratio)
    torque   [N*m, load]  = k_t * ratio * current

(ideal transmission: no belt or gear losses).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Calibration:
    torque_constant: float = 1.0  # N*m/A at the motor shaft
    counts_per_rev: int = 16384  # encoder counts per motor revolution
    ratio: float = 1.0  # motor revolutions per load revolution (belt or gear)

    def position(self, counts: np.ndarray) -> np.ndarray:
        """Load angle, rad, of unwrapped encoder counts (any shape)."""
        return np.asarray(counts, dtype=np.float64) * (2.0 * math.pi / (self.counts_per_rev * self.ratio))

    def torque(self, current: np.ndarray) -> np.ndarray:
        """Load torque, N*m, of a motor current in A (any shape)."""
        return np.asarray(current, dtype=np.float64) * (self.torque_constant * self.ratio)

    def current(self, torque: np.ndarray) -> np.ndarray:
        """Motor current, A, that gives a load torque in N*m (inverse of :meth:`torque`)."""
        return np.asarray(torque, dtype=np.float64) / (self.torque_constant * self.ratio)


class CountUnwrapper:
    """Turns int32 wire counts (modulo 2**32) into a continuous int64 count.

    Exact as long as consecutive samples differ by less than 2**31 counts. The first sample seen is
    taken at face value (the device starts counting at 0 after CONFIG).
    """

    def __init__(self) -> None:
        self.last: int | None = None

    def reset(self) -> None:
        self.last = None

    def __call__(self, raw: np.ndarray) -> np.ndarray:
        """int64 counts of a block of int32 wire counts, continuing from the previous block."""
        raw = np.asarray(raw, dtype=np.int64)
        if raw.size == 0:
            return np.zeros(0, dtype=np.int64)
        if self.last is None:
            base, prev = int(raw[0]), int(raw[0])
        else:
            base, prev = self.last, _wrap32(self.last)
        steps = np.diff(raw, prepend=prev)
        steps = (steps + 2**31) % 2**32 - 2**31  # the step modulo 2**32, in [-2**31, 2**31)
        out = base + np.cumsum(steps)
        self.last = int(out[-1])
        return out


def _wrap32(value: int) -> int:
    """``value`` modulo 2**32 as a signed int32 (what the wire carries)."""
    return (value + 2**31) % 2**32 - 2**31
