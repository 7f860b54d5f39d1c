"""Import of the Mnich rack-and-pinion friction rig (K. Mnich, github.com/KonradMnich/friction-identification).

Two unsynchronised exports of one short motion (0 -> 0.66 m/s -> 0):

- the servo amplifier's scope CSV (``a3MR.csv``: 5 header lines, 1.5 kHz): time (ms), motor speed (rpm),
  torque (% of rated), droop pulses (counts);
- the NI DAQ CSV (``a3NI.csv``: 4 header lines, 2 kHz): time (s), load-cell voltage (V), time, "Input 1" (V).

The run is written on the load cell's 2 kHz grid (the force is the measurement that matters), with the
author's conversions (data set README): linear speed = -rpm*20/1000/60 m/s, force = -(V - V0)*200 N/V, and
the NI clock shifted by ``shift`` = -0.004 s onto the servo's. V0 is the median load-cell voltage over the
first ``zero_window`` s, before the drive pulls. The servo's speed is interpolated linearly onto the shifted
NI times inside the overlap of the two records, and the position is its trapezoidal integral from 0 (there is
no encoder channel). The servo torque (% rated, no rated torque given) is kept as ``servo_torque_pct``.
Reduced mass 24.7 kg (README) goes into the calibration as ``inertia``.
"""

from __future__ import annotations

import os

import numpy as np
from scipy.integrate import cumulative_trapezoid

from hilbench.bench.storage import importers
from hilbench.bench.storage.importers import (
    ImportDataError,
    ImportedRun,
    _check_finite,
    _count_lines,
    _sample_rate,
    _sha256,
)
from hilbench.common.runfile import SAMPLE_INDEX

MNICH_MASS = 24.7  # kg, reduced mass (data set README)
MNICH_SHIFT = -0.004  # s, NI clock relative to the servo clock (data set README)
MNICH_FORCE_GAIN = 200.0  # N/V, load cell (data set README)


def _read_table(path: str, skip: int, columns: int) -> np.ndarray:
    """The first ``columns`` columns of a CSV export after ``skip`` header lines; its rows and line lengths are
    bounded (``MAX_IMPORT_SAMPLES``, ``MAX_LINE_BYTES``) before anything is parsed, and the other columns are
    not kept."""
    if not os.path.isfile(path):
        raise ImportDataError(f"{path}: no such file")
    rows = _count_lines(path) - skip
    if rows > importers.MAX_IMPORT_SAMPLES:
        raise ImportDataError(f"{path}: {rows} rows, above the import bound of {importers.MAX_IMPORT_SAMPLES} "
                              "samples (MAX_IMPORT_SAMPLES)")
    try:
        table = np.genfromtxt(path, delimiter=",", skip_header=skip, encoding="utf-8-sig", invalid_raise=True,
                              usecols=tuple(range(columns)))
    except (ValueError, IndexError) as exc:
        raise ImportDataError(f"{path}: not a readable CSV export ({str(exc).splitlines()[0]})") from None
    if table.ndim != 2 or table.shape[1] < columns or table.shape[0] < 10:
        raise ImportDataError(f"{path}: expected at least 10 rows of {columns} columns after {skip} header lines")
    return table


def load_mnich(
    servo_csv: str | os.PathLike,
    ni_csv: str | os.PathLike | None = None,
    *,
    shift: float = MNICH_SHIFT,
    zero_window: float = 0.02,
) -> ImportedRun:
    """Load ``a3MR.csv`` (servo) and ``a3NI.csv`` (load cell; default: beside the servo file) into one
    linear-axis run in m, m/s and N. See the module docstring for the conversions."""
    servo_csv = os.fspath(servo_csv)
    ni_csv = os.fspath(ni_csv) if ni_csv is not None else os.path.join(os.path.dirname(servo_csv), "a3NI.csv")
    mr = _read_table(servo_csv, 5, 3)  # time, speed, torque (the droop pulses are not used)
    ni = _read_table(ni_csv, 4, 2)  # time, load-cell voltage
    t_servo = mr[:, 0] / 1000.0
    speed = -mr[:, 1] * 20.0 / 1000.0 / 60.0
    torque_pct = mr[:, 2]
    t_ni = ni[:, 0] + shift
    volts = ni[:, 1]
    _check_finite({"t": t_servo, "speed": speed, "torque_pct": torque_pct}, servo_csv, {})
    _check_finite({"t": t_ni, "force": volts}, ni_csv, {})
    _sample_rate(t_servo, servo_csv)
    rest = ni[:, 0] < zero_window
    if rest.sum() < 5:
        raise ImportDataError(f"{ni_csv}: fewer than 5 samples in the first {zero_window} s to find the zero V0")
    v0 = float(np.median(volts[rest]))
    keep = (t_ni >= t_servo[0]) & (t_ni <= t_servo[-1])
    if keep.sum() < 10:
        raise ImportDataError(f"{ni_csv}: the load-cell record does not overlap the servo record after the shift")
    t = t_ni[keep] - t_ni[keep][0]
    fs = _sample_rate(t, ni_csv)
    velocity = np.interp(t_ni[keep], t_servo, speed)
    samples = {
        SAMPLE_INDEX: np.arange(t.size, dtype=np.int64),
        "t": t,
        "position": cumulative_trapezoid(velocity, t, initial=0.0),
        "velocity": velocity,
        "torque": -(volts[keep] - v0) * MNICH_FORCE_GAIN,
        "servo_torque_pct": np.interp(t_ni[keep], t_servo, torque_pct),
        "force_voltage": volts[keep],
    }
    return ImportedRun(
        axis="linear",
        sample_rate=fs,
        samples=samples,
        custom_units={"servo_torque_pct": "%", "force_voltage": "V"},
        protocol_name="import:mnich",
        protocol_params={
            "format": "mnich",
            "source_file": os.path.basename(servo_csv),
            "source_sha256": _sha256(servo_csv),
            "ni_file": os.path.basename(ni_csv),
            "ni_sha256": _sha256(ni_csv),
            "ni_shift_s": shift,
            "t0_on_servo_clock_s": float(t_ni[keep][0]),
            "notes": (
                "one short motion; servo and load cell unsynchronised (NI clock shifted by ni_shift_s); "
                "position integrated from the servo speed (no encoder); torque = load-cell force in N"
            ),
        },
        device={
            "name": "Mnich rack-and-pinion rig",
            "description": "servo-driven rack and pinion with a load cell (Lodz University of Technology)",
            "source": "GitHub KonradMnich/friction-identification, input/a3MR.csv and input/a3NI.csv",
        },
        calibration={
            "inertia": MNICH_MASS,
            "inertia_unit": "kg",
            "force_zero_v": v0,
            "force_gain": MNICH_FORCE_GAIN,
            "force_gain_unit": "N/V",
            "speed_scale": "-rpm*20/1000/60 m/s",
        },
    )
