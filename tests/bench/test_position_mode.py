"""Position mode end to end on the simulated bench (the C firmware core behind sim://): a position-mode
protocol with a feed-forward current runs through ``Bench.run`` and its run file holds the reference."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import ClassVar

import h5py
import numpy as np
import pytest

from hilbench.bench.acquisition import excitations
from hilbench.bench.acquisition.protocols import ParameterSpec, Protocol
from hilbench.bench.acquisition.runner import Bench, DeviceSettings

FS = 10000
CPR = 1 << 16


@dataclass(frozen=True)
class SineHold(Protocol):
    """A slow sine of angle ``amplitude`` (rad) with a constant feed-forward current ``ff`` (A)."""

    name: ClassVar[str] = "sine_hold"
    MODES: ClassVar[tuple[str, ...]] = ("position",)
    SPECS: ClassVar[dict[str, ParameterSpec]] = {
        "duration": ParameterSpec("s", 0.1, 10.0, "length"),
        "amplitude": ParameterSpec("rad", 0.0, 1.0, "sine amplitude"),
        "ff": ParameterSpec("A", -5.0, 5.0, "feed-forward current"),
    }
    duration: float = 0.5
    amplitude: float = 2e-3
    ff: float = 0.25
    mode: str = "position"
    sample_rate: int = FS

    def excitation(self, limit: float | None = None) -> excitations.Excitation:
        t = np.arange(self.n_samples) / self.sample_rate
        u = self.amplitude * np.sin(2 * np.pi * 2.0 * t)
        return excitations.Excitation(u=u, fs=self.sample_rate, mode="position", name=self.name, params={})

    def feedforward(self, limit: float) -> np.ndarray:
        return np.full(self.n_samples, self.ff)


@pytest.fixture(scope="module")
def position_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("pos") / "run.h5"
    settings = DeviceSettings(counts_per_rev=CPR, current_limit=10.0)
    with Bench.open("sim://?pacing=lockstep", settings) as bench:
        result = bench.run(SineHold(), out)
    return result, out


def test_a_position_run_with_feedforward_writes_its_reference(position_run):
    result, out = position_run
    assert result.status == "completed" and result.samples == 5000
    with h5py.File(out, "r") as f:
        s = f["samples"]
        assert s["position_cmd"].attrs["unit"] == "rad" and s["current_ff"].attrs["unit"] == "A"
        ref, pos, ff = s["position_cmd"][:], s["position"][:], s["current_ff"][:]
        config = json.loads(f["device/config"][()])
        assert f.attrs["schema_version"] == 2
        np.testing.assert_array_equal(f["protocol/feedforward"][:], np.full(5000, 0.25))
    assert config["mode"] == 2 and config["feedforward"] is True and config["position_kp"] > 0
    np.testing.assert_allclose(ff, 0.25)
    t = np.arange(5000) / FS
    np.testing.assert_allclose(ref, np.float32(2e-3 * np.sin(2 * np.pi * 2.0 * t)), rtol=0, atol=1e-9)
    # the loop follows the 2 mrad sine (through reversals in sliding friction) after its first 50 ms
    err = pos[500:] - ref[500:]
    print(f"tracking error: rms {np.sqrt(np.mean(err**2)):.3g} rad, max {np.max(np.abs(err)):.3g} rad")
    assert np.sqrt(np.mean(err**2)) < 2.5e-4 and np.max(np.abs(err)) < 5e-4
