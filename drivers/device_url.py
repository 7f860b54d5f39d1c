"""``open_device(url)``: a device from a device URL, through one table of schemes (:data:`SCHEMES`).

- ``serial:///dev/ttyUSB0?baud=2000000`` -- any local pyserial port or URL after ``serial://``
  (``serial://loop://``), opened exclusively; network ports (``socket://``, ``rfc2217://``) are refused;
- ``can://INTERFACE/CHANNEL?node=1&fd=1&bitrate=1000000`` -- any python-can interface
  (``can://socketcan/can0``, ``can://virtual/bench0``, ``can://pcan/PCAN_USBBUS1``);
- ``canopen://INTERFACE/CHANNEL?node=N&eds=FILE`` -- a CiA 402 drive over CANopen
  (:class:`drivers.canopen_drive.CanopenDrive`; ``udp_multicast`` stays on this host: hop limit 0, and
  ``&port=P`` picks its UDP port, default 43113: buses sharing a port hear each other whatever the group);
- ``odrive://INTERFACE/CHANNEL?node=N&tvl_endpoint=ID`` -- an ODrive axis over CAN Simple
  (:class:`drivers.odrive_drive.OdriveDrive`);
- ``moteus://INTERFACE/CHANNEL?id=1&kp=4&kd=0.1`` -- a moteus controller over the moteus library's python-can
  transport, CAN-FD (:class:`drivers.moteus_drive.MoteusDrive`; ``kp``, ``kd``: the controller's own
  ``servo.pid_position`` gains, N*m/rev and N*m*s/rev, needed for position mode only);
- ``sim://?pacing=lockstep&config=sim.toml&seed=3&tick=0.004`` -- starts the simulated amplifier (the C
  firmware core) as a separate process (``python -m hilbench.firmware_sim --serial``) and connects to its
  pseudo-terminal.
"""

from __future__ import annotations

import os
import select
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING
from urllib.parse import parse_qsl, urlsplit

from hilbench.drivers.errors import DeviceURLError, DriverError

if TYPE_CHECKING:  # the openers import them: a help text's describe_schemes() costs no numpy and no h5py
    from hilbench.drivers.amplifier import Amplifier
    from hilbench.drivers.device import Device

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


#: pyserial URL schemes that reach a port over the network. Refused: a network port cannot be opened
#: exclusively (one owner per device), and its latency is unbounded against the device watchdog.
NETWORK_SERIAL_SCHEMES = ("socket", "rfc2217")


@dataclass(frozen=True)
class Scheme:
    """One kind of device URL: its form (for help texts), its options, how to check it without opening
    anything, and how to open it. :data:`SCHEMES` is the one table ``open_device``, ``check_device_url`` and
    the CLI's help texts read (as python-can's interface table)."""

    name: str
    form: str
    options: frozenset[str]
    check: Callable[[str], object]
    open: Callable[[str, float], Device]


def _serial_parts(url: str) -> tuple[str, dict[str, str]]:
    rest = url.partition("://")[2]
    port, _, query = rest.rpartition("?") if "?" in rest else (rest, "", "")
    params = _query(query, set(SCHEMES["serial"].options), url)
    _int(params, "baud", 2_000_000, url)
    if not port:
        raise DeviceURLError(f"{url}: no serial port given")
    inner = port.partition("://")[0].lower() if "://" in port else ""
    if inner in NETWORK_SERIAL_SCHEMES:
        raise DeviceURLError(f"{url}: network serial ports ({', '.join(s + '://' for s in NETWORK_SERIAL_SCHEMES)}"
                             f") are refused: they cannot be owned exclusively and their latency is "
                             f"unbounded against the watchdog; use a local port")
    return port, params


def _open_serial(url: str, timeout: float) -> Amplifier:
    from hilbench.drivers.amplifier import Amplifier
    from hilbench.drivers.links import SerialLink

    port, params = _serial_parts(url)
    return Amplifier(SerialLink(port, _int(params, "baud", 2_000_000, url)), timeout=timeout)


def _can_parts(url: str) -> tuple[str, str, dict[str, str]]:
    parts = urlsplit(url)
    params = _query(parts.query, set(SCHEMES["can"].options), url)
    _int(params, "node", 1, url)
    _int(params, "bitrate", 0, url)
    channel = parts.path.lstrip("/")
    if not parts.netloc or not channel:
        raise DeviceURLError(f"{url}: expected can://INTERFACE/CHANNEL")
    return parts.netloc, channel, params


def _open_can(url: str, timeout: float) -> Amplifier:
    from hilbench.drivers.amplifier import Amplifier
    from hilbench.drivers.links import CanLink

    interface, channel, params = _can_parts(url)
    kwargs = {"bitrate": _int(params, "bitrate", 0, url)} if "bitrate" in params else {}
    fd = params.get("fd", "0") in ("1", "true")
    return Amplifier(CanLink(interface, channel, _int(params, "node", 1, url), fd, **kwargs), timeout=timeout)


def _sim_params(url: str) -> dict[str, str]:
    return _query(urlsplit(url).query, set(SCHEMES["sim"].options), url)


def _open_sim(url: str, timeout: float) -> Amplifier:
    from hilbench.drivers.amplifier import Amplifier
    from hilbench.drivers.links import SerialLink

    proc, path = start_simulator(_sim_params(url))
    try:
        link = SerialLink(path)
    except DriverError:
        stop_simulator(proc)
        raise
    return Amplifier(link, timeout=timeout, on_close=lambda: stop_simulator(proc))


def _bus_location(url: str, allowed: set[str]) -> tuple[str, str, dict[str, str], dict]:
    """INTERFACE, CHANNEL, query and python-can keyword arguments of a ``scheme://INTERFACE/CHANNEL?...`` URL."""
    parts = urlsplit(url)
    params = _query(parts.query, allowed, url)
    channel = parts.path.lstrip("/")
    if not parts.netloc or not channel:
        raise DeviceURLError(f"{url}: expected {parts.scheme}://INTERFACE/CHANNEL")
    kwargs: dict = {"bitrate": _int(params, "bitrate", 0, url)} if "bitrate" in params else {}
    if parts.netloc == "udp_multicast":
        kwargs["hop_limit"] = 0  # loopback only: the simulated drives live on this host
        if "port" in params:  # groups on one port hear each other (Linux): separate buses need their own port
            kwargs["port"] = _int(params, "port", 43113, url)
    elif "port" in params:
        raise DeviceURLError(f"{url}: port is an option of udp_multicast only")
    return parts.netloc, channel, params, kwargs


def _odrive_parts(url: str) -> tuple[str, str, int, int, dict]:
    interface, channel, params, kwargs = _bus_location(url, set(SCHEMES["odrive"].options))
    if "tvl_endpoint" not in params:
        raise DeviceURLError(f"{url}: tvl_endpoint=ID is required (the endpoint id of "
                             f"axis0.controller.config.enable_torque_mode_vel_limit in your firmware's "
                             f"flat_endpoints.json), so that the host can switch it off")
    node = _int(params, "node", 0, url)
    if not 0 <= node <= 63:
        raise DeviceURLError(f"{url}: node must be 0..63, got {node}")
    endpoint = _int(params, "tvl_endpoint", 0, url)
    if not 0 <= endpoint <= 0xFFFF:
        raise DeviceURLError(f"{url}: tvl_endpoint must be 0..65535 (a CAN Simple endpoint id), got {endpoint}")
    return interface, channel, node, endpoint, kwargs


def _open_odrive(url: str, timeout: float):
    from hilbench.drivers.odrive_drive import OdriveDrive

    interface, channel, node, endpoint, kwargs = _odrive_parts(url)
    return OdriveDrive(interface, channel, node, endpoint, timeout=timeout, **kwargs)


def _moteus_parts(url: str) -> tuple[str, str, int, dict]:
    interface, channel, params, kwargs = _bus_location(url, set(SCHEMES["moteus"].options))
    controller = _int(params, "id", 1, url)
    if not 1 <= controller <= 126:
        raise DeviceURLError(f"{url}: id must be 1..126 (127 is moteus's broadcast id), got {controller}")
    for key in ("kp", "kd"):
        if key in params:
            try:
                kwargs[key] = float(params[key])
            except ValueError:
                raise DeviceURLError(f"{url}: {key} must be a number, got {params[key]!r}") from None
            if not (kwargs[key] > 0 and kwargs[key] < float("inf")):
                raise DeviceURLError(f"{url}: {key} must be positive and finite (the controller's "
                                     f"servo.pid_position.{key}), got {params[key]}")
    return interface, channel, controller, kwargs


def _open_moteus(url: str, timeout: float):
    from hilbench.drivers.moteus_drive import MoteusDrive

    interface, channel, controller, kwargs = _moteus_parts(url)
    return MoteusDrive(interface, channel, controller, timeout=timeout, **kwargs)


def _canopen_parts(url: str) -> tuple[str, str, int, str, dict]:
    interface, channel, params, kwargs = _bus_location(url, set(SCHEMES["canopen"].options))
    if "eds" not in params:
        raise DeviceURLError(f"{url}: eds=FILE is required (the drive's EDS or DCF)")
    node = _int(params, "node", 1, url)
    if not 1 <= node <= 126:
        raise DeviceURLError(f"{url}: node must be 1..126 (127 is the host's own heartbeat id), got {node}")
    cycles = _int(params, "enable_cycles", 4, url)
    if not 0 <= cycles <= 1000:
        raise DeviceURLError(f"{url}: enable_cycles must be 0..1000, got {cycles}")
    return interface, channel, node, params["eds"], {**kwargs, "enable_cycles": cycles}


def _open_canopen(url: str, timeout: float):
    from hilbench.drivers.canopen_drive import CanopenDrive

    interface, channel, node, eds, kwargs = _canopen_parts(url)  # kwargs: the bus's, and enable_cycles
    if not os.path.isfile(eds):
        raise DeviceURLError(f"{url}: EDS file {eds} does not exist")
    return CanopenDrive(interface, channel, node, eds, timeout=timeout, **kwargs)


SCHEMES: dict[str, Scheme] = {s.name: s for s in (
    Scheme("serial", "serial:///dev/ttyUSB0?baud=2000000", frozenset({"baud"}), _serial_parts, _open_serial),
    Scheme("can", "can://INTERFACE/CHANNEL?node=1&fd=1&bitrate=1000000", frozenset({"node", "fd", "bitrate"}),
           _can_parts, _open_can),
    Scheme("canopen", "canopen://INTERFACE/CHANNEL?node=N&eds=FILE",
           frozenset({"node", "eds", "bitrate", "port", "enable_cycles"}), _canopen_parts, _open_canopen),
    Scheme("odrive", "odrive://INTERFACE/CHANNEL?node=N&tvl_endpoint=ID",
           frozenset({"node", "tvl_endpoint", "bitrate", "port"}), _odrive_parts, _open_odrive),
    Scheme("moteus", "moteus://INTERFACE/CHANNEL?id=1",
           frozenset({"id", "kp", "kd", "bitrate", "port"}), _moteus_parts, _open_moteus),
    Scheme("sim", "sim://?pacing=lockstep&config=sim.toml&seed=3&tick=0.004",
           frozenset({"pacing", "config", "seed", "tick"}), _sim_params, _open_sim),
)}


def describe_schemes() -> str:
    """The device URL forms, for help texts."""
    return ", ".join(s.form for s in SCHEMES.values())


def _scheme(url: str) -> Scheme:
    name, sep, _ = url.partition("://")
    if not sep:
        raise DeviceURLError(f"{url!r} is not a device URL ({', '.join(n + '://...' for n in SCHEMES)})")
    if name not in SCHEMES:
        raise DeviceURLError(f"{url}: unknown scheme {name!r} ({', '.join(SCHEMES)})")
    return SCHEMES[name]


def check_device_url(url: str) -> None:
    """Raise :class:`DeviceURLError` for a URL :func:`open_device` would refuse, without opening anything."""
    _scheme(url).check(url)


def open_device(url: str, timeout: float = 2.0) -> Device:
    """Connect to the device at ``url`` (see the module doc): an :class:`Amplifier` for the hilbench protocol,
    a host-clocked :class:`Device` for a CANopen, ODrive or moteus drive."""
    scheme = _scheme(url)
    scheme.check(url)
    return scheme.open(url, timeout)


def start_simulator(options: dict[str, str]) -> tuple[subprocess.Popen, str]:
    """Start ``python -m hilbench.firmware_sim --serial`` with ``options`` (pacing, config, seed, tick) as flags;
    return the process and the pty path it printed."""
    cmd = [sys.executable, "-m", "hilbench.firmware_sim", "--serial", "--parent-pid", str(os.getpid())]
    for key in ("pacing", "config", "seed", "tick"):
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
