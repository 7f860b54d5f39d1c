"""Readings no motor can give are flagged (NaN, counted, a note for the run file), never recorded as data."""

import math

import numpy as np
import pytest

from hilbench.common.physical_bounds import ABSOLUTE_ZERO_DEGC, temperature_possible
from hilbench.drivers.amplifier import flag_impossible


@pytest.mark.parametrize("reading", [math.inf, -math.inf, math.nan, -1273.0, ABSOLUTE_ZERO_DEGC, 1e30])
def test_an_impossible_temperature_becomes_nan_and_is_counted(reading):
    cmd, meas = np.array([0.5, 0.25], np.float32), np.array([0.49, 0.26], np.float32)
    out_cmd, out_meas, temperature, bad, note = flag_impossible(cmd, meas, reading, 100)
    assert math.isnan(temperature) and bad == 1 and "temperature" in note and "sample 100" in note
    np.testing.assert_array_equal(out_cmd, cmd.astype(np.float64))  # the currents are untouched
    np.testing.assert_array_equal(out_meas, meas.astype(np.float64))


@pytest.mark.parametrize("reading", [-40.0, 25.0, 180.0, 1000.0])
def test_a_possible_temperature_is_kept(reading):
    _, _, temperature, bad, note = flag_impossible(np.zeros(3), np.zeros(3), reading, 0)
    assert temperature == reading and bad == 0 and note == ""


def test_no_sensor_stays_no_sensor():
    assert flag_impossible(np.zeros(2), np.zeros(2), None, 0)[2:4] == (None, 0)


def test_non_finite_currents_become_nan_each_counted():
    cmd = np.array([0.5, np.inf, 0.1, 0.2], np.float32)
    meas = np.array([np.nan, 0.2, -np.inf, 0.3], np.float32)
    out_cmd, out_meas, _, bad, note = flag_impossible(cmd, meas, 30.0, 7)
    assert bad == 3 and note == "current -inf A at sample 9"
    np.testing.assert_array_equal(np.isnan(out_cmd), [False, True, False, False])
    np.testing.assert_array_equal(np.isnan(out_meas), [True, False, True, False])
    assert out_meas[3] == np.float32(0.3) and np.isinf(cmd[1])  # the block itself is not modified


def test_bounds():
    assert temperature_possible(-273.0) and not temperature_possible(-273.15) and not temperature_possible(1085.0)
