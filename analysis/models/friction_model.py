"""The identified friction model: a plain record of parameters, its virgin curve and its plant.

    J*theta'' + sum_i k_i*S_Delta_i[theta] + b*theta' + Fc*sign(theta') + c0 + K*theta = tau

Units per axis: rotary (rad, N*m, kg*m^2) or linear (m, N, kg).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.common.units import AXIS_UNITS as AXES


def check_axis(axis: str) -> str:
    if axis not in AXES:
        raise AnalysisError(f"axis must be 'rotary' or 'linear', got {axis!r}")
    return axis


@dataclass
class FrictionModel:
    """Parameters (SI, per ``axis``) and their standard errors (same keys; NaN when not estimable)."""

    axis: str
    inertia: float
    ms_stiffness: np.ndarray  # k_i, shape (N,)
    ms_delta: np.ndarray  # Delta_i, shape (N,), increasing
    viscous: float = 0.0
    coulomb: float = 0.0
    offset: float = 0.0  # c0, a constant load (N*m or N); the plant sees torque_offset = -c0
    spring: float = 0.0
    std_errors: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_axis(self.axis)
        self.ms_stiffness = np.asarray(self.ms_stiffness, float).ravel()
        self.ms_delta = np.asarray(self.ms_delta, float).ravel()
        order = np.argsort(self.ms_delta)
        self.ms_stiffness, self.ms_delta = self.ms_stiffness[order], self.ms_delta[order]

    @property
    def ms_slip(self) -> np.ndarray:
        """W_i = k_i*Delta_i (N*m or N)."""
        return self.ms_stiffness * self.ms_delta

    @property
    def breakaway(self) -> float:
        """sum W_i + Fc: the friction level once every element slips (N*m or N)."""
        return float(np.sum(self.ms_slip) + self.coulomb)

    def virgin_curve(self, x: np.ndarray) -> np.ndarray:
        """Maxwell-slip virgin curve sum_i k_i*clip(x, -Delta_i, Delta_i) (N*m or N); x any shape."""
        x = np.asarray(x, float)
        return np.sum(self.ms_stiffness * np.clip(x[..., None], -self.ms_delta, self.ms_delta), axis=-1)

    def element_curves(self, x: np.ndarray) -> np.ndarray:
        """Each element's force k_i*clip(x, +-Delta_i), shape x.shape + (N,)."""
        x = np.asarray(x, float)
        return self.ms_stiffness * np.clip(x[..., None], -self.ms_delta, self.ms_delta)

    def plant_params(self, **effects):
        """:class:`firmware_sim.engine.plant.PlantParams` of this model (torque_constant 1: input is torque)."""
        from hilbench.firmware_sim.engine.plant import PlantParams

        keep = (self.ms_stiffness > 0) & (self.ms_delta > 0)
        k = self.ms_stiffness[keep]
        return PlantParams(
            inertia=self.inertia,
            spring=self.spring,
            ms_stiffness=tuple(map(float, k)),
            ms_slip=tuple(map(float, k * self.ms_delta[keep])),
            viscous=self.viscous,
            coulomb=self.coulomb,
            torque_offset=-self.offset,
            torque_constant=1.0,
            **effects,
        )

    def to_dict(self) -> dict:
        units = AXES[self.axis]
        se = {
            k: (np.asarray(v, float).tolist() if np.ndim(v) else float(v)) for k, v in self.std_errors.items()
        }
        return {
            "axis": self.axis,
            "units": {
                "inertia": units["inertia"],
                "ms_stiffness": units["stiffness"],
                "ms_delta": units["position"],
                "ms_slip": units["torque"],
                "viscous": units["viscous"],
                "coulomb": units["torque"],
                "offset": units["torque"],
                "spring": units["stiffness"],
            },
            "inertia": float(self.inertia),
            "ms_stiffness": self.ms_stiffness.tolist(),
            "ms_delta": self.ms_delta.tolist(),
            "ms_slip": self.ms_slip.tolist(),
            "viscous": float(self.viscous),
            "coulomb": float(self.coulomb),
            "offset": float(self.offset),
            "spring": float(self.spring),
            "std_errors": se,
        }

    @classmethod
    def from_dict(cls, data: dict) -> FrictionModel:
        try:
            return cls(
                axis=data["axis"],
                inertia=float(data["inertia"]),
                ms_stiffness=data["ms_stiffness"],
                ms_delta=data["ms_delta"],
                viscous=float(data.get("viscous", 0.0)),
                coulomb=float(data.get("coulomb", 0.0)),
                offset=float(data.get("offset", 0.0)),
                spring=float(data.get("spring", 0.0)),
                std_errors=dict(data.get("std_errors", {})),
            )
        except KeyError as exc:
            raise AnalysisError(f"model file lacks the field {exc.args[0]!r}") from None
