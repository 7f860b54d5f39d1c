"""Fixtures for device-link tests: simulator configs with injected effects, and a simulator process."""

import pytest

from hilbench.drivers.device_url import start_simulator, stop_simulator

# A plant with injected effects, so that "bit for bit" covers the noise generator and its seed too.
EFFECTS_TOML = """
[device]
serial = "SIM-TEST"
buffer_capacity = 8192

[plant]
preset = "dc_motor"
elements = 8
substeps = 2
seed = {seed}
noise_current = {noise_current}
noise_position = 1e-4
current_lag = 2e-4
torque_offset = 0.01
velocity_kp = 0.02
velocity_ki = 0.5

[[plant.cogging]]
order = 6
amplitude = 0.02
"""


@pytest.fixture
def sim_toml(tmp_path):
    def write(seed: int = 7, noise_current: float = 0.003, name: str = "sim.toml") -> str:
        path = tmp_path / name
        path.write_text(EFFECTS_TOML.format(seed=seed, noise_current=noise_current))
        return str(path)

    return write


@pytest.fixture
def simulator():
    """Start simulators (``python -m hilbench.firmware_sim --serial``); yields a starter returning (proc, pty path)."""
    procs = []

    def start(**options):
        proc, path = start_simulator({k: str(v) for k, v in options.items()})
        procs.append(proc)
        return proc, path

    yield start
    for proc in procs:
        stop_simulator(proc)
