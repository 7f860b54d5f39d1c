"""The [drift] table is checked over the whole range a device can reach (winding between ambient and max_temperature,
distance slid up to max_distance) before the device starts: a table that would make the plant non-finite or
non-physical at some run is refused in one line naming the key. Before, each of the refused tables below passed
validation and broke the device at the first run that got there ([Errno 5] on the host, an all-inf temperature
channel, -500 degC recorded)."""

import pytest

from hilbench.firmware_sim.devices.sim_config import MAX_SUBSTEPS, SimConfigError, sim_config_from_dict, substeps_for
from hilbench.firmware_sim.engine.drift import reachable_extremes, scaled_params
from hilbench.firmware_sim.engine.plant import PlantParameterError, validate

RATES = (1000, 2000, 5000, 10000, 20000)  # Hz


@pytest.mark.parametrize(("table", "key"), [
    ({"ambient": 1e300}, "ambient"),
    ({"ambient": -500.0}, "ambient"),
    ({"reference_temperature": -300.0}, "reference_temperature"),
    ({"max_temperature": 2000.0}, "max_temperature"),
    ({"ambient": 200.0}, "max_temperature"),  # ambient above the hottest the laws are checked at
    ({"viscous_temperature_coefficient": -1.0}, "viscous_temperature_coefficient"),  # b x1.5e68 at 180 degC
    ({"viscous_temperature_coefficient": 5.0, "reference_temperature": 80.0},
     "viscous_temperature_coefficient"),  # x6e123 at ambient: non-finite at the first run
    ({"level_temperature_coefficient": -0.05}, "level_temperature_coefficient"),  # level <= 0 from 43 degC
    ({"wear_rate": 1e300}, "wear_rate"),  # stiffness inf after 1e6 rad
    ({"max_distance": -1.0}, "max_distance"),
])
def test_a_table_that_leaves_physics_somewhere_in_range_is_refused_in_one_line(table, key):
    with pytest.raises(SimConfigError) as info:
        sim_config_from_dict({"drift": table})
    text = str(info.value)
    assert f"[drift] {key}" in text and "\n" not in text


def test_the_documented_example_is_accepted():
    example = {"ambient": 23.0, "thermal_time_constant": 600.0, "thermal_resistance": 2.0, "winding_resistance": 1.0,
               "level_temperature_coefficient": -0.005, "viscous_temperature_coefficient": 0.02, "wear_rate": 1e-6,
               "wear_step": 0.2, "wear_step_distance": 50000.0}
    config = sim_config_from_dict({"drift": example})
    temperatures = {t for t, *_ in config.reachable_plants()}
    assert temperatures == {23.0, 180.0}


def test_extremes_bound_the_laws_over_the_range():
    """Oracle: the laws evaluated on a dense grid over the range never leave the span of the extremes."""
    import numpy as np

    config = sim_config_from_dict({"drift": {"level_temperature_coefficient": -0.004, "wear_rate": 2e-6,
                                             "wear_step": -0.3, "wear_step_distance": 4e5,
                                             "viscous_temperature_coefficient": 0.03, "reference_temperature": 40.0}})
    drift, extremes = config.drift, reachable_extremes(config.drift, config.ambient, config.max_temperature,
                                                       config.max_distance)
    levels, viscous = [e[2] for e in extremes], [e[3] for e in extremes]
    for t in np.linspace(config.ambient, config.max_temperature, 41):
        assert min(viscous) <= drift.viscous_factor(t) <= max(viscous)
        for s in np.linspace(0.0, config.max_distance, 101):
            assert min(levels) * (1 - 1e-12) <= drift.level_factor(t, s) <= max(levels) * (1 + 1e-12)


def test_substeps_keep_every_reachable_plant_stable_and_are_the_fewest():
    """A contact that wears 100-fold over 1e6 rad is accepted with the sub-steps its stiffest state needs: every
    extreme plant passes validation (the RK4 stability bound) at substeps_at(rate), the stiffest fails at one fewer."""
    config = sim_config_from_dict({"drift": {"wear_rate": 1e-4}})
    plants = [p for *_, p in config.reachable_plants()]
    for rate in RATES:
        n = config.substeps_at(rate)
        assert n == max(substeps_for(p, 1.0 / rate) for p in plants) <= MAX_SUBSTEPS
        for params in plants:
            validate(params, 1.0 / rate, n)
        if n > 1:
            with pytest.raises(PlantParameterError, match="unstable step"):
                validate(max(plants, key=lambda p: p.ms_stiffness[0]), 1.0 / rate, n - 1)
    nominal = sim_config_from_dict({})
    assert config.substeps_at(1000) > nominal.substeps_at(1000)  # the worn plant is the stiffer one


def test_scaled_params_scale_friction_and_viscous():
    config = sim_config_from_dict({})
    p = scaled_params(config.plant, 2.0, 0.5)
    assert p.ms_stiffness[0] == 2.0 * config.plant.ms_stiffness[0] and p.coulomb == 2.0 * config.plant.coulomb
    assert p.viscous == 0.5 * config.plant.viscous


def test_cli_refuses_a_drift_table_in_one_line_exit_2(tmp_path, starts_devices):
    import subprocess
    import sys

    bad = tmp_path / "sim.toml"
    bad.write_text("[drift]\nviscous_temperature_coefficient = 5.0\nreference_temperature = 80.0\n")
    res = subprocess.run([sys.executable, "-m", "hilbench.firmware_sim", "--serial", "--config", str(bad)],
                         capture_output=True, text=True, timeout=30)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "viscous_temperature_coefficient" in res.stderr
