"""The typed device identity: validated when a run file opens, stored as the flat JSON object older files hold."""

import json

import h5py
import numpy as np
import pytest

from hilbench.common.runfile import HOST_TIME, DeviceIdentity, RunFileError, RunWriter, host_sampled, open_run


@pytest.mark.parametrize(("device", "reason"), [
    ({"sample_times": "sync"}, "sample_times must be one of device, host_time, drive"),
    ({"serial": 17}, "serial must be text"),
    ({"node": object()}, "node is not JSON-serialisable"),
    ("sim", "device identity must be a mapping"),
])
def test_the_writer_refuses_a_bad_identity_in_one_line_before_touching_the_file(tmp_path, device, reason):
    path = tmp_path / "r.h5"
    with pytest.raises(RunFileError, match=reason) as caught:
        RunWriter(path, sample_rate=1000.0, device=device)
    assert str(caught.value).startswith(f"{path}: ") and "\n" not in str(caught.value)
    assert list(tmp_path.iterdir()) == []  # nothing written, no lock left


def test_the_identity_round_trips_as_a_flat_object_and_says_whose_clock(tmp_path):
    ident = DeviceIdentity(protocol="CiA 402 over CANopen", serial="42", sample_times=HOST_TIME,
                           details={"rated_torque_Nm": 0.5})
    path = tmp_path / "r.h5"
    with RunWriter(path, sample_rate=1000.0, channels=("sample_index", "t", HOST_TIME), device=ident) as w:
        w.append({"sample_index": np.arange(3), "t": np.arange(3) / 1e3, HOST_TIME: np.arange(3) / 1e3})
    with h5py.File(path) as f:
        stored = json.loads(f["device/identity"][()])
    assert stored == {"protocol": "CiA 402 over CANopen", "serial": "42", "sample_times": "host_time",
                      "rated_torque_Nm": 0.5}
    with open_run(path) as run:
        assert run.identity == ident and host_sampled(run.device, run.channels)
    assert DeviceIdentity(model="m").as_json() == {"model": "m"}  # a device-clocked run stores no sample_times
