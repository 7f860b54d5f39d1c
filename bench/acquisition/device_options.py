"""The device settings an operator may give a run (``hilbench run --OPTION``, the GUI's device settings and a
campaign's ``[settings]``): name -> (unit, what it sets). One table, read by the CLI and the GUI alike, with the
two functions every command that drives a device shares (``run``, ``compensate``)."""

from __future__ import annotations

import argparse
import math

DEVICE_OPTIONS = {
    "current_limit": ("A", "device current limit"),
    "velocity_limit": ("rad/s", "device velocity limit"),
    "position_min": ("rad", "lower end of the position window"),
    "position_max": ("rad", "upper end of the position window"),
    "watchdog_timeout": ("s", "device watchdog timeout (0 = off)"),
    "torque_constant": ("N*m/A", "calibration: torque constant"),
    "counts_per_rev": ("counts", "calibration: encoder counts per motor revolution"),
    "ratio": ("1", "calibration: motor revolutions per load revolution"),
    "position_kp": ("A/rad", "position loop: proportional gain (position mode)"),
    "position_ki": ("A/(rad*s)", "position loop: integral gain (0 = off)"),
    "position_kd": ("A*s/rad", "position loop: derivative gain (0 = off)"),
    "position_i_limit": ("A", "position loop: bound of the integral term"),
    "position_d_cutoff": ("Hz", "position loop: low-pass of the derivative (0 = unfiltered)"),
}


def add_device_options(parser: argparse.ArgumentParser) -> None:
    from hilbench.bench.acquisition.runner import DeviceSettings
    from hilbench.drivers.device_url import describe_schemes

    parser.add_argument("--device", default=None, help=f"device URL: {describe_schemes()} (default "
                        "$HILBENCH_DEVICE, the config file's 'device', else sim://: the simulated bench; docs/cli.md)")
    defaults = DeviceSettings()
    for name, (unit, text) in DEVICE_OPTIONS.items():
        parser.add_argument("--" + name.replace("_", "-"), dest=name, default=None,
                            type=int if name == "counts_per_rev" else float,
                            help=f"{text} ({unit}; default {getattr(defaults, name)})")


def settings_from_args(args: argparse.Namespace):
    """Device settings: the options given, over the config file's ``[settings]``, over the protocol's
    ``RECOMMENDED_SETTINGS``, over the defaults."""
    from hilbench.bench.acquisition.runner import DeviceSettings
    from hilbench.bench.acquisition.user_config import default_settings

    values = {name: getattr(args, name) for name in DEVICE_OPTIONS if getattr(args, name, None) is not None}
    for name, value in values.items():
        if isinstance(value, float) and math.isnan(value):
            raise ValueError(f"--{name.replace('_', '-')} is NaN")
    protocol = getattr(args, "protocol_class", None)
    recommended = protocol.RECOMMENDED_SETTINGS if protocol else {}
    return DeviceSettings(**{**recommended, **default_settings(), **values})
