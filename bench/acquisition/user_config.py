"""The user's defaults: which device a command talks to when ``--device`` is not given, and the device
settings (limits, calibration, position-loop gains) a run starts from.

Device order: the environment variable ``HILBENCH_DEVICE``; else the key ``device`` in the config file (TOML)
named by ``HILBENCH_CONFIG``, else ``$XDG_CONFIG_HOME/hilbench/config.toml`` (``~/.config/hilbench/config.toml``
when ``XDG_CONFIG_HOME`` is unset); else ``sim://``, the simulated bench. Settings: the table ``[settings]`` of
the same file, under the command line's options. See docs/cli.md.
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path

from hilbench.bench.errors import BenchError

SIMULATED = "sim://"


def config_path() -> Path:
    """The config file in use (it may not exist)."""
    explicit = os.environ.get("HILBENCH_CONFIG")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "hilbench" / "config.toml"


def _check_url(url: object, where: str) -> str:
    if not isinstance(url, str) or "://" not in url:
        raise BenchError(f"{where}: device {url!r} is not a device URL (sim://, serial:///dev/ttyUSB0, "
                         "can://socketcan/can0)")
    return url


def _load() -> tuple[Path, dict]:
    """The config file and its contents (empty when there is none)."""
    path = config_path()
    if os.environ.get("HILBENCH_CONFIG") and not path.is_file():
        raise BenchError(f"HILBENCH_CONFIG={path}: no such file")
    if not path.is_file():
        return path, {}
    try:
        with open(path, "rb") as fh:
            return path, tomllib.load(fh)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise BenchError(f"{path}: not valid TOML ({exc})") from None


def default_device() -> str:
    """The device URL to use when none is given on the command line."""
    env = os.environ.get("HILBENCH_DEVICE")
    if env:
        return _check_url(env, "HILBENCH_DEVICE")
    path, doc = _load()
    if "device" not in doc:
        return SIMULATED
    return _check_url(doc["device"], str(path))


def default_settings() -> dict[str, float]:
    """The ``[settings]`` table of the config file: device settings (``bench.acquisition.runner.SETTING_RANGES`` names,
    numbers in their units, e.g. ``position_kp = 2500.0`` A/rad). Empty without a file or table; an unknown
    key or a value that is not a number is a :class:`BenchError` naming the file. Ranges are checked by
    ``DeviceSettings``."""
    from hilbench.bench.acquisition.runner import SETTING_RANGES

    path, doc = _load()
    table = doc.get("settings", {})
    if not isinstance(table, dict):
        raise BenchError(f"{path}: settings must be a table ([settings]), got {table!r}")
    for key, value in table.items():
        if key not in SETTING_RANGES:
            raise BenchError(f"{path}: [settings] {key} is not a device setting (known: "
                             f"{', '.join(SETTING_RANGES)})")
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise BenchError(f"{path}: [settings] {key} must be a number in {SETTING_RANGES[key][2]}, "
                             f"got {value!r}")
    return dict(table)
