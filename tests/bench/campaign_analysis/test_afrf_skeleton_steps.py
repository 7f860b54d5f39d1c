"""The afrf and skeleton steps of ``hilbench analyse`` (#27: each run gets the steps its protocol supports), on a
small lockstep campaign of one stepped-sine and one chirp run. Each row is checked against its own command on the
same run file and against a closed form of the simulated plant: the dc_motor preset with a linear spring."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from hilbench.bench.acquisition.campaign import load_campaign, run_campaign
from hilbench.bench.cli import main
from hilbench.firmware_sim.engine.friction_models import dc_motor

SPRING = 5.0  # N*m/rad: the chirp sweeps through sqrt(K/J)/(2 pi) = 7.6 Hz, as the skeleton method needs

TOML = """
[defaults]
device = "sim://?pacing=lockstep&config={config}"
sample_rate = 1000
current_limit = "8 A"
counts_per_rev = 4294967295   # 1.5 nrad: the presliding step of 0.01 A moves 0.7 urad

[[run]]
name = "afrf"
protocol = "stepped_sine"
frequencies = [2.0, 5.0]
amplitudes = ["0.01 A", "6 A"]
settle_periods = 3
measure_periods = 4

[[run]]
name = "sk"
protocol = "chirp"
gain = "6 A"
duration = "6 s"
rate = "2 Hz/s"
"""


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    d = tmp_path_factory.mktemp("afrf_skeleton")
    (d / "sim.toml").write_text(f'[plant]\npreset = "dc_motor"\nspring = {SPRING}\n')
    (d / "c.toml").write_text(TOML.format(config=d / "sim.toml"))
    run_campaign(load_campaign(d / "c.toml"), d / "c")
    return d / "c"


@pytest.fixture(scope="module")
def rows(campaign, tmp_path_factory):
    out = tmp_path_factory.mktemp("results")
    assert main(["-q", "analyse", str(campaign), "-o", str(out), "--serial", "--steps", "afrf,skeleton,presliding",
                 "--skeleton-mass", str(dc_motor().inertia)]) == 0
    table = pq.read_table(out / "results.parquet")
    return {r["step"]: r for r in table.to_pylist()}, table.schema


def test_each_run_gets_the_step_of_its_protocol_with_unit_named_columns(rows):
    by_step, schema = rows
    assert {(s, r["protocol"], r["status"]) for s, r in by_step.items()} == {("afrf", "stepped_sine", "ok"),
                                                                            ("skeleton", "chirp", "ok")}
    unit = {f.name: f.metadata[b"unit"].decode() for f in schema}
    assert unit["afrf_compliance_low_amplitude"] == "rad/(N*m)" and unit["afrf_frequency_min"] == "Hz"
    assert unit["skeleton_stiffness_high_amplitude"] == "N*m/rad" and unit["skeleton_amplitude_max"] == "rad"


def test_afrf_row_is_hilbench_afrf_and_the_presliding_compliance(rows, campaign, tmp_path):
    row = rows[0]["afrf"]
    assert main(["-q", "afrf", str(campaign / "afrf-1.h5"), "--json", str(tmp_path / "a.json")]) == 0
    doc = json.loads((tmp_path / "a.json").read_text())
    mag, drive = np.array(doc["magnitude"]), np.array(doc["drive_magnitude"])  # [amplitude][frequency](harmonic)
    assert row["afrf_steps"] == 4 and (row["afrf_frequency_min"], row["afrf_frequency_max"]) == (2.0, 5.0)
    assert row["afrf_compliance_low_amplitude"] == pytest.approx(mag[0, 0, 0] / drive[0, 0], rel=1e-9)
    assert row["afrf_compliance_high_amplitude"] == pytest.approx(mag[1, 0, 0] / drive[1, 0], rel=1e-9)
    # closed form: at 0.01 A (2 mN*m) the 16 Maxwell-slip elements all stick (0.7 urad, under the smallest slip
    # deflection 2.5 urad), so the axis is linear: |X/T| = 1/|K - J w^2 + j w b| with K = sum k_i + spring
    p = dc_motor()
    w = 2 * np.pi * 2.0
    closed = 1 / abs(float(np.sum(p.ms_stiffness)) + SPRING - p.inertia * w**2 + 1j * w * p.viscous)
    assert row["afrf_compliance_low_amplitude"] == pytest.approx(closed, rel=1e-3)  # measured 2e-5
    # at 6 A (1.2 N*m, above the 0.76 N*m break-away) the elements slide: far more compliant than presliding
    assert row["afrf_compliance_high_amplitude"] > 100 * row["afrf_compliance_low_amplitude"]


def test_skeleton_row_is_hilbench_skeleton_and_tends_to_the_spring(rows, campaign, tmp_path):
    row = rows[0]["skeleton"]
    assert main(["-q", "skeleton", str(campaign / "sk-1.h5"), "--mass", str(dc_motor().inertia), "--json",
                 str(tmp_path / "s.json")]) == 0
    doc = json.loads((tmp_path / "s.json").read_text())
    a, k = np.array(doc["amplitude"], float), np.array(doc["stiffness"], float)
    assert row["skeleton_bins"] == a.size and row["skeleton_amplitude_max"] == pytest.approx(a.max(), rel=1e-12)
    assert row["skeleton_stiffness_low_amplitude"] == pytest.approx(k[np.argmin(a)], rel=1e-12)
    assert row["skeleton_stiffness_high_amplitude"] == pytest.approx(k[np.argmax(a)], rel=1e-12)
    # sliding over 0.7 rad, friction's first harmonic is in quadrature with the displacement (damping): k_eq
    # tends to the linear spring. The in-phase part of a loop whose presliding distance is d (at most 0.02 rad,
    # the largest element) is of order F_b*d/A^2 = 0.76*0.02/0.5 = 0.03 N*m/rad, 0.6 % of it; 5 % bound,
    # measured 0.2 %
    assert row["skeleton_stiffness_high_amplitude"] == pytest.approx(SPRING, rel=0.05)


def test_a_skeleton_without_a_mass_is_a_failed_row_with_the_reason(campaign, tmp_path):
    assert main(["-q", "analyse", str(campaign), "-o", str(tmp_path / "r"), "--serial", "--steps", "skeleton"]) == 0
    (row,) = pq.read_table(tmp_path / "r" / "results.parquet").to_pylist()
    assert row["status"] == "failed" and "declares no inertia" in row["error"]
