"""Measurement protocols: what a run plays, with units and validated ranges.

Each protocol is a frozen dataclass whose ``SPECS`` are the single source of truth for the CLI options,
the GUI forms and the campaign files. ``setpoints()`` builds the whole setpoint array from the pure
excitation functions in :mod:`bench.acquisition.excitations`. ``segments()`` splits it into the steps a run may pause
between.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any, ClassVar

import numpy as np

from hilbench.bench.acquisition import excitations
from hilbench.bench.errors import BenchError
from hilbench.common.units import MODE_UNITS

SAMPLE_RATES = (1000, 2000, 5000, 10000, 20000)
MODES = ("current", "velocity", "position")
#: The longest protocol, samples: 1 h at 20 kHz (every protocol's longest duration). Checked from the
#: parameters alone, before any array is allocated.
MAX_PROTOCOL_SAMPLES = 72_000_000
#: Peak memory of building a protocol's excitation plus the runner's copies, bytes per sample (measured
#: with tracemalloc on 500 000 samples: identification's zero-phase filter 128, a chirp 24, a stepped sine
#: 32; plus 12 for the runner's float64 setpoints and float32 wire copy).
PEAK_BYTES_PER_SAMPLE = {"identification": 140, "chirp": 36, "stepped_sine": 44, "presliding": 64}
#: A protocol not listed above: float64 angle and feed-forward, their (n, 2) stack, float32 wire copy.
DEFAULT_PEAK_BYTES_PER_SAMPLE = 64


class ProtocolError(BenchError):
    """A protocol parameter out of range, of the wrong type or unknown."""


@dataclass(frozen=True)
class ParameterSpec:
    """Unit, range and help of one protocol parameter. ``unit`` ``"setpoint"`` means A in current mode
    and rad/s in velocity mode. ``kind`` is ``float``, ``int``, ``str``, ``floats`` (a list) or ``choice``."""

    unit: str
    minimum: float | None
    maximum: float | None
    help: str
    kind: str = "float"
    choices: tuple[str, ...] = ()

    def unit_for(self, mode: str) -> str:
        if self.unit == "setpoint":
            return MODE_UNITS[mode]
        return self.unit

    def check(self, name: str, value: Any, mode: str) -> Any:
        """Return ``value`` converted to its kind, or raise :class:`ProtocolError` with name, unit, range."""
        unit = self.unit_for(mode)
        if self.kind == "choice":
            if value not in self.choices:
                raise ProtocolError(f"{name} must be one of {', '.join(self.choices)}, got {value!r}")
            return value
        if self.kind == "floats":
            if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
                raise ProtocolError(f"{name} must be a list of numbers in {unit}, got {value!r}")
            values = tuple(self._number(name, v, unit) for v in value)
            if not values:
                raise ProtocolError(f"{name} needs at least one value")
            return values
        return self._number(name, value, unit)

    def _number(self, name: str, value: Any, unit: str) -> float | int:
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise ProtocolError(f"{name} must be a number in {unit}, got {value!r}")
        if self.kind == "int":
            if int(value) != value:
                raise ProtocolError(f"{name} must be a whole number, got {value!r}")
            value = int(value)
        else:
            value = float(value)
        if not math.isfinite(value):
            raise ProtocolError(f"{name} must be finite, got {value}")
        lo, hi = self.minimum, self.maximum
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise ProtocolError(f"{name} = {value:g} {unit} is outside [{lo:g}, {hi:g}] {unit}"
                                if lo is not None and hi is not None else f"{name} = {value:g} out of range")
        return value


COMMON_SPECS: dict[str, ParameterSpec] = {
    "mode": ParameterSpec("", None, None, "current (setpoints in A) or velocity (rad/s, device PI loop)",
                          kind="choice", choices=("current", "velocity")),
    "sample_rate": ParameterSpec("Hz", 1000, 20000, "device sample rate: 1000, 2000, 5000, 10000 or 20000",
                                 kind="int"),
}


@dataclass(frozen=True)
class Protocol:
    """Base class: validation from ``SPECS`` and the common interface.

    A protocol plays in one of its ``MODES``. In ``position`` mode its setpoints are angles at the load, rad
    (the bench streams them times the ratio: at the encoder shaft), and it may define
    ``feedforward(limit) -> np.ndarray | None``: a motor current (A) per setpoint, streamed with it
    (``limit`` is the current limit, A).
    """

    name: ClassVar[str] = ""
    SPECS: ClassVar[dict[str, ParameterSpec]] = {}
    MODES: ClassVar[tuple[str, ...]] = ("current", "velocity")
    #: device settings (``DeviceSettings`` names, their units) this protocol measures best with; the config
    #: file's ``[settings]``, a campaign's keys and the command line all override them
    RECOMMENDED_SETTINGS: ClassVar[dict[str, float]] = {}

    def __post_init__(self) -> None:
        mode = self.mode  # type: ignore[attr-defined]
        if mode not in self.MODES:
            raise ProtocolError(f"{self.name} runs in {' or '.join(self.MODES)} mode, got {mode!r}")
        for f in fields(self):
            spec = self.specs()[f.name]
            object.__setattr__(self, f.name, spec.check(f.name, getattr(self, f.name), mode))
        if self.sample_rate not in SAMPLE_RATES:  # type: ignore[attr-defined]
            rates = ", ".join(map(str, SAMPLE_RATES))
            raise ProtocolError(f"sample_rate {self.sample_rate} Hz is not one of {rates} Hz")  # type: ignore
        self._check()
        n = self.n_samples
        if n > MAX_PROTOCOL_SAMPLES:
            raise ProtocolError(f"{self.name} would play {n} samples ({n / self.sample_rate:.6g} s at "  # type: ignore
                                f"{self.sample_rate} Hz, about {_gib(self.memory_bytes)} of memory), above the "  # type: ignore
                                f"bound of {MAX_PROTOCOL_SAMPLES} samples (1 h at 20 kHz)")

    @property
    def n_samples(self) -> int:
        """Samples the protocol plays, from its parameters alone (nothing is allocated)."""
        return int(round(self.duration_parameter * self.sample_rate))  # type: ignore[attr-defined]

    @property
    def duration_parameter(self) -> float:
        return float(self.duration)  # type: ignore[attr-defined]

    @property
    def memory_bytes(self) -> int:
        """Peak memory a run of this protocol needs for its setpoints, bytes (see PEAK_BYTES_PER_SAMPLE)."""
        return self.n_samples * PEAK_BYTES_PER_SAMPLE.get(self.name, DEFAULT_PEAK_BYTES_PER_SAMPLE)

    def check_memory(self, available: int | None = None) -> None:
        """Raise :class:`ProtocolError` if :attr:`memory_bytes` exceeds the memory available now (bytes,
        ``MemAvailable`` of /proc/meminfo unless given)."""
        available = available_memory() if available is None else available
        if available is not None and self.memory_bytes > available:
            raise ProtocolError(f"{self.name} needs about {_gib(self.memory_bytes)} of memory for "
                                f"{self.n_samples} samples; only {_gib(available)} is available")

    def _check(self) -> None:
        """Cross-field checks of a subclass."""

    @classmethod
    def specs(cls) -> dict[str, ParameterSpec]:
        common = dict(COMMON_SPECS)
        if cls.MODES != COMMON_SPECS["mode"].choices:
            common["mode"] = ParameterSpec("", None, None, f"control mode: {', '.join(cls.MODES)}", kind="choice",
                                           choices=cls.MODES)
        return {**cls.SPECS, **common}

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> Protocol:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ProtocolError(f"unknown {cls.name} parameter(s): {', '.join(unknown)} "
                                f"(known: {', '.join(sorted(known))})")
        return cls(**values)

    def parameters(self) -> dict[str, Any]:
        """JSON-able snapshot of every parameter, with units."""
        out = {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}
        out["units"] = {k: s.unit_for(self.mode) for k, s in self.specs().items() if s.unit}  # type: ignore
        return out

    def excitation(self, limit: float | None = None) -> excitations.Excitation:
        raise NotImplementedError

    def setpoints(self, limit: float | None = None) -> np.ndarray:
        """The whole setpoint array (A in current mode, rad/s in velocity mode)."""
        return self.excitation(limit).u

    def segments(self, limit: float | None = None) -> list[tuple[int, int]]:
        """(start, stop) sample ranges a run plays one after another; pauses happen between them."""
        return [(0, self.excitation(limit).u.size)]

    @property
    def duration(self) -> float:
        """Length of the run, s (samples / sample rate)."""
        return self.n_samples / self.sample_rate  # type: ignore[attr-defined]


def _gib(n: int) -> str:
    return f"{n / 2**30:.3g} GiB"


def available_memory() -> int | None:
    """Memory available to a new allocation, bytes (``MemAvailable``; None where the system does not say)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


@dataclass(frozen=True)
class Identification(Protocol):
    """Random-enveloped identification input (science.md §6): uniform noise low-passed at ``cutoff``
    times the three-term square-wave envelope of ``amplitude``, ``period`` and ``offset``."""

    name: ClassVar[str] = "identification"
    SPECS: ClassVar[dict[str, ParameterSpec]] = {
        "duration": ParameterSpec("s", 0.1, 3600.0, "length of the run"),
        "amplitude": ParameterSpec("setpoint", 1e-3, 1e3, "envelope amplitude"),
        "period": ParameterSpec("s", 0.05, 600.0, "envelope (square-wave) period"),
        "offset": ParameterSpec("setpoint", -1e3, 1e3, "envelope offset"),
        "cutoff": ParameterSpec("Hz", 0.5, 2000.0, "low-pass cut-off of the noise"),
        "seed": ParameterSpec("", 0, 2**32 - 1, "random seed (same seed, same input)", kind="int"),
    }
    duration: float = 20.0
    amplitude: float = 16.0  # about 4x the DC-motor break-away current: presliding and sliding
    period: float = 4.0
    offset: float = 0.0
    cutoff: float = 40.0
    seed: int = 0
    mode: str = "current"
    sample_rate: int = 10000

    def _check(self) -> None:
        if self.cutoff >= self.sample_rate / 2:
            raise ProtocolError(f"cutoff {self.cutoff} Hz must be below Nyquist ({self.sample_rate / 2} Hz)")

    def excitation(self, limit: float | None = None) -> excitations.Excitation:
        return excitations.random_enveloped(
            self.duration, self.sample_rate, amplitude=self.amplitude, period=self.period, offset=self.offset,
            cutoff=self.cutoff, seed=self.seed, mode=self.mode, limit=limit)


@dataclass(frozen=True)
class Chirp(Protocol):
    """Chirp ``gain*sin(pi*rate*t^2)`` (``sweep = quadratic``, the paper's), or a linear/log sine sweep
    from ``f_start`` to ``f_stop``."""

    name: ClassVar[str] = "chirp"
    SPECS: ClassVar[dict[str, ParameterSpec]] = {
        "duration": ParameterSpec("s", 0.1, 3600.0, "length of the run"),
        "gain": ParameterSpec("setpoint", 1e-3, 1e3, "peak setpoint G"),
        "sweep": ParameterSpec("", None, None, "quadratic: G*sin(pi*a*t^2); linear/log: f_start..f_stop",
                               kind="choice", choices=("quadratic", "linear", "log")),
        "rate": ParameterSpec("Hz/s", 1e-4, 1e4, "a of the quadratic chirp (instantaneous frequency a*t)"),
        "f_start": ParameterSpec("Hz", 1e-3, 5000.0, "start frequency of a linear/log sweep"),
        "f_stop": ParameterSpec("Hz", 1e-3, 5000.0, "stop frequency of a linear/log sweep"),
    }
    duration: float = 20.0
    gain: float = 2.0
    sweep: str = "quadratic"
    rate: float = 0.1
    f_start: float = 0.1
    f_stop: float = 20.0
    mode: str = "current"
    sample_rate: int = 10000

    def excitation(self, limit: float | None = None) -> excitations.Excitation:
        if self.sweep == "quadratic":
            return excitations.quadratic_chirp(self.duration, self.sample_rate, gain=self.gain, a=self.rate,
                                               mode=self.mode, limit=limit)
        return excitations.sweep(self.duration, self.sample_rate, gain=self.gain, f_start=self.f_start,
                                 f_stop=self.f_stop, method=self.sweep, mode=self.mode, limit=limit)


@dataclass(frozen=True)
class SteppedSine(Protocol):
    """Stepped sine over ``amplitudes`` x ``frequencies`` (amplitude outer), each step ``settle_periods``
    then ``measure_periods`` whole periods. A run may pause between steps."""

    name: ClassVar[str] = "stepped_sine"
    SPECS: ClassVar[dict[str, ParameterSpec]] = {
        "frequencies": ParameterSpec("Hz", 1e-3, 5000.0, "excitation frequencies", kind="floats"),
        "amplitudes": ParameterSpec("setpoint", 1e-3, 1e3, "excitation amplitudes", kind="floats"),
        "settle_periods": ParameterSpec("periods", 0, 10000, "whole periods discarded per step", kind="int"),
        "measure_periods": ParameterSpec("periods", 1, 10000, "whole periods analysed per step", kind="int"),
    }
    frequencies: tuple[float, ...] = field(default=(1.0, 2.0, 5.0))
    # either side of the simulated DC motor's break-away (3.8 A): 0.5 and 2 A never left presliding;
    # `hilbench plan` sizes them from the motor at hand
    amplitudes: tuple[float, ...] = field(default=(2.0, 5.0))
    settle_periods: int = 5
    measure_periods: int = 10
    mode: str = "current"
    sample_rate: int = 10000

    def excitation(self, limit: float | None = None) -> excitations.Excitation:
        return excitations.stepped_sine(self.sample_rate, frequencies=self.frequencies,
                                        amplitudes=self.amplitudes, settle_periods=self.settle_periods,
                                        measure_periods=self.measure_periods, mode=self.mode, limit=limit)

    def segments(self, limit: float | None = None) -> list[tuple[int, int]]:
        w = self.excitation(limit).windows
        return [(int(r["settle_start"]), int(r["measure_stop"])) for r in w]

    @property
    def n_samples(self) -> int:
        # the count excitations.stepped_sine plays: g-period blocks of round(g*fs/f) samples
        g = math.gcd(self.settle_periods, self.measure_periods)
        per_amplitude = sum(max(1, int(round(g * self.sample_rate / f))) for f in self.frequencies)
        return (self.settle_periods // g + self.measure_periods // g) * per_amplitude * len(self.amplitudes)


#: Largest presliding amplitude, rad at the load: presliding lives in milliradians; beyond this is a typo.
MAX_PRESLIDING_RAD = 10.0


@dataclass(frozen=True)
class Presliding(Protocol):
    """Presliding friction: a quasi-static displacement in position mode, a virgin ramp from rest to A1 then
    nested reversals of decreasing amplitude (to -A2, +A3, ...), the inner loops closing again
    (``close_inner``), each turning point held ``settle`` s. Amplitudes in rad or m at the load, or as
    multiples ``d`` of the presliding distance you estimate. The run file is a displacement-driven record.
    """

    name: ClassVar[str] = "presliding"
    MODES: ClassVar[tuple[str, ...]] = ("position",)
    # A gentle, integral-led loop. On a quantised encoder the proportional and derivative terms kick the
    # current at every count edge, the contact then runs minor loops, and the averaged force falls below the
    # virgin curve: -1.3 % of the sliding level with the stiff defaults (kp 3000, ki 3e5, kd 5), -0.2 % with
    # these on the simulated DC motor at 2^16 counts/rev (docs/presliding.md, "Loop gains").
    RECOMMENDED_SETTINGS: ClassVar[dict[str, float]] = {"position_kp": 100.0, "position_ki": 3.0e4,
                                                        "position_kd": 0.5}
    record: ClassVar[str] = "displacement-driven"
    SPECS: ClassVar[dict[str, ParameterSpec]] = {
        "amplitudes": ParameterSpec("unit", 1e-9, 1e3, "turning-point amplitudes A1 >= A2 >= ... (in `unit`)",
                                    kind="floats"),
        "unit": ParameterSpec("", None, None, "unit of amplitudes and rate: rad or m at the load, or d "
                              "(multiples of presliding_distance)", kind="choice", choices=("d", "rad", "m")),
        "presliding_distance": ParameterSpec("rad", 1e-9, 1.0, "your estimate of the presliding distance "
                                             "(unit d)"),
        "m_per_rad": ParameterSpec("m/rad", 0.0, 10.0, "linear travel per load radian (unit m): screw lead/2pi "
                                   "or pulley radius; 0 = not set"),
        "rate": ParameterSpec("unit/s", 1e-9, 1e3, "speed of the ramps between turning points"),
        "settle": ParameterSpec("s", 0.0, 60.0, "hold at rest before the ramp and at every turning point"),
        "cycles": ParameterSpec("", 1, 100, "times the reversal cycle (A1 back to A1) is played (a campaign's "
                                "`repeats` is its number of runs)", kind="int"),
        "close_inner": ParameterSpec("", None, None, "retrace the turning points to close each inner loop "
                                     "(yes) or return to A1 at once (no)", kind="choice", choices=("yes", "no")),
        "inertia": ParameterSpec("kg*m^2", 0.0, 100.0, "J at the load to subtract J*acceleration from the "
                                 "torque (0 = not given: force = torque)"),
    }
    amplitudes: tuple[float, ...] = field(default=(4.0, 3.0, 2.0, 1.0))
    unit: str = "d"
    presliding_distance: float = 5e-4  # rad: the simulated DC motor's d (firmware_sim.engine.friction_models)
    m_per_rad: float = 0.0
    rate: float = 2.0
    settle: float = 0.2
    cycles: int = 1
    close_inner: str = "yes"
    inertia: float = 0.0
    mode: str = "position"
    sample_rate: int = 10000

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> Protocol:
        """As :meth:`Protocol.from_dict`; the loop count's old name ``repeats`` (run files and forms before
        issue 38, where a campaign's ``repeats`` also meant its number of runs) is read as ``cycles``."""
        if "repeats" in values:
            import warnings

            values = dict(values)
            if "cycles" in values:
                raise ProtocolError("presliding: give the loop count as cycles only (repeats is its old name)")
            warnings.warn("presliding parameter 'repeats' is now 'cycles' (the loop count); read as cycles",
                          DeprecationWarning, stacklevel=2)
            values["cycles"] = values.pop("repeats")
        return super().from_dict(values)

    @property
    def rad_per_unit(self) -> float:
        """Load radians per amplitude unit."""
        if self.unit == "d":
            return self.presliding_distance
        if self.unit == "m":
            return 1.0 / self.m_per_rad
        return 1.0

    def _check(self) -> None:
        if self.unit == "m" and self.m_per_rad <= 0:
            raise ProtocolError("unit m needs m_per_rad > 0 (metres of travel per load radian)")
        a = self.amplitudes
        if any(later > earlier for earlier, later in zip(a, a[1:], strict=False)):
            raise ProtocolError(f"amplitudes must not increase (nested reversals: A1 >= A2 >= ...), got {list(a)}")
        peak = a[0] * self.rad_per_unit
        if peak > MAX_PRESLIDING_RAD:
            raise ProtocolError(f"amplitude A1 = {a[0]:g} {self.unit} is {peak:.6g} rad at the load, above the "
                                f"presliding bound of {MAX_PRESLIDING_RAD:g} rad")

    def points(self) -> np.ndarray:
        """Turning points, rad at the load, starting with 0 (excitations.nested_reversal_points)."""
        pts = excitations.nested_reversal_points(self.amplitudes, self.close_inner == "yes", self.cycles)
        return pts * self.rad_per_unit

    @property
    def n_samples(self) -> int:
        ramps, hold = excitations.reversal_path_lengths(self.points(), self.rate * self.rad_per_unit, self.settle,
                                                        self.sample_rate)
        return int(ramps.sum()) + hold * (ramps.size + 1)

    def _path(self) -> tuple[np.ndarray, np.ndarray]:
        return excitations.reversal_path(self.points(), self.rate * self.rad_per_unit, self.settle,
                                         self.sample_rate)

    def excitation(self, limit: float | None = None) -> excitations.Excitation:
        """The reference angle at the load, rad (the bench turns it to the motor shaft with the ratio)."""
        u, _ = self._path()
        return excitations.Excitation(name=self.name, mode="position", fs=float(self.sample_rate), u=u,
                                      params=self.parameters())

    def parameters(self) -> dict[str, Any]:
        out = super().parameters()
        out["units"].update(amplitudes=self.unit, rate=f"{self.unit}/s")
        out["rad_per_unit"] = self.rad_per_unit
        return out

    def protocol_arrays(self) -> dict[str, np.ndarray]:
        """``turning_points``: sample index reaching each point and the point (rad at the load)."""
        return {"turning_points": self._path()[1]}

    def feedforward(self, limit: float) -> None:
        """No feed-forward: the loop's integral carries the friction at quasi-static speed."""
        return None


PROTOCOLS: dict[str, type[Protocol]] = {p.name: p for p in (Identification, Chirp, SteppedSine, Presliding)}


def make_protocol(name: str, values: dict[str, Any]) -> Protocol:
    """Build protocol ``name`` from a dict of parameters (campaign files, GUI forms)."""
    if name not in PROTOCOLS:
        raise ProtocolError(f"unknown protocol {name!r} (known: {', '.join(PROTOCOLS)})")
    try:
        return PROTOCOLS[name].from_dict(values)
    except (TypeError, ValueError) as exc:
        raise ProtocolError(str(exc)) from exc
