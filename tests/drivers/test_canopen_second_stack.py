"""Issue #25: the CiA 402 driver against a drive built on a second CANopen stack (tests/drivers/second_stack.py,
written over python-can frames, sharing no code with the simulated drive, the driver or the ``canopen`` package),
through the CLI with a device URL that points at it: an identification run and a stepped sine run.

Oracle: the drive's own trace (what it sent at every SYNC) and its plant's closed form: the run file must hold
exactly the drive's samples, in order, and the drive's applied torque must be the host's command rounded to per
mille of the rated torque.
"""

from __future__ import annotations

import math
import uuid

import h5py
import numpy as np
import pytest

from hilbench.bench.acquisition.protocols import SteppedSine
from hilbench.bench.cli import main
from hilbench.firmware_sim.devices.cia402_drive import EDS_PATH
from tests.drivers.second_stack import SecondStackDrive

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]  # starts a device


@pytest.fixture
def drive():
    channel = f"s-{uuid.uuid4().hex[:8]}"
    responder = SecondStackDrive(channel, 5)
    yield responder, f"canopen://virtual/{channel}?node=5&eds={EDS_PATH}"
    responder.close()


def test_identification_through_the_cli(drive, tmp_path):
    responder, url = drive
    out = tmp_path / "id.h5"
    assert main(["run", "identify", "--device", url, "--sample-rate", "1000", "--duration", "2", "--amplitude",
                 "2", "--quiet", "-o", str(out)]) == 0
    trace = np.array(responder.trace)
    with h5py.File(out) as f:
        assert f.attrs["status"] == "completed"
        s = f["samples"]
        counts, torque, velocity, torque_cmd = s["counts"][:], s["torque"][:], s["velocity"][:], s["torque_cmd"][:]
        events = [m.decode() for m in f["events"]["message"][:]]
    assert counts.size == 2000 and len(trace) == 2001  # one stream: its samples and the answer to the end SYNC
    np.testing.assert_array_equal(counts, trace[:2000, 0])
    np.testing.assert_allclose(velocity, trace[:2000, 1] * 2 * math.pi / 2**20, rtol=0, atol=1e-12)
    np.testing.assert_allclose(torque, trace[:2000, 2] * 0.5 / 1000, rtol=0, atol=1e-12)
    # the drive applies command k from SYNC k on: its torque actual at k+1 is the command k, to 1 per mille
    np.testing.assert_allclose(torque[1:], torque_cmd[:-1], rtol=0, atol=0.5e-3 + 1e-12)
    assert np.ptp(counts) > 1000  # it moved
    # the objects the EDS names and this drive lacks were skipped, saying so
    assert any("0x607D:1 (software position limit, min) is not in the drive" in e for e in events), events
    # the closed form of the plant (J w' = tau - b w, torque held over each 1 ms cycle) gives the same positions
    j, b, dt = responder.inertia, responder.viscous, 1e-3
    a = math.exp(-b * dt / j)
    theta = w = 0.0
    expected = []
    for tau in torque_cmd:  # sample k is taken before command k acts
        expected.append(round(theta * 2**20 / (2 * math.pi)))
        theta += tau / b * dt + (w - tau / b) * (1 - a) * j / b
        w = a * w + (1 - a) * tau / b
    np.testing.assert_allclose(counts, expected, rtol=0, atol=1)  # per-mille rounding of the command: 0 here


def test_stepped_sine_through_the_cli(drive, tmp_path):
    responder, url = drive
    out = tmp_path / "afrf.h5"
    assert main(["run", "afrf", "--device", url, "--sample-rate", "1000", "--frequencies", "10", "20", "40",
                 "--amplitudes", "1", "--settle-periods", "1", "--measure-periods", "2", "--quiet",
                 "-o", str(out)]) == 0
    with h5py.File(out) as f:
        assert f.attrs["status"] == "completed"
        counts, status = f["samples/counts"][:], f["samples/drive_status"][:].astype(int)
        planned = f["protocol/setpoints"].shape[0]
    trace = np.array(responder.trace)
    steps = SteppedSine(frequencies=[10.0, 20.0, 40.0], amplitudes=[1.0], settle_periods=1, measure_periods=2,
                        sample_rate=1000).segments()
    # one stream per step: each SYNC answered, plus each stream's end SYNC (which the host drops); the file holds
    # every sample of every step, and they are the drive's, in order
    assert counts.size == planned == steps[-1][1] and len(trace) == planned + len(steps)
    rows = np.concatenate([np.arange(a, b) + i for i, (a, b) in enumerate(steps)])
    np.testing.assert_array_equal(counts, trace[rows, 0])
    np.testing.assert_array_equal(status, trace[rows, 3])
    assert set(int(w) & 0x6F for w in status) <= {0x27, 0x23}  # operation enabled, or switched on while enabling
    assert np.ptp(counts) > 1000  # it moved
