"""The protocol runner: startup (configure, arm), execute (stream, log), shutdown (always).

    with Bench.open("sim://") as bench:
        result = bench.run(Identification(duration=10, amplitude=4.0), out="runs/id.h5")

Every sample the device returns goes to the run file as it arrives. The file is flushed at least every
0.5 s of device time and says ``completed``, ``aborted`` or, after a crash, ``crashed``. Whatever
happens (an exception, Ctrl-C, an abort, a device fault), shutdown zeroes the current and disarms.
"""

from __future__ import annotations

import math
import signal
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from hilbench.bench.acquisition.protocols import Protocol
from hilbench.bench.errors import BenchError
from hilbench.common.runfile import (
    CURRENT_CMD,
    CURRENT_FF,
    DEVICE_CHANNELS,
    HOST_CLOCKED_CHANNELS,
    POSITION_CMD,
    SAMPLE_INDEX,
    DeviceIdentity,
    RunFileError,
    RunWriter,
)
from hilbench.drivers import protocol as wire
from hilbench.drivers.amplifier import Amplifier
from hilbench.drivers.device import Device, refusal
from hilbench.drivers.device_url import open_device
from hilbench.drivers.errors import ConfigError, DeviceFaultError, DriverError, SampleLossError

#: Default device settings: the simulated DC motor's catalogue values (firmware_sim default_sim.toml).
DEFAULT_TORQUE_CONSTANT = 0.2  # N*m/A
DEFAULT_COUNTS_PER_REV = 1 << 20


#: Ranges of the device settings: (low, high, unit); a value outside is refused before anything moves.
#: The highs are far beyond any bench this drives, there only to catch typos (1e9 A) and overflow.
SETTING_RANGES: dict[str, tuple[float, float, str]] = {
    "current_limit": (0.0, 1000.0, "A"),
    "velocity_limit": (0.0, 1e5, "rad/s"),
    "position_min": (-math.inf, math.inf, "rad"),
    "position_max": (-math.inf, math.inf, "rad"),
    "watchdog_timeout": (0.0, 60.0, "s"),
    "torque_constant": (0.0, 100.0, "N*m/A"),
    "counts_per_rev": (1, 2**32 - 1, "counts"),
    "ratio": (0.0, 1e6, "1"),
    # position loop (position mode, protocol v2); 0 is allowed for ki, kd, i_limit and d_cutoff (term off)
    "position_kp": (0.0, 1e7, "A/rad"),
    "position_ki": (0.0, 1e10, "A/(rad*s)"),
    "position_kd": (0.0, 1e5, "A*s/rad"),
    "position_i_limit": (0.0, 1000.0, "A"),
    "position_d_cutoff": (0.0, 10000.0, "Hz"),
}
#: Settings that may be 0 (the rest must be > their low end).
_ZERO_ALLOWED = ("watchdog_timeout", "position_ki", "position_kd", "position_i_limit", "position_d_cutoff")


class SettingsError(BenchError, ValueError):
    """A device setting of the wrong type or out of its range (the message starts with its name)."""


#: what a campaign's [plant] table may say of the load, and its unit (at the load)
PLANT_UNITS = {"inertia": "kg*m^2"}


@dataclass(frozen=True)
class DeviceSettings:
    """Limits and calibration sent to the device with every run (units at the motor shaft).

    Every field is checked on construction against :data:`SETTING_RANGES` (:class:`SettingsError`):
    numbers only, limits and calibration > 0, the watchdog >= 0 (0 = off), ``counts_per_rev`` a whole
    number, a position window with ``position_min < position_max`` (infinite ends allowed)."""

    current_limit: float = 20.0          # A
    velocity_limit: float = 300.0        # rad/s
    position_min: float = -math.inf      # rad
    position_max: float = math.inf      # rad
    watchdog_timeout: float = 0.5        # s; 0.1 s trips under host load on small machines (see docs/protocol.md)
    torque_constant: float = DEFAULT_TORQUE_CONSTANT  # N*m/A
    counts_per_rev: int = DEFAULT_COUNTS_PER_REV
    ratio: float = 1.0                   # motor revolutions per load revolution
    # position loop gains (docs/protocol.md "Position mode"; defaults hold the simulated DC motor)
    position_kp: float = wire.POSITION_GAINS["position_kp"]              # A/rad
    position_ki: float = wire.POSITION_GAINS["position_ki"]              # A/(rad*s)
    position_kd: float = wire.POSITION_GAINS["position_kd"]              # A*s/rad
    position_i_limit: float = wire.POSITION_GAINS["position_i_limit"]    # A
    position_d_cutoff: float = wire.POSITION_GAINS["position_d_cutoff"]  # Hz

    def __post_init__(self) -> None:
        for name, (low, high, unit) in SETTING_RANGES.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
                raise SettingsError(f"{name} must be a number in {unit}, got {value!r}")
            if name == "counts_per_rev":
                if int(value) != value:
                    raise SettingsError(f"counts_per_rev must be a whole number of counts, got {value!r}")
                object.__setattr__(self, name, int(value))
            else:
                object.__setattr__(self, name, float(value))
            value = getattr(self, name)
            infinite_ok = name.startswith("position")
            strict = name not in _ZERO_ALLOWED and not infinite_ok
            bad = math.isnan(value) or (not infinite_ok and not math.isfinite(value)) or value > high \
                or value < low or (strict and value <= low)
            if bad:
                rel = ">" if strict else ">="
                raise SettingsError(f"{name} = {value!r} {unit} is out of range: it must be {rel} {low:g} and "
                                    f"<= {high:g} {unit}")
        if not self.position_min < self.position_max:
            raise SettingsError(f"position_min ({self.position_min} rad) must be below position_max "
                                f"({self.position_max} rad)")

    def config(self, protocol: Protocol, feedforward: bool = False) -> wire.Config:
        """The CONFIG of a run of ``protocol``; ``feedforward``: position setpoints carry a current (A)."""
        mode = wire.Mode[protocol.mode.upper()]  # type: ignore[attr-defined]
        return wire.Config(sample_rate=protocol.sample_rate, mode=mode,  # type: ignore[attr-defined]
                           current_limit=self.current_limit, velocity_limit=self.velocity_limit,
                           position_min=self.position_min, position_max=self.position_max,
                           watchdog_timeout=self.watchdog_timeout, torque_constant=self.torque_constant,
                           counts_per_rev=self.counts_per_rev, ratio=self.ratio,
                           **{g: getattr(self, g) for g in wire.Config.GAINS}, feedforward=feedforward)

    def limit_for(self, protocol: Protocol) -> float:
        """The bound of the streamed current or velocity: A in current and position mode (there, of the
        feed-forward current), rad/s in velocity mode."""
        return self.velocity_limit if protocol.mode == "velocity" else self.current_limit  # type: ignore


@dataclass
class Progress:
    """One received sample block, for progress displays and live plots (arrays of the new block)."""

    done: int            # samples received so far
    total: int           # samples in the protocol
    eta_s: float         # estimated seconds to go (wall clock)
    segment: int         # index of the current segment (stepped-sine step)
    n_segments: int
    t: np.ndarray        # device time, s
    current_cmd: np.ndarray  # A
    current_meas: np.ndarray  # A
    torque: np.ndarray   # N*m
    position: np.ndarray  # rad
    velocity: np.ndarray  # rad/s, backward difference of position (display only; not logged)
    position_cmd: np.ndarray | None = None  # rad at the load: the position setpoint (position mode only)


@dataclass
class RunResult:
    path: Path
    status: str
    samples: int
    uid: str = ""
    message: str = ""


OPERATOR_ABORT = "aborted by operator"  # the abort event's opening words unless a reason is given


@dataclass
class RunControl:
    """Thread-safe pause/resume/abort of a run. Pause takes effect at the next segment boundary."""

    _resume: threading.Event = field(default_factory=threading.Event)
    _abort: threading.Event = field(default_factory=threading.Event)
    reason: str = OPERATOR_ABORT

    def __post_init__(self) -> None:
        self._resume.set()

    def pause(self) -> None:
        self._resume.clear()

    def resume(self) -> None:
        self._resume.set()

    def abort(self, reason: str = OPERATOR_ABORT) -> None:
        """End the run at the next block; ``reason`` starts the run's abort event."""
        if not self._abort.is_set():
            self.reason = reason
        self._abort.set()
        self._resume.set()

    @property
    def paused(self) -> bool:
        return not self._resume.is_set()

    @property
    def aborted(self) -> bool:
        return self._abort.is_set()

    def wait_while_paused(self, keepalive: Callable[[], None], period: float = 0.05) -> None:
        while not self._resume.wait(period):
            keepalive()


class AbortRun(BenchError):
    """Raised inside a run when the operator aborts it."""


class Bench:
    """A connected bench: one device, its settings, and the protocols run on it."""

    def __init__(self, amplifier: Amplifier | Device, url: str, settings: DeviceSettings | None = None):
        self.amplifier = amplifier
        self.url = url
        self.settings = settings or DeviceSettings()
        self._temperatures: list[float] = []  # the present run's first, last and highest temperature, degC

    @classmethod
    def open(cls, url: str = "sim://", settings: DeviceSettings | None = None, timeout: float = 2.0) -> Bench:
        """Connect to the device at ``url`` (``sim://`` starts the simulated amplifier)."""
        return cls(open_device(url, timeout=timeout), url, settings)

    def __enter__(self) -> Bench:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self.amplifier.close()

    def identity(self) -> DeviceIdentity:
        return self.amplifier.info()

    def run(self, protocol: Protocol, out: str | Path | None = None, *, operator: str = "", notes: str = "",
            progress: Callable[[Progress], None] | None = None, control: RunControl | None = None,
            overwrite: bool = False, plant: dict[str, float] | None = None) -> RunResult:
        """Run ``protocol`` and log it to ``out`` (default ``runs/<protocol>-<uid>.h5``).

        ``plant``: what is known of the load beyond the device's calibration, written into the run file's
        calibration with the unit of :data:`PLANT_UNITS` (a campaign's ``[plant] inertia``, which the skeleton
        analysis reads when no mass is given).

        ``progress`` is called with a :class:`Progress` after every sample block the device returns, in the
        calling thread: ``done`` (samples received so far) grows strictly from call to call, ``total`` is the
        protocol's sample count in every call, and a completed run's last call has ``done == total``. The call
        sits in the streaming loop: keep it short (print a line, update a bar), or the device's buffer drains.

        Raises whatever the device or the link raised after the file has been finished as ``aborted``;
        :class:`AbortRun` and Ctrl-C are turned into an ``aborted`` result (Ctrl-C is re-raised).
        """
        control = control or RunControl()
        if hasattr(protocol, "bind"):  # needs the device's calibration (acquisition/compensation.py)
            protocol = protocol.bind(self.settings)
        protocol.check_memory()
        why = refusal(self.url, self.amplifier.capabilities, protocol.mode, protocol.sample_rate)  # type: ignore
        if why:  # before anything moves
            raise ConfigError(f"cannot run {protocol.name}: {why}")
        limit = self.settings.limit_for(protocol)
        excitation = protocol.excitation(limit)
        segments = protocol.segments(limit)
        position = protocol.mode == "position"  # type: ignore[attr-defined]
        ff = protocol.feedforward(limit) if position and hasattr(protocol, "feedforward") else None
        if ff is not None:
            ff = np.asarray(ff, dtype=np.float64)
            if ff.shape != excitation.u.shape:
                raise ConfigError(f"{protocol.name}: feed-forward of shape {ff.shape} for setpoints of shape "
                                  f"{excitation.u.shape}")
        config = self.settings.config(protocol, feedforward=ff is not None)
        # a position protocol gives angles at the load; the device takes them at the encoder (motor) shaft
        shaft = excitation.u * self.settings.ratio if position else excitation.u
        stream = shaft if ff is None else np.column_stack([shaft, ff])
        stamp = uuid.uuid4().hex[:8]
        path = Path(out) if out is not None else Path("runs") / f"{protocol.name}-{stamp}.h5"
        path.parent.mkdir(parents=True, exist_ok=True)
        arrays = {"setpoints": excitation.u}
        if ff is not None:
            arrays["feedforward"] = ff
        if excitation.windows is not None:
            arrays["step_windows"] = excitation.windows
        if hasattr(protocol, "protocol_arrays"):  # e.g. presliding's turning points
            arrays.update(protocol.protocol_arrays())
        amp = self.amplifier
        # -- startup
        amp.configure(config)
        host_clocked = amp.clock == "host"
        reference = ((POSITION_CMD,) + ((CURRENT_FF,) if ff is not None else ())) if position else ()
        writer = RunWriter(
            path, sample_rate=float(protocol.sample_rate),  # type: ignore
            channels=(DEVICE_CHANNELS + reference + (HOST_CLOCKED_CHANNELS if host_clocked else ())
                      + amp.reported_channels),
            record=getattr(protocol, "record", "torque-driven"),
            device=replace(self.identity(), url=self.url),
            config={k: getattr(config, k) if not isinstance(getattr(config, k), float) or
                    math.isfinite(getattr(config, k)) else str(getattr(config, k)) for k in config.__slots__},
            calibration={"torque_constant": config.torque_constant, "counts_per_rev": config.counts_per_rev,
                         "ratio": config.ratio, **(plant or {}),
                         "units": {"torque_constant": "N*m/A", "ratio": "1",
                                   **{k: PLANT_UNITS[k] for k in plant or {}}}},
            protocol_name=protocol.name, protocol_params=protocol.parameters(), protocol_arrays=arrays,
            operator=operator, notes=notes, overwrite=overwrite,
        )
        status, message = "aborted", ""
        self._temperatures = []
        try:
            amp.arm()
            self._execute(protocol, stream, segments, writer, progress, control)
            status = "completed"
        except AbortRun as exc:
            message = str(exc)
            writer.add_event("abort", message)
        except KeyboardInterrupt as exc:
            message = f"interrupted ({exc or 'Ctrl-C'})"
            writer.add_event("abort", message)
            raise
        except RunFileError:  # the writer failed (disk full): it has recorded why and marked the run failed
            raise
        except DeviceFaultError as exc:
            if exc.faults & wire.Fault.WATCHDOG:  # "WATCHDOG" alone does not say what to do
                exc.args = (f"{exc}: {watchdog_hint(self.settings.watchdog_timeout)}",)
            message = str(exc)
            writer.add_event("fault", message)
            raise
        except BaseException as exc:
            message = " ".join(str(exc).split()) or type(exc).__name__
            if writer.status == "running":
                writer.add_event("error", message)
            raise
        finally:
            # -- shutdown: always zero the current and disarm, then finish the file
            try:
                amp.disarm()
            except DriverError:
                pass
            for kind, text in amp.run_events():  # host-clocked timing, latched EMCY
                writer.add_event(kind, text)
            if self._temperatures:  # the run's thermal summary, in the file beside the channel
                first, last, high = self._temperatures
                writer.add_event("info", f"winding temperature {first:.2f} -> {last:.2f} degC (max {high:.2f} degC)")
            writer.finish(status)
        return RunResult(path, status, writer.n_samples, writer.uid, message)  # what the file holds

    def _execute(self, protocol: Protocol, u: np.ndarray, segments: list[tuple[int, int]], writer: RunWriter,
                 progress: Callable[[Progress], None] | None, control: RunControl) -> int:
        """Stream ``u`` segment by segment: (n,) setpoints, or (n, 2) angle (rad) and feed-forward (A)."""
        amp = self.amplifier
        total = len(u)
        position = protocol.mode == "position"  # type: ignore[attr-defined]
        ratio = self.settings.ratio
        done = 0
        t_start = time.monotonic()
        last_pos = None
        for seg, (a, b) in enumerate(segments):
            if control.paused:
                writer.add_event("pause", f"paused before step {seg}")
                amp.disarm()
                control.wait_while_paused(keepalive=amp.status)
                if not control.aborted:
                    writer.add_event("resume", f"resumed at step {seg}")
                    amp.arm()
            if control.aborted:
                raise AbortRun(f"{control.reason} after {done} of {total} samples")
            k = a  # setpoint of the block's first sample
            for blk in amp.stream(u[a:b]):
                n = len(blk)
                measured = blk.position
                torque = blk.torque
                t = blk.time
                reference = {}
                if position:  # the reference at the load, like `position` (setpoints are at the motor)
                    ref = u[k: k + n].reshape(n, -1)
                    reference[POSITION_CMD] = ref[:, 0] / ratio
                    if ref.shape[1] > 1:
                        reference[CURRENT_FF] = ref[:, 1]
                k += n
                extra = blk.extra()
                writer.append({SAMPLE_INDEX: blk.index, "t": t, CURRENT_CMD: blk.current_cmd,
                               "current": blk.current_meas, "torque": torque, "position": measured,
                               "counts": blk.counts, **reference, **extra})
                if n and "temperature" in extra and math.isfinite(extra["temperature"][-1]):  # NaN: flagged
                    reading = float(extra["temperature"][-1])
                    seen = self._temperatures
                    self._temperatures = [seen[0], reading, max(seen[2], reading)] if seen else [reading] * 3
                done += n
                if progress is not None:
                    prev = measured[:1] if last_pos is None else np.array([last_pos])
                    velocity = np.diff(np.concatenate([prev, measured])) * blk.sample_rate
                    elapsed = time.monotonic() - t_start
                    eta = elapsed / done * (total - done) if done else math.inf
                    progress(Progress(done, total, eta, seg, len(segments), t, blk.current_cmd,
                                      blk.current_meas, torque, measured, velocity, reference.get(POSITION_CMD)))
                if n:
                    last_pos = float(measured[-1])
                if control.aborted:
                    raise AbortRun(f"{control.reason} after {done} of {total} samples")
            if k != b:  # a run that ends short is never completed, whatever the driver said
                raise SampleLossError(f"the device returned {k - a} of the {b - a} samples of step {seg} "
                                      f"({done} of {total} in all): the run is incomplete")
        return done


def watchdog_hint(timeout: float) -> str:
    """What a watchdog trip means and what to change, in the CLI's words."""
    return (f"the device's watchdog tripped: no setpoint reached it for {timeout:g} s (--watchdog-timeout), "
            f"usually a busy host or link; raise --watchdog-timeout (e.g. {max(1.0, 2 * timeout):g} s) or run with "
            f"less load, then 'hilbench fault clear' before the next run")


@contextmanager
def signals_as_interrupt(signums: tuple[int, ...] = (signal.SIGTERM, signal.SIGHUP),
                         control: RunControl | None = None) -> Iterator[None]:
    """While active, SIGTERM and SIGHUP end a run the way Ctrl-C does: a KeyboardInterrupt naming the
    signal, so shutdown zeroes the current, disarms and finishes the file ``aborted``. Main thread only
    (elsewhere Python cannot take signals, and this does nothing).

    With ``control``, Ctrl-C (SIGINT) is taken too, and every signal also sets ``control``'s abort flag: an
    exception raised while C code holds the thread can be cleared there and lost, the flag cannot, and the
    run loop checks it after every sample block. A SIGINT the process was started ignoring (a background job
    of a script) stays ignored, as Python itself leaves it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: object) -> None:
        if control is not None:
            control.abort()
        raise KeyboardInterrupt() if signum == signal.SIGINT else KeyboardInterrupt(signal.Signals(signum).name)

    if control is not None and signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        signums = (*signums, signal.SIGINT)
    previous = {s: signal.signal(s, interrupt) for s in signums}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def settings_dict(settings: DeviceSettings) -> dict:
    return {k: (v if not isinstance(v, float) or math.isfinite(v) else str(v))
            for k, v in asdict(settings).items()}
