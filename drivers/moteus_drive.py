"""A moteus controller over the ``moteus`` library's python-can transport (CAN-FD), host-clocked.

    with MoteusDrive("socketcan", "can0", controller_id=1) as drive:
        drive.configure(Config(sample_rate=1000, current_limit=20.0, torque_constant=0.2))
        drive.arm()
        for block in drive.stream(setpoints_in_amperes):
            use(block.time, block.position, block.torque, block.host_time)

Every frame is built and parsed by the ``moteus`` library (``Controller.make_position``, ``make_stop``,
``make_custom_query``, ``parse_registers``); one-off exchanges (identity, state, faults, stop) go through its
``Transport`` over a ``PythonCanDevice``. The stream is the host-clocked loop of drivers/host_clocked.py: per
cycle one position-mode command with a query (arbitration id ``0x8000 | host << 8 | id``); the controller answers
each with mode, position (rev), velocity (rev/s), torque (N*m), fault and the torque it commands (0x03a), sampled
when the command arrives, before it acts.

- **torque** (``current`` mode, setpoints in A): position mode with ``kp_scale = kd_scale = 0`` and the
  feed-forward torque ``k_t * i``, moteus's way to command torque, which keeps its position-mode watchdog;
- **position** (setpoints in rad at the motor, with an optional feed-forward current): position in revolutions,
  ``kp_scale`` and ``kd_scale`` from the host's gains over the controller's own ``servo.pid_position.kp`` and
  ``.kd`` (``&kp=`` and ``&kd=`` in the URL: the register protocol cannot read them), the velocity command the
  setpoint's slope; the integral gain is the controller's own;
- every command carries ``maximum_torque = k_t * current_limit``; the host checks the position window and the
  velocity limit on every reply (drivers/host_cycle.py ``Guard``);
- **the watchdog** is the controller's: the host never writes 0x027, so ``servo.default_timeout_s`` (0.1 s by
  default) applies; arming starts a zero-torque feed (kp = kd = 0) that keeps it fed until the stream's own
  commands take over and again after them; a host that dies leaves the controller in mode 11 (timeout) within
  that time, latched until a stop (``hilbench fault clear``);
- **one owner**: the host listens first, sending nothing, and refuses a controller another host commands (its
  frames on the bus, or the controller already in position or current mode).
"""

from __future__ import annotations

import asyncio
import math
import struct
import threading
import time

import numpy as np

from hilbench.common.can import pad_fd
from hilbench.common.runfile.schema import HOST_TIME, DeviceIdentity
from hilbench.drivers import errors as e
from hilbench.drivers import protocol as p
from hilbench.drivers.device import Capabilities, CycleSamples
from hilbench.drivers.host_clocked import GuardFrame, HostClockedDevice
from hilbench.drivers.host_cycle import CanCycle, CanCycleSpec

HOST_ID = 0           # the host's source id (the moteus library's default)
OWNER_LISTEN = 0.15   # s the host listens, sending nothing, for another host's commands to the controller
WIDTH = 64            # bytes of a CAN-FD frame
MODE, POSITION, VELOCITY, TORQUE, FAULT, CONTROL_TORQUE = 0x000, 0x001, 0x002, 0x003, 0x00F, 0x03A
STOPPED, FAULTED, CURRENT_MODE, POSITION_MODE, TIMEOUT = 0, 1, 9, 10, 11
MODES = {0: "stopped", 1: "fault", 5: "pwm", 6: "voltage", 7: "voltage foc", 8: "voltage dq", 9: "current",
         10: "position", 11: "timeout", 12: "zero velocity", 13: "stay within", 14: "measure inductance",
         15: "brake"}
#: moteus fault codes (register 0x00f), from its reference manual
FAULTS = {32: "calibration fault", 33: "motor driver fault", 34: "over voltage", 35: "encoder fault",
          36: "motor not configured", 37: "pwm cycle overrun", 38: "over temperature", 39: "outside limit",
          40: "under voltage", 41: "config changed", 42: "theta invalid", 43: "position invalid",
          44: "driver enable fault", 45: "stop position deprecated", 46: "timing violation",
          47: "bemf feedforward without accel limit", 48: "invalid limits"}
IDENTITY = {0x100: "model", 0x101: "firmware", 0x102: "register_map", 0x120: "serial1", 0x121: "serial2",
            0x122: "serial3"}
FEED_WAIT = 0.01  # s between queries while arming
PROBE = 1.2345  # a float whose four bytes are all non-zero: how a command's value is found in its frame


def reply_layout(data: bytes) -> dict[int, tuple[int, int]]:
    """Where each register's value sits in a moteus reply frame: register -> (byte offset, resolution), from
    the frame's own subframe headers (``moteus.multiplex``: reply base 0x20, resolution in bits 2-3, a count of
    1-3 in bits 0-1 or in the next byte, the first register as a varuint)."""
    from moteus import multiplex as mp

    out, i = {}, 0
    while i < len(data) and data[i] & 0xF0 == mp.REPLY_BASE:
        resolution, count = (data[i] >> 2) & 3, data[i] & 3
        i += 1
        if count == 0:
            count, i = data[i], i + 1
        register, i = mp.read_varuint(i, data)
        if register is None:
            break
        for r in range(register, register + count):
            out[r] = (i, resolution)
            i += mp.resolution_size(resolution)
    return out


def _fault_text(mode: int, code: int) -> str:
    if mode == TIMEOUT:
        return "mode 11 (timeout): no command within the controller's watchdog timeout"
    if mode == FAULTED:
        return f"mode 1 (fault), fault {code} {FAULTS.get(code, 'unknown')}"
    return f"mode {mode} ({MODES.get(mode, 'unknown')})"


class MoteusDrive(HostClockedDevice):
    """A moteus controller ``controller_id`` (1..126) on a python-can bus (CAN-FD)."""

    capabilities = Capabilities({"current": (1000,), "position": (1000,)})
    feeds_watchdog = True

    def __init__(self, interface: str, channel: str, controller_id: int, timeout: float = 2.0,
                 kp: float | None = None, kd: float | None = None, **bus_kwargs) -> None:
        import moteus

        self.name = f"moteus://{interface}/{channel}?id={controller_id}"
        self.label = f"moteus controller {controller_id}"
        self.id, self.timeout, self.gains = controller_id, timeout, (kp, kd)
        self.interface, self.channel, self.bus_kwargs = interface, channel, {**bus_kwargs, "fd": True}
        self.config: p.Config | None = None
        self._estopped = False
        self._halted = False  # the controller left position mode (or was stopped): no feed re-energises it
        self._mode, self._fault = STOPPED, 0  # as last reported
        self._last_cmd = 0.0
        self._loop = asyncio.new_event_loop()
        threading.Thread(target=self._loop.run_forever, name="moteus-transport", daemon=True).start()
        try:
            self.device = moteus.PythonCanDevice(interface=interface, channel=channel, **self.bus_kwargs)
        except Exception as exc:  # python-can raises many types for a missing interface
            self._loop.call_soon_threadsafe(self._loop.stop)
            raise e.DriverError(f"{self.name}: cannot open the CAN bus: {' '.join(str(exc).split())}") from exc
        self.bus = self._guard_bus(self.device._can)  # the transport's own bus (python-can's BusABC)
        try:
            self._refuse_if_owned()  # listens only, before the transport sends anything
            self.transport = moteus.Transport([self.device])
            self.query = moteus.QueryResolution()
            for name in ("voltage", "temperature"):
                setattr(self.query, name, moteus.IGNORE)
            self.query._extra = {CONTROL_TORQUE: moteus.F32}
            self.controller = moteus.Controller(controller_id, query_resolution=self.query,
                                                transport=self.transport, source_can_id=HOST_ID)
            values = self._state()
            if values[MODE] in (POSITION_MODE, CURRENT_MODE):
                raise e.PortBusyError(f"{self.name} is in use by another host (the controller is in "
                                      f"{MODES[values[MODE]]} mode); nothing was commanded: stop that host's run first")
            raw = self._run(self.controller.custom_query({r: moteus.INT32 for r in IDENTITY}), "identity")
            self._identity = {IDENTITY[r]: int(v) for r, v in raw.values.items() if r in IDENTITY}
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------------ the transport
    def _run(self, coroutine, what: str):
        """Run a moteus library coroutine on the transport's event loop; its result (None: no reply)."""
        future = asyncio.run_coroutine_threadsafe(asyncio.wait_for(coroutine, self.timeout), self._loop)
        try:
            return future.result(self.timeout + 1.0)
        except TimeoutError:
            future.cancel()
            raise e.DeviceTimeoutError(f"{self.label} did not answer ({what}) within {self.timeout:g} s") from None

    def _state(self) -> dict[int, float]:
        result = self._run(self.controller.query(), "query")
        if result is None or MODE not in result.values:
            raise e.DeviceTimeoutError(f"{self.label} did not answer a query within {self.timeout:g} s")
        values = dict(result.values)
        self._mode, self._fault = int(values[MODE]), int(values.get(FAULT, 0))
        self._layout = reply_layout(bytes(result.data))
        return values

    def _message(self, command):
        """A library command as a python-can message: moteus's arbitration id, padded to a CAN-FD length."""
        import can

        arb = (0x8000 if command.reply_required else 0) | (HOST_ID << 8) | self.id
        return can.Message(arbitration_id=arb, data=pad_fd(command.data), is_extended_id=arb > 0x7FF, is_fd=True,
                           bitrate_switch=True)

    def _refuse_if_owned(self) -> None:
        """Refuse, having sent nothing, a controller another host commands: its frames, heard on the bus."""
        heard = []
        deadline = time.monotonic() + OWNER_LISTEN
        while (left := deadline - time.monotonic()) > 0:
            msg = self.bus.recv(left)
            if msg is not None and msg.arbitration_id & 0x7F == self.id and (msg.arbitration_id >> 8) & 0x7F != self.id:
                heard.append(msg.arbitration_id)
        if heard:
            raise e.PortBusyError(f"{self.name} is in use by another host (its commands, CAN id "
                                  f"0x{heard[-1]:X}, on the bus); nothing was sent to it: stop that host's run first")

    # ------------------------------------------------------------------ what every device answers
    def info(self) -> DeviceIdentity:
        ident = self._identity
        serial = "".join(f"{ident.get(k, 0):08x}" for k in ("serial1", "serial2", "serial3"))
        # the controller samples when a command arrives: host_time (its echo from the bus) is the sample time
        return DeviceIdentity(
            protocol="moteus register protocol over CAN-FD (moteus library, python-can transport)", url=self.name,
            sample_times=HOST_TIME, model=f"0x{ident.get('model', 0):X}", firmware=f"0x{ident.get('firmware', 0):X}",
            serial=serial, details={"id": self.id, "register_map": ident.get("register_map", 0),
                                    "watchdog": "the controller's servo.default_timeout_s (0x027 never written)"})

    def state(self) -> str:
        values = self._state()
        return f"{MODES.get(self._mode, 'unknown')} (mode {self._mode}, fault {int(values.get(FAULT, 0))})"

    def faults(self) -> list[str]:
        self._state()
        out = [_fault_text(self._mode, self._fault)] if self._mode in (FAULTED, TIMEOUT) else []
        if self._estopped:
            out.append("e-stop requested by the host (stop sent)")
        return out

    def fault_line(self) -> str:
        if self._mode in (FAULTED, TIMEOUT):
            return f"{self.label}: {_fault_text(self._mode, self._fault)}"
        return ""

    def clear_faults(self) -> None:
        """A stop command: moteus leaves fault and timeout modes only through stop."""
        self._run(self.controller.set_stop(), "stop")
        self._estopped = False
        if self._state()[MODE] in (FAULTED, TIMEOUT):
            raise e.DeviceFaultError(f"{self.label} is still in {_fault_text(self._mode, self._fault)} after a stop")

    def status(self) -> int:
        return self._mode

    def live_state(self) -> dict:
        streaming = self._cycle is not None
        mode = self._mode if streaming else int(self._state()[MODE])
        return {"state": f"mode {mode} ({MODES.get(mode, '?')})", "armed": mode in (POSITION_MODE, CURRENT_MODE),
                "streaming": streaming, "faults": [self.fault_line()] if self.fault_line() else [],
                "cycle": self._progress, "current_cmd": self._last_cmd if streaming else 0.0,
                "counters": self.timing_counters()}

    # ------------------------------------------------------------------ Device API
    def configure(self, config: p.Config) -> None:
        self._check_config(config)
        if config.mode == p.Mode.POSITION and None in self.gains:
            raise e.ConfigError(f"{self.name}: position mode needs the controller's own position gains in the URL "
                                f"(&kp=N*m/rev&kd=N*m*s/rev, its servo.pid_position.kp and .kd), to scale the host's")
        self.config = config

    def arm(self) -> None:
        self._configured("arming")
        self._state()
        if self._mode in (FAULTED, TIMEOUT) or self._estopped:
            why = "e-stop requested" if self._estopped else _fault_text(self._mode, self._fault)
            raise e.DeviceFaultError(f"{self.label}: {why}; clear it with `hilbench fault clear --device URL` first")
        self._halted = False
        self._start_feed()  # zero torque, position mode: the power stage on, the watchdog fed
        deadline = time.monotonic() + self.timeout
        while self._state()[MODE] != POSITION_MODE:
            if time.monotonic() > deadline:
                self._stop_feed()
                raise e.DeviceTimeoutError(f"{self.label} did not enter position mode within {self.timeout:g} s "
                                           f"({_fault_text(self._mode, self._fault)})")
            time.sleep(FEED_WAIT)

    def _start_feed(self) -> None:
        if not self._halted:  # after a stop, a fault or a timeout only arm() powers the motor again
            super()._start_feed()

    def _feed_message(self):
        return self._message(self._zero_torque())

    def _zero_torque(self):
        return self.controller.make_position(position=math.nan, velocity=0.0, feedforward_torque=0.0, kp_scale=0.0,
                                             kd_scale=0.0)

    def disarm(self) -> None:
        self._halted = True
        self._stop_cycle()  # joined: no keepalive frame of the cycle follows the stop sent below
        self._stop_feed()
        self.bus.send(self._message(self.controller.make_stop()))

    def estop(self) -> None:
        self._estopped = self._halted = True
        cycle = self._cycle
        if cycle is not None:
            cycle.estop()
        self._stop_feed()
        self.bus.send(self._message(self.controller.make_stop()))

    # ------------------------------------------------------------------ the stream loop's hooks
    def _check_ready(self) -> None:
        self._state()  # also the reply layout the stream's rows are decoded with
        if self._estopped or self._mode != POSITION_MODE:
            raise e.CommandRefusedError(f"cannot stream: {self.label} is not in position mode "
                                        f"({_fault_text(self._mode, self._fault)}); arm it first")

    def _commands(self, values: np.ndarray) -> tuple[bytes, np.ndarray]:
        """The cycle's command frames: the library's frame for the first sample, and its bytes for every sample
        (uint8, (n, len)): the values that change are written where the library puts them."""
        cfg = self.config
        kt = cfg.torque_constant
        fixed = {"maximum_torque": cfg.current_limit * kt, "query": True}
        if cfg.mode == p.Mode.POSITION:
            kp, kd = self.gains
            per_rev = kt * 2 * math.pi  # A/rad -> N*m/rev
            fixed.update(kp_scale=cfg.position_kp * per_rev / kp, kd_scale=cfg.position_kd * per_rev / kd)
            angle = values if values.ndim == 1 else values[:, 0]
            ff = np.zeros(len(values)) if values.ndim == 1 else values[:, 1] * kt
            # the velocity command is the setpoint's own slope: the derivative term damps the error, not the motion
            slope = np.gradient(angle) * cfg.sample_rate if len(angle) > 1 else np.zeros(1)
            columns = {"position": angle / (2 * math.pi), "velocity": slope / (2 * math.pi), "feedforward_torque": ff}
        else:
            fixed.update(position=math.nan, velocity=0.0, kp_scale=0.0, kd_scale=0.0)
            columns = {"feedforward_torque": values * kt}
        zero = {name: 0.0 for name in columns}
        base = self._message(self.controller.make_position(**fixed, **zero)).data
        out = np.tile(np.frombuffer(bytes(base), np.uint8), (len(values), 1))
        for name, column in columns.items():
            probe = self._message(self.controller.make_position(**fixed, **{**zero, name: PROBE})).data
            at = next(i for i, (x, y) in enumerate(zip(base, probe, strict=True)) if x != y)
            assert bytes(probe[at:at + 4]) == struct.pack("<f", PROBE), "the library's position frame changed"
            out[:, at:at + 4] = np.asarray(column, "<f4").view(np.uint8).reshape(-1, 4)
        return bytes(base), out

    def _cycle_spec(self, values: np.ndarray) -> tuple[CanCycleSpec, np.ndarray]:
        base, frames = self._commands(values)
        command_id = 0x8000 | (HOST_ID << 8) | self.id
        tx = np.zeros((len(values), 1, WIDTH), np.uint8)
        tx[:, 0, :len(base)] = frames
        end = self._message(self._zero_torque()).data
        stop = self._message(self.controller.make_stop(query=True)).data  # answered: the stream sees mode 0
        spec = CanCycleSpec(self.interface, self.channel, self.bus_kwargs, float(self.config.sample_rate),
                            (command_id,), (len(base),), ((self.id << 8) | HOST_ID,), (bytes(stop),), (bytes(end),),
                            echo_id=command_id,  # host_time: when command k was on the bus
                            guards=self._guards(self.config), fd=True, width=WIDTH)
        # the torque command as sent (float32 on the wire); position mode: the controller reports its own (0x03a)
        self._commanded = (np.asarray(values * self.config.torque_constant, "<f4").astype(np.float64)
                           if self.config.mode != p.Mode.POSITION else None)
        return spec, tx

    def _decode(self, rows: np.ndarray) -> dict[int, np.ndarray]:
        """Mode, position, velocity, torque, fault and control torque of reply rows (uint8, (k, 64))."""
        out = {}
        for register in (MODE, POSITION, VELOCITY, TORQUE, FAULT, CONTROL_TORQUE):
            offset, resolution = self._layout[register]
            dtype = ("<i1", "<i2", "<i4", "<f4")[resolution]
            size = np.dtype(dtype).itemsize
            out[register] = rows[:, offset:offset + size].copy().view(dtype).ravel().astype(np.float64)
        return out

    def _rows(self, done: int, ready: int, arrays: dict) -> tuple[CycleSamples | None, int, bool]:
        v = self._decode(arrays["rx"][0, done:ready])
        mode = v[MODE].astype(np.int64)
        end = False
        left = np.flatnonzero(mode != POSITION_MODE)
        if left.size:  # the controller left position mode (fault, timeout, stop): keep the sample that says so
            ready, end, self._halted = done + int(left[0]) + 1, True, True
            v = {r: a[: ready - done] for r, a in v.items()}
            self._mode, self._fault = int(mode[left[0]]), int(v[FAULT][left[0]])
        return self._block(done, ready, v, arrays), ready, end

    def _block(self, a: int, b: int, v: dict[int, np.ndarray], arrays: dict) -> CycleSamples:
        cfg = self.config
        kt, ratio = cfg.torque_constant, cfg.ratio
        turns = v[POSITION]
        torque_cmd = self._commanded[a:b] if self._commanded is not None else v[CONTROL_TORQUE]
        torque = v[TORQUE]
        self._last_cmd = float(torque_cmd[-1] / kt)
        counts = np.rint(turns * cfg.counts_per_rev).astype(np.int64)
        return CycleSamples(np.arange(a, b, dtype=np.int64), arrays[HOST_TIME][a:b].copy(), counts,
                            torque_cmd / kt, torque / kt, torque_cmd * ratio, torque * ratio,
                            2 * math.pi * turns / ratio, 2 * math.pi * v[VELOCITY] / ratio, cfg.sample_rate,
                            v[MODE].astype(np.uint16))

    def _end_stream(self, cycle: CanCycle, done: int, n: int, allow_loss: bool) -> None:
        if done >= n:
            return
        if self._mode != POSITION_MODE:
            why = "e-stop (stop sent)" if self._estopped else _fault_text(self._mode, self._fault)
            raise e.DeviceFaultError(f"{self.label} left position mode at sample {done - 1}: {why}")
        lost = cycle.sent - done
        if lost and not allow_loss:
            raise e.SampleLossError(f"{self.label}: {lost} of {cycle.sent} commands got no reply")

    def _silence_line(self, done: int, n: int) -> str:
        return f"{self.label} stopped replying at sample {done} of {n} (no reply for {self.timeout:g} s)"

    def _answer_slack(self, rate: float) -> float:
        return rate * 0.25  # a quarter second of commands unanswered before the silence is timed

    def _guard_frame(self) -> GuardFrame:
        """The reply: position (rev) and velocity (rev/s) where the reply layout puts them, float32."""
        (position, p_res), (velocity, v_res) = self._layout[POSITION], self._layout[VELOCITY]
        if p_res != 3 or v_res != 3:
            raise e.ConfigError(f"{self.label} replies position and velocity in resolutions {p_res}, {v_res}, not "
                                f"float32 as queried")
        return GuardFrame(0, "<f", position, velocity, 1 / (2 * math.pi), 1 / (2 * math.pi))

    def _release(self) -> None:
        self._stop_feed()
        transport = getattr(self, "transport", None)
        try:
            if transport is not None:
                transport.close()
            else:
                self.device.close()
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
