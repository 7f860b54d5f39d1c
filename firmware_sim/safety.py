"""Wire-independent safety logic of the simulated amplifier: limits, watchdog, latched faults.

Everything here works on sample indices and arrays, with no I/O, so it is tested directly.
A fault trips at a sample k when the measurements of sample k (taken at t_k, before u[k] acts) or the
setpoint u[k] violate a limit; the firmware then applies zero current from sample k on.
"""

from __future__ import annotations

import math

import numpy as np

from hilbench.drivers.protocol import Config, Fault, Mode


class SafetyMonitor:
    """Limit checks over blocks of samples, and the latched fault register.

    Limits (encoder-shaft units, from :class:`drivers.protocol.Config`):

    - over-current: ``|current_meas[k]| > current_limit``, or in current mode ``|u[k]| > current_limit``;
    - over-speed: ``|v[k]| > velocity_limit`` with the encoder velocity estimate
      ``v[k] = 2*pi/cpr * (counts[k] - counts[k-W]) / (W*dt)`` over ``W = max(1, rate/1000)`` samples
      (a 1 ms window; before a stream's first sample the motor is taken to be at rest at that sample's
      count, so a count flicker at arming is never read as speed);
    - position window: ``2*pi*counts[k]/cpr`` outside ``[position_min, position_max]``.
    """

    def __init__(self, config: Config) -> None:
        self.config = config
        self.window = max(1, config.sample_rate // 1000)
        self._scale = 2.0 * math.pi / config.counts_per_rev
        self._history = np.zeros(0, dtype=np.int64)  # last `window` counts before the next block
        self.faults = 0
        self.fault_index = 0
        self.fault_silence = 0

    def first_trip(self, counts: np.ndarray, current_meas: np.ndarray,
                   setpoints: np.ndarray) -> tuple[int, int]:
        """``(j, faults)``: the first sample j of the block that trips and its fault bits, or
        ``(len(block), 0)``. Does not change the monitor (call :meth:`accept` for the samples kept)."""
        cfg = self.config
        n = len(counts)
        bad = np.zeros((3, n), dtype=bool)
        bad[0] = np.abs(current_meas) > cfg.current_limit
        if cfg.mode == Mode.CURRENT:
            bad[0] |= np.abs(setpoints) > cfg.current_limit
        history = self._history if self._history.size or not n else np.full(self.window, counts[0])
        hist = np.concatenate((history, counts))
        w = self.window
        velocity = (hist[w:] - hist[:n]) * (self._scale * cfg.sample_rate / w)  # hist[w+k] = counts[k]
        bad[1] = np.abs(velocity) > cfg.velocity_limit
        position = counts * self._scale
        bad[2] = (position < cfg.position_min) | (position > cfg.position_max)
        any_bad = bad.any(axis=0)
        if not any_bad.any():
            return n, 0
        j = int(np.argmax(any_bad))
        bits = [Fault.OVER_CURRENT, Fault.OVER_SPEED, Fault.POSITION_WINDOW]
        return j, int(sum(int(bit) for bit, row in zip(bits, bad, strict=True) if row[j]))

    def accept(self, counts: np.ndarray) -> None:
        """Record the counts of samples that were executed (for the velocity window)."""
        counts = np.asarray(counts, dtype=np.int64)
        if not self._history.size and counts.size:
            self._history = np.full(self.window, counts[0])
        hist = np.concatenate((self._history, counts))
        self._history = hist[-self.window:]

    def reset_history(self) -> None:
        self._history = np.zeros(0, dtype=np.int64)

    def latch(self, faults: int, index: int, silence: int = 0) -> None:
        """Latch fault bits at sample ``index``; the first fault's index and host silence are kept."""
        if not self.faults:
            self.fault_index = index
            self.fault_silence = silence
        self.faults |= int(faults)

    def clear(self) -> None:
        self.faults = 0
        self.fault_index = 0
        self.fault_silence = 0


def watchdog_trip_index(last_rx: float, timeout: float, t0: float, k0: int, rate: int) -> int | None:
    """First sample index whose nominal time ``t0 + (k-k0)/rate`` is after ``last_rx + timeout``.

    So the current is zeroed no later than one sample period after the watchdog deadline. ``None`` when
    the watchdog is off (``timeout == 0``).
    """
    if timeout <= 0:
        return None
    # 1e-9 sample absorbs the rounding of (last_rx - t0) so that a deadline exactly on a sample is met
    return k0 + math.floor((last_rx - t0) * rate + timeout * rate + 1e-9) + 1
