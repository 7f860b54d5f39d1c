"""``compare`` at the bench's sample rates: the family starts stay physical at 10 kHz, the equation error of a
model too stiff to integrate is still its exact friction, and a family that fails is named while the others
complete (analysis/models/families.py, compare.py)."""

import math

import numpy as np
import pytest

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.models import compare as compare_module
from hilbench.analysis.models.compare import compare, document, markdown_table
from hilbench.analysis.models.families import (
    FAMILIES,
    RunData,
    _build_families,
    _sliding_starts,
    _starts,
    evaluate,
    maxwell_slip_start,
    path_plant,
    substeps_for,
)
from hilbench.bench.acquisition.protocols import Identification
from hilbench.firmware_sim.engine.friction_models import DC_MOTOR_INERTIA, dc_motor
from hilbench.firmware_sim.engine.plant import LuGre, PlantParams, simulate

FS = 10_000.0


def _device_run(seed: int, duration: float = 4.0, fs: float = FS) -> tuple[RunData, np.ndarray]:
    """The bench's default identification protocol on the DC motor, recorded as the simulated device does:
    torque from the measured current (the mean over the previous sample), a 2^20-count encoder."""
    u = Identification(duration=duration, sample_rate=int(fs), seed=seed).setpoints()
    p = dc_motor().replace(counts_per_rev=2**20, seed=seed)
    out = simulate(p, u, 1 / fs)
    tau = p.torque_constant * out.current_meas
    return RunData.from_arrays(f"dc{seed}", "rotary", fs, out.position_meas, tau, "hold_previous"), tau


@pytest.fixture(scope="module")
def runs():
    return _device_run(0), _device_run(1)


def test_every_start_is_physical_at_10_khz(runs):
    # At 10 kHz the fs/20 filter passes the presliding oscillation (186 Hz) and the least-squares J of a law
    # without presliding came out -0.00066 kg*m^2; floored to 1e-12 it made b/J = 1.1e12 1/s, "too stiff to
    # simulate" (issue #26). Every start now has the Maxwell-slip fit's J (within 3 % of the true 0.0022)
    # and simulates in at most 4 RK4 sub-steps (measured: 1; the stiffest mode is sqrt(sum k/J) ~ 1200 1/s)
    (train, tau), _ = runs
    ms = maxwell_slip_start(train, "hold_previous", train.x, tau).model
    fams = _build_families(ms)
    starts = _starts(train, ms)
    for name, start in [*starts.items(), *(("sliding " + k, v) for k, v in _sliding_starts(train, ms, starts).items())]:
        family = name.removeprefix("sliding ")
        assert start["inertia"] == pytest.approx(DC_MOTOR_INERTIA, rel=0.03), name
        assert substeps_for(fams[family].plant(start), FS) <= 4, name


def test_compare_completes_at_10_khz(runs):
    # the default identification run at 10 kHz: every family fitted (a small refinement budget: this checks
    # completion, test_families.py the fits), each with finite figures on both runs
    (train, tau), (val, _) = runs
    result = compare(train, val, timing="hold_previous", train_position=train.x, train_torque=tau, max_nfev=2)
    assert [r.name for r in result.rows] == list(FAMILIES)
    for r in result.rows:
        assert r.error is None, (r.name, r.error)
        for figures in (r.train, r.validation):
            assert math.isfinite(figures["torque_nrmse"]) and math.isfinite(figures["position_nrmse_segmented"])
    # the Maxwell-slip row (the fit the others start from) follows the validation run to 5 %
    ms_row = next(r for r in result.rows if r.name == "maxwell_slip")
    assert ms_row.validation["position_nrmse_segmented"] < 0.05


def test_a_failing_family_is_named_and_the_others_complete(runs, monkeypatch):
    (train, tau), (val, _) = runs
    real = compare_module.fit_family

    def failing(family, *args, **kwargs):
        if family == "dahl":
            raise AnalysisError("sigma0 unidentifiable (test)")
        return real(family, *args, **kwargs)

    monkeypatch.setattr(compare_module, "fit_family", failing)
    result = compare(train, val, timing="hold_previous", train_position=train.x, train_torque=tau,
                     families=("coulomb_viscous", "dahl", "maxwell_slip"), max_nfev=1)
    rows = {r.name: r for r in result.rows}
    assert rows["dahl"].error == "sigma0 unidentifiable (test)"
    assert math.isnan(rows["dahl"].validation["torque_nrmse"])
    for name in ("coulomb_viscous", "maxwell_slip"):
        assert rows[name].error is None and math.isfinite(rows[name].validation["torque_nrmse"])
    table = markdown_table(result)
    assert "| dahl | – |" in table and "FAILED: sigma0 unidentifiable (test)" in table
    doc = {r["model"]: r for r in document(result, {})["rows"]}
    assert doc["dahl"]["error"] == "sigma0 unidentifiable (test)"
    assert doc["dahl"]["n_parameters"] is None and doc["dahl"]["validation"]["torque_nrmse"] is None
    assert doc["maxwell_slip"]["error"] is None


def test_friction_of_a_bristle_too_stiff_to_integrate_is_the_closed_form():
    # Dahl, sigma0 = 1e5 N*m/rad on J = 1e-11 kg*m^2: RK4 would need 5000 sub-steps per sample at 10 kHz (above
    # the limit), but the friction along an imposed path is not integrated, so the equation error exists. Along
    # x = v*t from a relaxed bristle, z = Fc/sigma0*(1 - exp(-sigma0*x/Fc)) exactly (the engine's update over
    # each sample is that exponential); then back down from x_top: z = -Fc/s0 + (z_top + Fc/s0)*exp(-s0*(x_top
    # - x)/Fc). Friction sigma0*z + b*v to 1e-12 relative
    fc, s0, b, v = 0.5, 1e5, 0.004, 0.02
    params = PlantParams(inertia=1e-11, viscous=b, lugre=LuGre(sigma0=s0, coulomb=fc))
    with pytest.raises(AnalysisError, match="too stiff"):
        substeps_for(params, FS)
    n, m = 400, 200
    t = np.arange(n) / FS
    up = np.arange(n) <= m
    x = np.where(up, v * t, v * (2 * t[m] - t))
    vel = np.where(up, v, -v)
    got = path_plant(params, FS).friction_path(x, vel)
    z = fc / s0 * (1 - np.exp(-s0 * x / fc))
    x_top, z_top = x[m], z[m]
    z_down = -fc / s0 + (z_top + fc / s0) * np.exp(-s0 * (x_top - x) / fc)
    expected = np.where(up, s0 * z, s0 * z_down) + b * vel
    np.testing.assert_allclose(got[1:], expected[1:], rtol=1e-12, atol=1e-12 * fc)


def test_evaluation_of_a_model_too_stiff_to_simulate_keeps_its_torque_figure(runs):
    # the same stiff Dahl scored on a run: the torque (equation-error) figure is finite, the simulation is
    # refused (NaN) instead of aborting the comparison
    (train, _), _ = runs
    params = PlantParams(inertia=1e-11, viscous=0.004, lugre=LuGre(sigma0=1e5, coulomb=0.5))
    figures = evaluate(params, train)
    assert math.isfinite(figures["torque_nrmse"])
    assert math.isnan(figures["position_nrmse_segmented"])
