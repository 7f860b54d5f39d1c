"""The ``presliding`` protocol: nested-reversal reference (closed forms), a short run on the simulated DC
motor with current noise at 2**16 counts/rev (the measured displacement follows the reference), and the
one-line refusals of bad parameters."""

from __future__ import annotations

import json
import math

import h5py
import numpy as np
import pytest

from hilbench.bench.acquisition import excitations
from hilbench.bench.acquisition.protocols import Presliding, ProtocolError, make_protocol
from hilbench.bench.acquisition.runner import Bench, DeviceSettings
from hilbench.bench.cli import main

CPR = 1 << 16
COUNT = 2 * math.pi / CPR  # rad, one encoder count
D = 5e-4  # rad, the DC-motor preset's presliding distance
SIM_NOISE = """[device]
model = "HB-SIM-1"
serial = "SIM-0001"
buffer_capacity = 8192
[plant]
preset = "dc_motor"
elements = 16
seed = 3
noise_current = 0.01
"""


def test_nested_reversal_points_closed_form():
    assert excitations.nested_reversal_points((4, 3, 2, 1)).tolist() == [0, 4, -3, 2, -1, 2, -3, 4]
    assert excitations.nested_reversal_points((4, 3, 2, 1), close_inner=False).tolist() == [0, 4, -3, 2, -1, 4]
    assert excitations.nested_reversal_points((2, 1), repeats=2).tolist() == [0, 2, -1, 2, -1, 2]
    assert excitations.nested_reversal_points((3,), repeats=3).tolist() == [0, 3]
    with pytest.raises(ValueError, match="non-increasing"):
        excitations.nested_reversal_points((1, 2))


def test_reversal_path_is_constant_speed_and_ends_on_each_point():
    points = np.array([0.0, 2e-3, -1.5e-3, 1e-3])
    rate, settle, fs = 1e-2, 0.01, 10000.0
    u, turning = excitations.reversal_path(points, rate, settle, fs)
    np.testing.assert_array_equal(turning["position"], points)
    np.testing.assert_allclose(u[turning["index"]], points, rtol=0, atol=1e-18)
    hold = 100
    assert np.all(u[:hold] == 0) and turning["index"][1] == hold + 2000 - 1  # 2 mrad at 10 mrad/s = 0.2 s
    for j in range(1, points.size):  # each turning point is held `settle` s
        i = turning["index"][j]
        assert np.all(u[i: i + hold + 1] == points[j])
    steps = np.abs(np.diff(u))
    moving = steps > 0
    np.testing.assert_allclose(steps[moving], rate / fs, rtol=1e-9)
    assert u.size == hold * points.size + int(np.sum(np.round(np.abs(np.diff(points)) / rate * fs)))


@pytest.mark.parametrize("values", [
    {}, {"unit": "rad", "amplitudes": (1e-3, 4e-4), "rate": 3.3e-3, "settle": 0.0123, "cycles": 3},
    {"unit": "m", "m_per_rad": 0.01, "amplitudes": (2e-5, 2e-5, 1e-5), "rate": 1e-4, "close_inner": "no"},
    {"amplitudes": (1.0,), "sample_rate": 20000},
])
def test_planned_samples_match_the_reference(values):
    proto = Presliding(**values)
    u = proto.excitation().u
    assert proto.n_samples == u.size  # from the parameters alone, before any array is built
    np.testing.assert_allclose(np.max(np.abs(u)), proto.amplitudes[0] * proto.rad_per_unit, rtol=1e-12)


@pytest.mark.parametrize("values, message", [
    ({"amplitudes": (1.0, 2.0)}, "must not increase"),
    ({"unit": "m"}, "m_per_rad > 0"),
    ({"mode": "current"}, "presliding runs in position mode"),
    ({"amplitudes": (3e4,)}, "outside"),
    ({"unit": "rad", "amplitudes": (20.0,)}, "presliding bound of 10 rad"),
    ({"close_inner": "maybe"}, "close_inner must be one of"),
])
def test_bad_parameters_are_refused(values, message):
    with pytest.raises(ProtocolError, match=message):
        make_protocol("presliding", values)


@pytest.mark.parametrize("argv, message", [
    (["--amplitudes", "1", "2"], "must not increase"),
    (["--unit", "m"], "m_per_rad > 0"),
    (["--rate", "-1"], "--rate -1"),
    (["--position-kp", "-5"], "--position-kp -5.0 A/rad"),  # the option, not the Python field
])
def test_cli_refuses_bad_parameters_in_one_line(argv, message, capsys, tmp_path):
    assert main(["run", "presliding", "-o", str(tmp_path / "x.h5"), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err
    assert not (tmp_path / "x.h5").exists()


@pytest.fixture(scope="module")
def presliding_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("presliding")
    (tmp / "sim.toml").write_text(SIM_NOISE)
    out = tmp / "presliding.h5"
    proto = Presliding(amplitudes=(4.0, 2.0, 1.0), rate=10.0, settle=0.05)
    with Bench.open(f"sim://?pacing=lockstep&config={tmp / 'sim.toml'}", DeviceSettings(counts_per_rev=CPR)) as b:
        result = b.run(proto, out)
    return proto, result, out


def test_presliding_run_is_a_displacement_driven_record(presliding_run):
    proto, result, out = presliding_run
    assert result.status == "completed" and result.samples == proto.n_samples
    with h5py.File(out, "r") as f:
        assert f.attrs["record"] == "displacement-driven" and f.attrs["schema_version"] == 2
        s = f["samples"]
        assert s["position_cmd"].attrs["unit"] == "rad" and s["position"].attrs["unit"] == "rad"
        assert s["torque"].attrs["unit"] == "N*m" and "current_ff" not in s
        turning = f["protocol/turning_points"][:]
        np.testing.assert_allclose(turning["position"], np.array([0, 4, -2, 1, -2, 4]) * D, rtol=1e-12)
        assert f["protocol"].attrs["name"] == "presliding"


def test_measured_displacement_follows_the_reference(presliding_run):
    """Quasi-static at 5 mrad/s with 10 mA rms current noise: within 1.5 counts rms and 3 counts at worst;
    at the end of each settle hold the angle is within 1 count of the turning point."""
    proto, _, out = presliding_run
    with h5py.File(out, "r") as f:
        ref, pos = f["samples/position_cmd"][:], f["samples/position"][:]
        turning = f["protocol/turning_points"][:]
    err = pos - ref
    rms, worst = float(np.sqrt(np.mean(err**2))), float(np.max(np.abs(err)))
    print(f"tracking: rms {rms / COUNT:.2f} counts, max {worst / COUNT:.2f} counts")
    assert rms < 1.5 * COUNT and worst < 3 * COUNT
    hold = round(proto.settle * proto.sample_rate)
    settled = pos[turning["index"][1:] + hold]
    assert np.all(np.abs(settled - turning["position"][1:]) <= COUNT * 1.0001)


def test_a_campaign_plays_presliding_with_gains_and_units(tmp_path, capsys):
    toml = tmp_path / "c.toml"
    toml.write_text('[defaults]\ndevice = "sim://?pacing=lockstep"\ncounts_per_rev = 65536\n'
                    'position_kp = "2500 A/rad"\n\n[[run]]\nname = "pre"\nprotocol = "presliding"\n'
                    'amplitudes = [4, 2, 1]\nrate = 20\nsettle = "0.02 s"\n')
    assert main(["campaign", str(toml), "--check"]) == 0
    assert "pre-1: presliding 1.2 s (12200 samples" in capsys.readouterr().out
    toml.write_text(toml.read_text().replace('"0.02 s"', '"0.02 A"'))
    assert main(["campaign", str(toml), "--check"]) == 2
    assert "settle" in capsys.readouterr().err


def test_settings_come_from_the_config_file_under_the_options(tmp_path, monkeypatch, capsys):
    cfg = tmp_path / "config.toml"
    cfg.write_text('device = "sim://?pacing=lockstep"\n[settings]\ncounts_per_rev = 65536\nposition_kp = 2500.0\n'
                   'position_kd = 6\n')
    monkeypatch.setenv("HILBENCH_CONFIG", str(cfg))
    monkeypatch.delenv("HILBENCH_DEVICE", raising=False)
    out = tmp_path / "p.h5"
    assert main(["run", "presliding", "--amplitudes", "2", "1", "--rate", "50", "--settle", "0", "--quiet",
                 "--position-kd", "4", "-o", str(out)]) == 0
    with h5py.File(out, "r") as f:
        config = json.loads(f["device/config"][()])
    assert (config["counts_per_rev"], config["position_kp"], config["position_kd"]) == (65536, 2500.0, 4.0)
    # what neither the file nor the options set comes from the protocol's recommendation, then the defaults
    assert config["position_ki"] == Presliding.RECOMMENDED_SETTINGS["position_ki"] == 3.0e4
    assert config["position_i_limit"] == DeviceSettings().position_i_limit
    cfg.write_text('[settings]\nposition_gain = 1.0\n')
    assert main(["run", "presliding", "-o", str(tmp_path / "q.h5")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "position_gain is not a device setting" in err
