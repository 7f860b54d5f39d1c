"""``hilbench paper --quick`` smoke test and the closed forms the reproduction is checked against."""

import json

import numpy as np
import pytest

from hilbench.analysis.reproductions.paper import afrf_db_error, maxwell_slip_closed_form, virgin_closed_form
from hilbench.analysis.reproductions.paper_figures import FIGURES
from hilbench.bench.cli import main
from hilbench.firmware_sim.engine.friction_models import paper_system
from hilbench.firmware_sim.engine.plant import stop_operator
from tests.figure_checks import recording_figures


def test_maxwell_slip_closed_form_against_simulated_loops():
    # Independent oracle: drive the stop operators with x = A*sin(theta) (3 cycles, 20000 points each), take
    # the last cycle's in-phase first harmonic k_eq = (1/(pi*A)) * int F sin(theta) dtheta and the loop area
    # E = closed integral of F dx. Quadrature on 20000 points: 1e-3 relative.
    p = paper_system()
    k, w = np.asarray(p.ms_stiffness), np.asarray(p.ms_slip)
    amps = np.array([0.002, 0.05, 0.5, 3.0])
    k_cf, e_cf = maxwell_slip_closed_form(p, amps)
    th = np.linspace(0, 6 * np.pi, 60001)
    last = th >= 4 * np.pi
    for a, kc, ec in zip(amps, k_cf, e_cf, strict=True):
        x = a * np.sin(th)
        f = stop_operator(x, w / k) @ k
        keq = np.trapezoid(f[last] * np.sin(th[last]), th[last]) / (np.pi * a)
        energy = np.trapezoid(f[last], x[last])
        assert keq == pytest.approx(kc, rel=1e-3)
        assert energy == pytest.approx(ec, rel=1e-3, abs=1e-9)
    # and the 16-element model approaches the continuous virgin curve's closed forms (discretisation: 3 %)
    kv, _ = virgin_closed_form(amps)
    np.testing.assert_allclose(k_cf, kv, rtol=0.03)


def test_afrf_db_error():
    ref = np.array([[1.0, 1e-3, 1e-9], [0.1, 1e-4, 0.0]])
    model = ref * np.array([[10.0, 1.0, 5.0], [10.0, 1.0, 1.0]])
    # H1 is 20 dB off everywhere; H2 equal; H3 below the floor (1e-4 of 1.0) in both -> 0 dB
    np.testing.assert_allclose(afrf_db_error(model, ref), [20.0, 0.0, 0.0], atol=1e-9)


@pytest.fixture(scope="module")
def quick_paper(tmp_path_factory):
    out = tmp_path_factory.mktemp("paper")
    with recording_figures() as seen:  # issue 13: every axis labelled with a unit, no empty legend
        assert main(["paper", "--quick", "-o", str(out), "--json", str(out / "copy.json")]) == 0
    return out, json.loads((out / "summary.json").read_text()), seen


def test_paper_quick_writes_every_figure_and_summary(quick_paper):
    out, doc, seen = quick_paper
    assert set(seen) == set(FIGURES)
    assert not any(seen.values()), {k: v for k, v in seen.items() if v}
    for name in FIGURES:
        assert (out / name).stat().st_size > 10_000, name
    md = (out / "summary.md").read_text()
    assert all(name in md for name in FIGURES)
    assert "Inferred settings" in md and "FAIL" not in md
    assert json.loads((out / "copy.json").read_text()) == doc


def test_paper_quick_numbers_meet_the_tolerances(quick_paper):
    _, doc, _ = quick_paper
    assert all(doc["checks"].values()), doc["checks"]
    sk = doc["skeleton"]
    # k_eq within 5 % of the 16-element and of the continuous closed forms over the excited range
    assert sk["max_k_16"] < 0.05 and sk["max_k_continuous"] < 0.05
    assert sk["excited_range"][0] < 0.01 and sk["excited_range"][1] > 3.0
    # energy (A >= 0.1 m): median within 5 % of the continuous closed form, and every bin within 5 % of the
    # closed form of the simulated 16-element model (measured 4.1 %)
    # for A >= 0.1 (where the loss matters: E >= 7 % of the Coulomb limit 4hA)
    assert sk["median_E_continuous_checked"] < 0.05 and sk["max_E_16_checked"] < 0.05
    # the 64-element system (discretisation < 0.6 %): every bin from 0.01 m within 5 % of the continuous
    # closed forms (measured 4.1 % in E; k_eq 1.1 % over every bin)
    skc = doc["skeleton_continuous"]
    assert skc["elements"] == 64 and skc["checked_from"] <= 0.01
    assert skc["max_E_continuous_checked"] < 0.05 and skc["max_k_continuous"] < 0.02
    sim = doc["afrf_simulated"]
    # the paper's claim: the equivalent follows the original at low amplitude where Coulomb sticks (no
    # motion: > 40 dB off); at the largest amplitude both are within 3 dB on the first harmonic
    assert sim["equivalent"][0]["rms_db"][0] < 6.0 < 40.0 < sim["coulomb"][0]["rms_db"][0]
    assert sim["equivalent"][-1]["rms_db"][0] < 3.0 and sim["coulomb"][-1]["rms_db"][0] < 3.0
    motor = doc["afrf_motor"]
    assert motor["equivalent"][0]["rms_db"][0] < 6.0 < 40.0 < motor["coulomb"][0]["rms_db"][0]
    assert motor["equivalent"][-1]["rms_db"][0] < 1.0


def test_paper_bad_output(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    assert main(["paper", "-o", str(f)]) == 2
    assert "not a folder" in capsys.readouterr().err
