"""The device interface every bench device implements: who owns the clock, what it can run, in which units.

Two kinds of device exist:

- **device-clocked stream** (``clock = "device"``): the host streams setpoint blocks ahead and the device
  owns the sample clock (the hilbench protocol, :class:`drivers.amplifier.Amplifier`);
- **host-clocked cycle** (``clock = "host"``): the device buffers nothing; the host sends one setpoint per
  cycle and triggers the sample (CiA 402 SYNC, ODrive cyclic messages). Every sample then also carries its
  host timestamp and cycle counter, and the cycle's timing is summarised for the run file.

The runner only uses :meth:`Device.configure`, :meth:`Device.arm`, :meth:`Device.disarm`,
:meth:`Device.estop`, :meth:`Device.stream` and :meth:`Device.close`, and asks :func:`refusal` before
anything moves whether a protocol can run at all. ``hilbench info`` and ``hilbench fault`` use
:meth:`Device.info`, :meth:`Device.state`, :meth:`Device.faults`, :meth:`Device.history` and
:meth:`Device.clear_faults`, which every device kind answers.
"""

from __future__ import annotations

import abc
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from hilbench.common.runfile.schema import CYCLE, DRIVE_STATUS, HOST_TIME, TORQUE_CMD, DeviceIdentity

CLOCKS = ("device", "host")
#: Control modes a device may offer and their setpoint units: ``MODE_UNITS`` (hilbench.common.units).

@dataclass(frozen=True)
class Capabilities:
    """What a device can run: for each control mode, the sample (cycle) rates it supports, Hz."""

    modes: dict[str, tuple[int, ...]] = field(default_factory=dict)

    def rates(self, mode: str) -> tuple[int, ...]:
        return self.modes.get(mode, ())

    def describe(self) -> str:
        return "; ".join(f"{m} at {', '.join(map(str, r))} Hz" for m, r in self.modes.items() if r) or "nothing"


def refusal(name: str, capabilities: Capabilities, mode: str, sample_rate: int) -> str | None:
    """One line saying why ``mode`` at ``sample_rate`` cannot run on the device ``name``, or None if it can."""
    rates = capabilities.rates(mode)
    if not rates:
        return f"{name} cannot run {mode} mode (it offers {capabilities.describe()})"
    if sample_rate not in rates:
        return (f"{name} cannot run {mode} mode at {sample_rate} Hz (it offers {capabilities.describe()}); "
                f"choose --sample-rate {rates[0]}")
    return None


class SampleBlock:
    """What every device's ``stream`` yields, one block at a time: the one sample-block type the runner reads.

    Every block has (1-D arrays of equal length, SI units at the load): ``index`` (sample index, int64),
    ``time`` (device time, s), ``counts`` (encoder counts, unwrapped), ``current_cmd`` and ``current_meas``
    (A), ``torque`` (N*m), ``position`` (rad), ``status`` (the device's status per sample) and ``sample_rate``
    (Hz); :meth:`extra` gives the channels a device adds beyond that set ({} when none).
    """

    def extra(self) -> dict[str, np.ndarray]:
        """Channels beyond the device-clocked set, for the run file (name: array)."""
        return {}


@dataclass
class CycleSamples(SampleBlock):
    """One block of samples of a host-clocked device, in SI units at the load.

    Attributes (1-D arrays of equal length):
        cycle: cycle counter (SYNC or cyclic-message count since the stream started), int64.
        host_time: host monotonic time at which the cycle's trigger (SYNC) was sent, s.
        counts: encoder counts, unwrapped, int64.
        current_cmd: commanded current, A (the torque command divided by the host's torque constant).
        current_meas: measured current, A (measured torque divided by the torque constant).
        torque_cmd, torque: commanded and measured motor torque at the load, N*m.
        position: load angle, rad; velocity: load velocity the drive reports, rad/s.
        status: the drive's status word per sample (CiA 402 0x6041; ODrive axis state), if it has one.
        sample_rate: nominal cycle rate, Hz.
    """

    cycle: np.ndarray
    host_time: np.ndarray
    counts: np.ndarray
    current_cmd: np.ndarray
    current_meas: np.ndarray
    torque_cmd: np.ndarray
    torque: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    sample_rate: int
    status: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.cycle)

    @property
    def index(self) -> np.ndarray:
        return self.cycle

    @property
    def time(self) -> np.ndarray:
        """Drive time of each sample, s: cycle / rate (the drive samples at each SYNC)."""
        return self.cycle / self.sample_rate

    def extra(self) -> dict[str, np.ndarray]:
        """Channels beyond the device-clocked set, for the run file."""
        status = self.status if self.status is not None else np.zeros(len(self))
        out = {HOST_TIME: self.host_time, CYCLE: self.cycle.astype(np.float64), "velocity": self.velocity,
               TORQUE_CMD: self.torque_cmd, DRIVE_STATUS: status.astype(np.float64)}
        return out


class Device(abc.ABC):
    """A bench device. Subclasses set :attr:`clock`, :attr:`capabilities` and :attr:`name`."""

    clock: str = "device"
    capabilities: Capabilities = Capabilities()
    name: str = "device"

    @property
    def reported_channels(self) -> tuple[str, ...]:
        """Run-file channels this device adds to every block's :meth:`SampleBlock.extra` beyond its clock's
        set (e.g. ``temperature`` from a device with a winding sensor); known before the first stream."""
        return ()

    @abc.abstractmethod
    def info(self) -> DeviceIdentity:
        """Identity of the device (model, serial, firmware, whose clock times the samples...), as the run file
        stores it."""

    @abc.abstractmethod
    def configure(self, config) -> None:
        """Send a :class:`drivers.protocol.Config` (rate, mode, limits, watchdog, calibration)."""

    @abc.abstractmethod
    def arm(self) -> None:
        """Enable the power stage at zero torque."""

    @abc.abstractmethod
    def disarm(self) -> None:
        """Zero the torque and disable the power stage."""

    @abc.abstractmethod
    def estop(self) -> None:
        """Emergency stop (quick stop on a drive); safe from any thread."""

    @abc.abstractmethod
    def stream(self, setpoints) -> Iterator[SampleBlock]:
        """Play ``setpoints`` (A in current mode, rad/s in velocity mode), one per sample; yield sample blocks."""

    @abc.abstractmethod
    def close(self) -> None:
        """Disable and release the device. Idempotent."""

    def run_events(self) -> list[tuple[str, str]]:
        """(kind, one-line message) events for the run file once a stream has ended (timing, faults)."""
        return []

    # What ``hilbench info`` and ``hilbench fault show|clear`` use, on every device kind.
    def state(self) -> str:
        """The device's own state in words (asked of the device)."""
        return "unknown"

    def faults(self) -> list[str]:
        """The faults the device has latched, one line each, each with its code and name; [] when none.
        A device that latches no fault has none."""
        return []

    def history(self) -> list[str]:
        """Lines on past faults the device keeps (a CiA 402 drive's error history 0x1003); [] when it keeps none."""
        return []

    def clear_faults(self) -> None:
        """Clear the latched faults, so that the device can be armed again. A device that latches no fault
        has nothing to clear."""
        return None

    def __enter__(self) -> Device:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
