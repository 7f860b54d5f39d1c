"""The user's defaults: which device a command talks to when ``--device`` is not given.

Order: the environment variable ``HILBENCH_DEVICE``; else the key ``device`` in the config file (TOML) named by
``HILBENCH_CONFIG``, else ``$XDG_CONFIG_HOME/hilbench/config.toml`` (``~/.config/hilbench/config.toml`` when
``XDG_CONFIG_HOME`` is unset); else ``sim://``, the simulated bench. See docs/cli.md.
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


def default_device() -> str:
    """The device URL to use when none is given on the command line."""
    env = os.environ.get("HILBENCH_DEVICE")
    if env:
        return _check_url(env, "HILBENCH_DEVICE")
    path = config_path()
    if os.environ.get("HILBENCH_CONFIG") and not path.is_file():
        raise BenchError(f"HILBENCH_CONFIG={path}: no such file")
    if not path.is_file():
        return SIMULATED
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise BenchError(f"{path}: not valid TOML ({exc})") from None
    if "device" not in doc:
        return SIMULATED
    return _check_url(doc["device"], str(path))
