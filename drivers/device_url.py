"""``open_device(url)``: an :class:`Amplifier` from a device URL.

- ``serial:///dev/ttyUSB0?baud=2000000`` -- any pyserial port or URL after ``serial://``
  (``serial://socket://host:7777``, ``serial://loop://``);
- ``can://INTERFACE/CHANNEL?node=1&fd=1&bitrate=1000000`` -- any python-can interface
  (``can://socketcan/can0``, ``can://virtual/bench0``, ``can://pcan/PCAN_USBBUS1``);
- ``sim://?pacing=lockstep&config=sim.toml&seed=3&tick=0.004&core=c`` -- starts the simulated amplifier as a
  separate process (``python -m hilbench.firmware_sim --serial``) and connects to its pseudo-terminal;
  ``core`` picks the device implementation (``c``: the firmware core, default; ``python``).
"""

from __future__ import annotations

import os
import select
import subprocess
import sys
import time
from urllib.parse import parse_qsl, urlsplit

from hilbench.drivers.amplifier import Amplifier
from hilbench.drivers.errors import DeviceURLError, DriverError
from hilbench.drivers.links import CanLink, SerialLink

SIM_START_TIMEOUT = 20.0  # s, for the simulator to print its pty path


def _query(text: str, allowed: set[str], url: str) -> dict[str, str]:
    params = dict(parse_qsl(text, keep_blank_values=True))
    unknown = sorted(set(params) - allowed)
    if unknown:
        raise DeviceURLError(f"{url}: unknown option(s) {', '.join(unknown)} "
                             f"(allowed: {', '.join(sorted(allowed))})")
    return params


def _int(params: dict[str, str], key: str, default: int, url: str) -> int:
    try:
        return int(params.get(key, default))
    except ValueError:
        raise DeviceURLError(f"{url}: {key} must be an integer, got {params[key]!r}") from None


def open_device(url: str, timeout: float = 2.0) -> Amplifier:
    """Connect to the device at ``url`` (see the module doc) and return its :class:`Amplifier`."""
    scheme, sep, rest = url.partition("://")
    if not sep:
        raise DeviceURLError(f"{url!r} is not a device URL (serial://..., can://..., sim://...)")
    if scheme == "serial":
        port, _, query = rest.rpartition("?") if "?" in rest else (rest, "", "")
        params = _query(query, {"baud"}, url)
        if not port:
            raise DeviceURLError(f"{url}: no serial port given")
        return Amplifier(SerialLink(port, _int(params, "baud", 2_000_000, url)), timeout=timeout)
    if scheme == "can":
        parts = urlsplit(url)
        params = _query(parts.query, {"node", "fd", "bitrate"}, url)
        channel = parts.path.lstrip("/")
        if not parts.netloc or not channel:
            raise DeviceURLError(f"{url}: expected can://INTERFACE/CHANNEL")
        kwargs = {"bitrate": _int(params, "bitrate", 0, url)} if "bitrate" in params else {}
        fd = params.get("fd", "0") in ("1", "true")
        link = CanLink(parts.netloc, channel, _int(params, "node", 1, url), fd, **kwargs)
        return Amplifier(link, timeout=timeout)
    if scheme == "sim":
        params = _query(urlsplit(url).query, {"pacing", "config", "seed", "tick", "core"}, url)
        proc, path = start_simulator(params)
        try:
            link = SerialLink(path)
        except DriverError:
            stop_simulator(proc)
            raise
        return Amplifier(link, timeout=timeout, on_close=lambda: stop_simulator(proc))
    raise DeviceURLError(f"{url}: unknown scheme {scheme!r} (serial, can or sim)")


def start_simulator(options: dict[str, str]) -> tuple[subprocess.Popen, str]:
    """Start ``python -m hilbench.firmware_sim --serial`` with ``options`` (pacing, config, seed, tick) as flags;
    return the process and the pty path it printed."""
    cmd = [sys.executable, "-m", "hilbench.firmware_sim", "--serial", "--parent-pid", str(os.getpid())]
    for key in ("pacing", "config", "seed", "tick", "core"):
        if key in options:
            cmd += [f"--{key}", options[key]]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + SIM_START_TIMEOUT
    line = b""
    while not line.endswith(b"\n"):
        ready, _, _ = select.select([proc.stdout], [], [], max(0.0, deadline - time.monotonic()))
        if not ready:
            stop_simulator(proc)
            raise DriverError(f"simulator did not start within {SIM_START_TIMEOUT:.0f} s")
        chunk = os.read(proc.stdout.fileno(), 1)
        if not chunk:
            err = proc.stderr.read().decode(errors="replace").strip().splitlines()
            proc.wait()
            raise DriverError(f"simulator failed to start: {err[-1] if err else f'exit {proc.returncode}'}")
        line += chunk
    return proc, line.decode().strip()


def stop_simulator(proc: subprocess.Popen) -> None:
    """Terminate a simulator started by :func:`start_simulator` and reap it."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    for stream in (proc.stdout, proc.stderr):
        if stream is not None:
            stream.close()
