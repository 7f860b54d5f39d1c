"""The feed-forward of every family along a reference, against independent oracles: closed forms (Coulomb,
viscous, Stribeck, J*q'', the continuous model's Masing loop), tests/truth (Maxwell-slip stop operators,
LuGre and Dahl by LSODA), a GMS integrator written here from its equations, and the plant driven open-loop
by the feed-forward torque (it must follow the reference)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hilbench.analysis.compensation.feedforward import (
    Compensator,
    coulomb_at_breakaway,
    feedforward,
    feedforward_torque,
    load_compensators,
)
from hilbench.analysis.compensation.references import point_to_point, slow_sine, triangle
from hilbench.analysis.errors import AnalysisError
from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import GMS, Hysteresis, LuGre, PlantParams, simulate, stiffest_eigenvalue
from tests.truth.generator import Truth, displacement_ode, stop_operator_forces

FS = 2000.0
J = 0.0022
B = 0.004


@pytest.fixture(scope="module")
def sine():
    return slow_sine(FS, amplitudes=(4e-4, 1e-2), frequency=1.0, cycles=2, rest=0.05)


def test_coulomb_viscous_and_inertia_closed_form(sine):
    p = PlantParams(inertia=J, coulomb=0.7, viscous=B, torque_offset=-0.05)
    tau = feedforward_torque(p, sine)
    expect = J * sine.acceleration + 0.7 * np.sign(sine.velocity) + B * sine.velocity + 0.05
    assert np.max(np.abs(tau - expect)) < 1e-12


def test_stribeck_closed_form(sine):
    p = PlantParams(inertia=J, coulomb=0.6, static=0.8, stribeck_velocity=0.05, viscous=B)
    v = sine.velocity
    expect = J * sine.acceleration + (0.6 + 0.2 * np.exp(-(v / 0.05) ** 2)) * np.sign(v) + B * v
    assert np.max(np.abs(feedforward_torque(p, sine) - expect)) < 1e-12


def test_maxwell_slip_against_exact_stop_operators(sine):
    p = dc_motor(16).replace(torque_constant=1.0)
    k = np.asarray(p.ms_stiffness)
    w = np.asarray(p.ms_slip)
    expect = J * sine.acceleration + stop_operator_forces(k, w, sine.position) + B * sine.velocity
    # exact up to rounding (measured 3e-16 N*m)
    assert np.max(np.abs(feedforward_torque(p, sine) - expect)) < 1e-12


@pytest.mark.parametrize("family", ["dahl", "lugre"])
def test_dahl_and_lugre_against_the_lsoda_truth(family):
    ref = slow_sine(FS, amplitudes=(1e-3,), frequency=1.0, cycles=1, rest=0.0)
    tr = Truth(family=family, inertia=J, coulomb=0.6, viscous=B, presliding=1e-3,
               stribeck_excess=0.2 if family == "lugre" else 0.0, stribeck_velocity=0.01)
    sigma0 = 2 * tr.coulomb / tr.presliding
    sigma1 = 2 * math.sqrt(sigma0 * J) * 0.3 if family == "lugre" else 0.0
    lugre = LuGre(sigma0=sigma0, sigma1=sigma1, sigma2=B, coulomb=0.6,
                  static=0.8 if family == "lugre" else None, stribeck_velocity=0.01 if family == "lugre" else 0.0)
    p = PlantParams(inertia=J, lugre=lugre)
    friction = feedforward_torque(p, ref) - J * ref.acceleration
    truth = displacement_ode(tr, ref.position, FS)
    # the truth takes the velocity of the segment after each sample, the feed-forward the reference's own
    # velocity at the sample: they differ by |a|*dt/2 in the sigma1 and viscous terms (measured: Dahl 1e-7,
    # LuGre 7e-5 N*m)
    assert np.max(np.abs(friction - truth)) < 2e-4


def _gms_oracle(k, alpha, fc, fs_, vs, attraction, x, v_ref, fs, sub=100):
    """GMS (docs/plant.md) by explicit Euler on the linear path, ``sub`` steps per sample, element by element;
    the Stribeck level s(v) = fc + (fs_ - fc)*exp(-(v/vs)^2) at the reference velocity of the step's end."""
    f = [0.0] * len(k)
    slipping = [False] * len(k)
    out = np.zeros(x.size)
    h = 1.0 / fs / sub
    for i in range(1, x.size):
        v = (x[i] - x[i - 1]) * fs
        sv = math.copysign(1.0, v) if v else 0.0
        level = fc + (fs_ - fc) * math.exp(-((v_ref[i] / vs) ** 2))
        for j in range(len(k)):
            cap = alpha[j] * level
            for _ in range(sub):
                if slipping[j] and math.copysign(1.0, f[j]) != sv:
                    slipping[j] = False  # the motion reversed: the element sticks again
                if slipping[j]:
                    f[j] += attraction * h * (sv - f[j] / cap)
                else:
                    f[j] += k[j] * v * h
                    if abs(f[j]) >= cap:
                        f[j] = math.copysign(cap, f[j])
                        slipping[j] = True
        out[i] = sum(f)
    return out


def test_gms_against_an_independent_integrator():
    ref = slow_sine(1000.0, amplitudes=(1e-3,), frequency=1.0, cycles=1, rest=0.0)
    k = np.array([800.0, 300.0])
    alpha = np.array([0.4, 0.6])
    p = PlantParams(inertia=J, gms=GMS(stiffness=tuple(k), fractions=tuple(alpha), coulomb=0.6, static=0.8,
                                       stribeck_velocity=5e-3, attraction=50.0))
    friction = feedforward_torque(p, ref) - J * ref.acceleration
    oracle = _gms_oracle(k, alpha, 0.6, 0.8, 5e-3, 50.0, ref.position, ref.velocity, 1000.0)
    # the engine integrates the slip phase its own way; measured 6.3e-4 N*m (0.1 % of Fc)
    assert np.max(np.abs(friction - oracle)) < 2e-3


def test_continuous_hysteresis_masing_loop_closed_form():
    a, h, d = 2e-3, 0.76, 5e-4
    ref = slow_sine(FS, amplitudes=(a,), frequency=1.0, cycles=2, rest=0.0)
    p = PlantParams(inertia=J, hysteresis=Hysteresis(h=h, d=d))

    def phi(x):
        return h * (1 - (d / (d + np.abs(x))) ** 2) * np.sign(x)

    x, v = ref.position, ref.velocity
    top = phi(2 * a)
    expect = np.where(v >= 0, top - 2 * phi(a) + 2 * phi(x / 2), top - 2 * phi((2 * a - x) / 2))
    first = np.arange(x.size) <= np.argmax(x)  # the virgin stroke to the first peak
    expect[first] = phi(x[first])
    friction = feedforward_torque(p, ref) - J * ref.acceleration
    assert np.max(np.abs(friction - expect)) < 1e-9 * h


@pytest.mark.parametrize("make", [lambda: slow_sine(FS, amplitudes=(5e-4, 2e-2), cycles=2, rest=0.1),
                                  lambda: point_to_point(FS, targets=(0.02, -0.01), rest=0.2)],
                         ids=["sine", "point_to_point"])
@pytest.mark.parametrize("family", ["maxwell_slip", "dahl", "continuous"])
def test_the_plant_driven_by_the_feedforward_follows_the_reference(make, family):
    ref = make()
    p = {"maxwell_slip": dc_motor(8).replace(torque_constant=1.0),
         "dahl": PlantParams(inertia=J, viscous=B, lugre=LuGre(sigma0=1500, coulomb=0.7)),
         "continuous": PlantParams(inertia=J, viscous=B, hysteresis=Hysteresis(h=0.76, d=5e-4))}[family]
    sub = max(1, math.ceil(stiffest_eigenvalue(p) / FS / 2))
    theta = simulate(p, feedforward_torque(p, ref), 1 / FS, substeps=sub).theta
    # measured: at most 1.6e-3 of the travel (the torque is held over each sample, the path is not)
    assert np.max(np.abs(theta - ref.position)) < 3e-3 * np.ptp(ref.position)


def test_current_conversion_and_clipping_count():
    ref = triangle(FS, amplitude=0.02, frequency=1.0, cycles=1, corner=0.01, rest=0.05)
    p = PlantParams(inertia=J, coulomb=0.5, viscous=B)
    ff = feedforward(Compensator("c", p), ref, torque_constant=0.2, ratio=2.0, current_limit=1.0)
    raw = feedforward_torque(p, ref) / 0.4
    assert np.allclose(ff.torque / 0.4, raw)
    assert ff.clipped == int(np.sum(np.abs(raw) > 1.0)) > 0
    assert np.max(np.abs(ff.current)) == 1.0
    assert np.array_equal(ff.current, np.clip(raw, -1, 1))
    none = feedforward(Compensator("none", None), ref, 0.2, 1.0, 1.0)
    assert none.clipped == 0 and not none.current.any()


def test_coulomb_at_the_maxwell_slip_breakaway():
    ms = dc_motor(16).replace(torque_constant=1.0)
    c = coulomb_at_breakaway(ms)
    assert c.params.coulomb == pytest.approx(0.76, rel=1e-9)
    assert c.params.inertia == ms.inertia and c.params.viscous == ms.viscous and not c.params.ms_stiffness


def _model_doc(axis="rotary", inertia_unit="kg*m^2"):
    units = {"inertia": inertia_unit, "ms_stiffness": "N*m/rad", "ms_delta": "rad", "viscous": "N*m*s/rad",
             "coulomb": "N*m", "offset": "N*m"}
    return {"schema": "hilbench.friction-model/1", "parameters": {
        "axis": axis, "units": units, "inertia": J, "ms_stiffness": [1000.0, 500.0], "ms_delta": [1e-4, 5e-4],
        "viscous": B, "coulomb": 0.0, "offset": 0.0, "spring": 0.0, "std_errors": {}}}


def test_model_file_gives_none_coulomb_maxwell_slip(tmp_path):
    path = tmp_path / "m.json"
    path.write_text(json.dumps(_model_doc()))
    comps, _ = load_compensators(path)
    assert [c.name for c in comps] == ["none", "coulomb", "maxwell_slip"]
    assert comps[1].params.coulomb == pytest.approx(1000 * 1e-4 + 500 * 5e-4)


@pytest.mark.parametrize("doc, match", [
    (_model_doc(axis="linear", inertia_unit="kg"), "linear axis"),
    (_model_doc(inertia_unit="kg"), "inertia is in kg"),
    ({"schema": "other"}, "not a hilbench model"),
])
def test_a_model_for_another_axis_or_units_is_refused(tmp_path, doc, match):
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(AnalysisError, match=match):
        load_compensators(path)


def test_a_family_file_of_compare_gives_that_family(tmp_path):
    # schema 2 family file (`hilbench compare` writes OUT/models/FAMILY.json): none plus that family's plant
    plant = dc_motor(4).replace(torque_constant=1.0)
    doc = {"schema": "hilbench.friction-model/2", "family": "gms", "plant": plant.to_dict(),
           "parameters": {"axis": "rotary", "units": {"inertia": "kg*m^2"}, "inertia": plant.inertia}}
    path = tmp_path / "gms.json"
    path.write_text(json.dumps(doc))
    comps, _ = load_compensators(path)
    assert [c.name for c in comps] == ["none", "gms"]
    assert comps[1].params.ms_stiffness == pytest.approx(plant.ms_stiffness)
    with pytest.raises(AnalysisError, match="linear axis"):
        path.write_text(json.dumps({**doc, "parameters": {**doc["parameters"], "axis": "linear"}}))
        load_compensators(path, "rotary")
