"""The compensated-reference protocol: the device's position loop tracks a reference while the host streams a
model-based feed-forward current with it (docs/compensation.md).

Setpoints are the reference angles at the load (rad, zero at CONFIG); ``Bench.run`` streams them times the ratio to
the encoder (motor) shaft. :meth:`CompensatedReference.feedforward` is the
current (A) of the chosen model along the reference, J*q''_ref + F(q_ref) + c0 converted with the
calibration (``torque_constant``, ``ratio``): ``Bench.run`` binds the protocol to the device settings'
(:meth:`CompensatedReference.bind`), so it is always the device's; clipped to the current limit.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from hilbench.analysis.compensation.references import KINDS, Reference, make_reference
from hilbench.analysis.errors import AnalysisError
from hilbench.bench.acquisition import excitations
from hilbench.bench.acquisition.protocols import PROTOCOLS, ParameterSpec, Protocol, ProtocolError

if TYPE_CHECKING:  # the feed-forward pulls in the model code (scipy, the C plant): imported when used
    from hilbench.analysis.compensation.feedforward import Compensator, FeedForward

#: Peak memory per sample of a compensated run, bytes: the reference (position, velocity, acceleration), the
#: feed-forward and the runner's (n, 2) stack and float32 copy. Measured with tracemalloc on 0.5-0.6 M samples
#: (protocol built, setpoints, feed-forward, stack): triangle 71.6, sine 75.4, point-to-point 73.9; plus margin.
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

        return feedforward(self.compensator, self.reference_path, self.torque_constant, self.ratio, limit)


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
        # how the run's tracking is scored (analysis.compensation.metrics): kept with the run, so the matrix report,
        # the campaign's compensation row, the GUI and `hilbench report` score it alike
        "window": ParameterSpec("s", 1e-4, 10.0, "metrics: glitch window after each reversal of the reference"),
        "tolerance": ParameterSpec("rad", 1e-9, 1.0, "metrics: settling band of point-to-point moves"),
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
    window: float = 0.05
    tolerance: float = 1e-4
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

    @property
    def calibration(self) -> tuple[float, float] | None:
        """(k_t N*m/A, ratio) the feed-forward and the motor-shaft setpoints use; None until :meth:`bind`."""
        return self.__dict__.get("_calibration")

    def bind(self, settings) -> CompensatedReference:
        """This protocol on a device with ``settings`` (its ``torque_constant`` and ``ratio``): ``Bench.run``
        binds every protocol that has this method, so the feed-forward always uses the device's calibration."""
        return self.calibrated(settings.torque_constant, settings.ratio)

    def calibrated(self, torque_constant: float, ratio: float) -> CompensatedReference:
        new = replace(self)
        new.__dict__["_calibration"] = (float(torque_constant), float(ratio))
        new.__dict__.pop("case", None)
        return new

    @cached_property
    def case(self) -> Case:
        kt, ratio = self.calibration or (1.0, 1.0)  # unbound: the reference and the model are still checked
        return Case(self.reference, tuple(self.reference_parameters().items()), self.model, self.compensation,
                    self.sample_rate, kt, ratio)

    @classmethod
    def of(cls, case: Case, window: float = 0.05, tolerance: float = 1e-4) -> CompensatedReference:
        """The protocol that plays ``case`` (bound to the case's calibration), scored with the glitch ``window``
        (s) and settling ``tolerance`` (rad)."""
        return cls(reference=case.reference, model=case.model, compensation=case.compensation,
                   sample_rate=case.sample_rate, window=window, tolerance=tolerance,
                   **dict(case.parameters)).calibrated(case.torque_constant, case.ratio)

    def _bound(self) -> Case:
        if self.calibration is None:
            raise ProtocolError("compensated: not bound to a device calibration (Bench.run binds it)")
        return self.case

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
        """Setpoints: the reference at the load, q_ref (rad), as every position protocol gives them; ``Bench.run``
        streams ratio*q_ref to the encoder (motor) shaft and logs q_ref as ``position_cmd``. (Multiplying by the
        ratio here as well moved the load ratio*q_ref against a feed-forward computed for q_ref.)"""
        ref = self.reference_path
        return excitations.Excitation("compensated_" + ref.kind, self.mode, float(self.sample_rate),
                                      ref.position,
                                      {"reference": ref.kind, **ref.params, "compensation": self.compensation})

    def feedforward(self, limit: float) -> np.ndarray | None:
        """Feed-forward current, A, shape (n,), clipped to +-``limit`` A; None without a model."""
        if self.compensation == "none":
            return None
        return self._bound().feedforward_result(limit).current


PROTOCOLS[CompensatedReference.name] = CompensatedReference
