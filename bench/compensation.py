"""The compensated-reference protocol: the device's position loop tracks a reference while the host streams a
model-based feed-forward current with it (docs/compensation.md).

Setpoints are angles at the encoder (motor) shaft (rad, zero at CONFIG: ratio times the load-side reference);
:meth:`CompensatedReference.feedforward` is the
current (A) of the chosen model along the reference, J*q''_ref + F(q_ref) + c0 converted with the
calibration (``torque_constant``, ``ratio``, which must be the device's; the command and the campaign set them
from the device settings), clipped to the current limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from hilbench.analysis.compensation.references import KINDS, Reference, make_reference
from hilbench.analysis.errors import AnalysisError
from hilbench.bench import excitations
from hilbench.bench.protocols import PROTOCOLS, ParameterSpec, Protocol, ProtocolError

if TYPE_CHECKING:  # the feed-forward pulls in the model code (scipy, the C plant): imported when used
    from hilbench.analysis.compensation.feedforward import Compensator, FeedForward

#: Peak memory per sample of a compensated run: position, velocity, acceleration, friction, torque and
#: current (float64) plus the runner's copies (measured order of magnitude, like PEAK_BYTES_PER_SAMPLE).
BYTES_PER_SAMPLE = 96


@dataclass(frozen=True)
class Case:
    """One compensated tracking case, independent of any device: the reference (``kind`` and its parameters),
    the feed-forward (``compensation`` of ``model``), the sample rate (Hz) and the calibration (N*m/A, 1)."""

    reference: str
    parameters: tuple[tuple[str, Any], ...]
    model: str
    compensation: str
    sample_rate: int
    torque_constant: float
    ratio: float

    @cached_property
    def reference_path(self) -> Reference:
        return make_reference(self.reference, float(self.sample_rate), **dict(self.parameters))

    @cached_property
    def compensator(self) -> Compensator:
        from hilbench.analysis.compensation.feedforward import Compensator, load_compensators

        if self.compensation == "none":
            return Compensator("none", None)
        if not self.model:
            raise AnalysisError(f"compensation {self.compensation!r} needs a model file")
        comps, _ = load_compensators(self.model)
        found = {c.name: c for c in comps}
        if self.compensation not in found:
            raise AnalysisError(f"{self.model} offers feed-forward {', '.join(found)}; not {self.compensation!r}")
        return found[self.compensation]

    def feedforward_result(self, limit: float) -> FeedForward:
        """Feed-forward current (A, clipped to +-``limit``) and torque (N*m) along the reference."""
        from hilbench.analysis.compensation.feedforward import feedforward

        return feedforward(self.compensator, self.reference_path, self.torque_constant, self.ratio,
                           limit if math.isfinite(limit) else np.inf)


@dataclass(frozen=True)
class TextSpec(ParameterSpec):
    """A free-text parameter (a file path or a name)."""

    kind: str = "str"

    def check(self, name: str, value: Any, mode: str) -> Any:
        if not isinstance(value, str):
            raise ProtocolError(f"{name} must be text, got {value!r}")
        if self.choices and value not in self.choices:
            raise ProtocolError(f"{name} must be one of {', '.join(self.choices)}, got {value!r}")
        return value


@dataclass(frozen=True)
class CompensatedReference(Protocol):
    """Position tracking of a reference (slow sine, triangle or point-to-point) with a model feed-forward."""

    name: ClassVar[str] = "compensated"
    MODES: ClassVar[tuple[str, ...]] = ("position",)
    SPECS: ClassVar[dict[str, ParameterSpec]] = {
        "reference": ParameterSpec("", None, None, "sine | triangle | point_to_point", kind="choice",
                                   choices=KINDS),
        "model": TextSpec("", None, None, "model file (hilbench identify --json) or comparison "
                          "(hilbench compare compare.json); empty: no feed-forward"),
        "compensation": TextSpec("", None, None, "feed-forward: none, coulomb, maxwell_slip or a family of the "
                                 "comparison"),
        "amplitudes": ParameterSpec("rad", 1e-7, 100.0, "sine: amplitudes (peak-to-peak 2A)", kind="floats"),
        "amplitude": ParameterSpec("rad", 1e-7, 100.0, "triangle: amplitude"),
        "frequency": ParameterSpec("Hz", 1e-3, 100.0, "sine and triangle: frequency"),
        "cycles": ParameterSpec("periods", 1, 10000, "sine (per amplitude) and triangle: periods", kind="int"),
        "corner": ParameterSpec("s", 1e-4, 100.0, "triangle: corner blend time"),
        "targets": ParameterSpec("rad", -1e3, 1e3, "point_to_point: targets in turn", kind="floats"),
        "move_time": ParameterSpec("s", 1e-3, 100.0, "point_to_point: time of each move (minimum jerk)"),
        "rest": ParameterSpec("s", 0.0, 600.0, "rest at 0 (sine, triangle) or after each move"),
        "torque_constant": ParameterSpec("N*m/A", 1e-6, 100.0, "k_t the feed-forward current is computed "
                                         "with (the device's)"),
        "ratio": ParameterSpec("1", 1e-6, 1e6, "motor revolutions per load revolution (the device's)"),
    }
    reference: str = "sine"
    model: str = ""
    compensation: str = "none"
    amplitudes: tuple[float, ...] = field(default=(2e-4, 1e-3, 1e-2, 0.1))
    amplitude: float = 0.05
    frequency: float = 0.5
    cycles: int = 3
    corner: float = 0.02
    targets: tuple[float, ...] = field(default=(0.05, -0.05, 0.0))
    move_time: float = 0.3
    rest: float = 0.5
    torque_constant: float = 0.2
    ratio: float = 1.0
    mode: str = "position"
    sample_rate: int = 10000

    def _check(self) -> None:
        try:
            self.case.reference_path  # noqa: B018 (built once: every reference parameter is checked here)
            self.case.compensator  # noqa: B018
        except AnalysisError as exc:
            raise ProtocolError(str(exc)) from None

    def reference_parameters(self) -> dict[str, Any]:
        if self.reference == "sine":
            return {"amplitudes": self.amplitudes, "frequency": self.frequency, "cycles": self.cycles,
                    "rest": self.rest}
        if self.reference == "triangle":
            return {"amplitude": self.amplitude, "frequency": self.frequency, "cycles": self.cycles,
                    "corner": self.corner, "rest": self.rest}
        return {"targets": self.targets, "move_time": self.move_time, "rest": self.rest}

    @cached_property
    def case(self) -> Case:
        return Case(self.reference, tuple(self.reference_parameters().items()), self.model, self.compensation,
                    self.sample_rate, self.torque_constant, self.ratio)

    @classmethod
    def of(cls, case: Case) -> CompensatedReference:
        """The protocol that plays ``case``."""
        return cls(reference=case.reference, model=case.model, compensation=case.compensation,
                   sample_rate=case.sample_rate, torque_constant=case.torque_constant, ratio=case.ratio,
                   **dict(case.parameters))

    @property
    def reference_path(self) -> Reference:
        return self.case.reference_path

    @property
    def n_samples(self) -> int:
        return self.reference_path.n

    @property
    def memory_bytes(self) -> int:
        return self.n_samples * BYTES_PER_SAMPLE

    def excitation(self, limit: float | None = None) -> excitations.Excitation:
        """Setpoints: the reference at the encoder (motor) shaft, ratio*q_ref (rad); the run file's
        ``position_cmd`` is q_ref again, at the load."""
        ref = self.reference_path
        return excitations.Excitation("compensated_" + ref.kind, self.mode, float(self.sample_rate),
                                      ref.position * self.ratio,
                                      {"reference": ref.kind, **ref.params, "compensation": self.compensation})

    def feedforward(self, limit: float) -> np.ndarray | None:
        """Feed-forward current, A, shape (n,), clipped to +-``limit`` A; None without a model."""
        if self.compensation == "none":
            return None
        return self.case.feedforward_result(limit).current


PROTOCOLS[CompensatedReference.name] = CompensatedReference
