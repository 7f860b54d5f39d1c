"""Issue 38: campaign files that mean one thing. `repeats` is the number of runs everywhere (the presliding loop
count is `cycles`), plan's TOML takes `repeats = 3` on every run, writes no placeholder and carries the inertia
it measured into every run file ([plant] -> calibration), and a relative path in a device URL is read from the
campaign file's folder, checked before anything moves."""

from __future__ import annotations

import re
import warnings

import pytest

from hilbench.bench.acquisition.breakaway_probe import ProbeResult
from hilbench.bench.acquisition.campaign import CampaignError, load_campaign, run_campaign
from hilbench.bench.acquisition.planning import Plan, size_protocols
from hilbench.bench.acquisition.protocols import Presliding, make_protocol
from hilbench.bench.acquisition.runner import DeviceSettings
from hilbench.bench.cli import main
from hilbench.common.runfile import open_run

KT = 0.2  # N*m/A, the default calibration
PROBE = ProbeResult("probe.h5", 6.0, (3.7, -3.5, 3.5), 1.1e-3, 0.05,
                    {"positive": 3.8, "negative": -3.8, "inertia_per_kt": 0.011, "viscous_per_kt": 0.02})


def _plan_toml(device: str = "sim://?pacing=lockstep") -> str:
    settings = DeviceSettings(current_limit=20.0, torque_constant=KT)
    runs, notes = size_protocols(PROBE, settings, duration=2.0)
    return Plan(device, settings, PROBE, ["probe.h5"], runs, notes).toml()


@pytest.mark.device_free
def test_plans_toml_takes_repeats_on_every_run_and_writes_no_placeholder(tmp_path):
    text = _plan_toml()
    assert not re.search(r"^repeats\s*=", text, re.M)  # the loop count is `cycles`: `repeats` is free to add
    assert "0 m/rad" not in text and "0 kg*m^2" not in text and "unit/s" not in text
    chirp = text.split('name = "chirp"')[1].split("[[run]]")[0]
    assert 'sweep = "log"' in chirp and not re.search(r"^rate\s*=", chirp, re.M)  # no quadratic rate on a log sweep
    assert re.search(r'^\[plant\]\ninertia = "0.0022 kg\*m\^2"$', text, re.M)  # J = 0.011 A*s^2/rad x 0.2 N*m/A
    edited = re.sub(r'^(protocol = "[a-z_]+")$', r"\1\nrepeats = 3", text, flags=re.M)  # the obvious edit
    campaign = load_campaign(_write(tmp_path / "plan.toml", edited))
    assert [r.key for r in campaign.runs][:3] == ["identification-1", "identification-2", "identification-3"]
    assert len(campaign.runs) == 12
    presliding = [r for r in campaign.runs if r.name == "presliding"]
    assert [p.protocol.cycles for p in presliding] == [1, 1, 1]
    assert presliding[0].protocol.inertia == pytest.approx(0.0022)
    assert all(r.plant == {"inertia": pytest.approx(0.0022)} for r in campaign.runs)


@pytest.mark.device_free
def test_presliding_loop_count_is_cycles_and_its_old_name_is_read_with_a_note():
    with pytest.warns(DeprecationWarning, match="'repeats' is now 'cycles'"):
        old = make_protocol("presliding", {"amplitudes": [2.0, 1.0], "repeats": 3})
    assert old == Presliding(amplitudes=(2.0, 1.0), cycles=3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert make_protocol("presliding", {"amplitudes": [2.0, 1.0], "cycles": 2}).cycles == 2


def _write(path, text):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


CAMPAIGN = """
[defaults]
device = "sim://?pacing=lockstep&config={config}"

[plant]
inertia = "{inertia}"

[[run]]
name = "id"
protocol = "identification"
repeats = 2
duration = "0.3 s"
amplitude = "2 A"
"""


@pytest.mark.device_free
def test_a_relative_simulator_config_is_read_from_the_campaign_folder(tmp_path, monkeypatch, capsys):
    folder = tmp_path / "lab"
    _write(folder / "sims" / "paper.toml", '[plant]\npreset = "paper_system"\n')
    path = _write(folder / "c.toml", CAMPAIGN.format(config="sims/paper.toml", inertia="1 kg*m^2"))
    monkeypatch.chdir(tmp_path)  # not the campaign's folder: the path must not depend on where we stand
    device = load_campaign(path).device
    assert f"config={folder / 'sims' / 'paper.toml'}" in device
    missing = _write(folder / "m.toml", CAMPAIGN.format(config="sims/nope.toml", inertia="1 kg*m^2"))
    with pytest.raises(CampaignError, match=r"m.toml:3: run 1: device option config=sims/nope.toml: no file"):
        load_campaign(missing)
    assert main(["campaign", str(missing), "--check"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "config=sims/nope.toml" in err
    bad = _write(folder / "b.toml", CAMPAIGN.format(config="sims/paper.toml", inertia="1 kg"))
    with pytest.raises(CampaignError, match=r"\[plant\] inertia: unit 'kg' is wrong, expected 'kg\*m\^2'"):
        load_campaign(bad)


def test_the_plants_inertia_reaches_every_run_files_calibration(tmp_path):  # lockstep: unpaced
    """What the skeleton step reads when no --skeleton-mass is given (analysis.skeleton.run_mass)."""
    _write(tmp_path / "sim.toml", "[plant]\npreset = \"dc_motor\"\n")
    campaign = load_campaign(_write(tmp_path / "c.toml", CAMPAIGN.format(config="sim.toml",
                                                                         inertia="0.00211 kg*m^2")))
    run_campaign(campaign, tmp_path / "out")
    for key in ("id-1", "id-2"):
        with open_run(tmp_path / "out" / f"{key}.h5") as run:
            assert run.calibration["inertia"] == pytest.approx(0.00211)
            assert run.calibration["units"]["inertia"] == "kg*m^2"
