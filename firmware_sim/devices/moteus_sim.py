"""A simulated moteus controller: the mjbots register protocol over CAN-FD, with the C plant behind it.

What it implements, as a moteus controller on the bus does (register numbers and scalings are the ``moteus``
library's, ``moteus.protocol``; frames are parsed with its ``parse_registers`` and replies written with its
``Writer`` and ``WriteCombiner``):

- CAN-FD frames with the moteus arbitration id: ``0x8000`` (reply wanted) ``| source << 8 | destination``;
  replies go out as ``controller << 8 | source``, padded to an FD length with 0x50 (NOP);
- mode register 0x000 written by the host: 0 stop (power stage off; clears a fault and the timeout), 10
  position, 9 current (q axis, ``torque = k_t * i_q``). Position mode: ``torque = kp * kp_scale * e + I + kd *
  kd_scale * (velocity - v) + feedforward``, ``e = position - x``, ``I = clip(I + ki * e * dt, +-ilimit *
  ilimit_scale)`` (position in revolutions; a NaN position turns the proportional and integral terms off),
  limited to ``maximum_torque`` (0x025) and the current limit;
- a query answers the registers it names, each at the resolution asked, at the state sampled when the frame
  arrived, before its command acts (the plant's convention: outputs of sample k measured at t_k, input k held
  over [t_k, t_k+1)). Registers: mode, position (rev), velocity (rev/s), torque (N*m), q current (A), motor and
  board temperature, voltage, fault, control torque 0x03a (the torque commanded of the motor), model,
  firmware and register-map version, serial number; anything else answers a read error;
- **the watchdog**: in position or current mode, no command for ``default_timeout`` s (moteus's
  ``servo.default_timeout_s``, 0.1 s) or for the command's own 0x027 enters mode 11 (timeout). Here the timeout
  mode turns the power stage off (moteus's ``servo.timeout_mode = 0``); it latches until a stop command;
- faults latch in mode 1 with their code (0x00f) until a stop command: 39 (outside limit) when the speed
  passes ``servo.max_velocity`` x 1.5.

The plant: each command frame advances it, with the previous command held, by the time since the previous frame
arrived (``clock="real"``, kernel timestamps where the bus has them; at most ``COAST_LIMIT`` s) or by exactly one
nominal period 1/``rate`` (``clock="sync"``, deterministic, for tests); the plant runs at ``oversample`` steps per
period. Current mode and position mode without a loop (kp = kd = 0 and a NaN position: moteus's torque command) hold
their torque over the steps. Position mode with gains closes its loop inside the controller, as a real moteus does
between host commands: at every plant step (``rate * oversample``, 10 kHz by default; a real moteus runs 15-40 kHz),
in the C plant (:meth:`Plant.run_position`), on the encoder's position and a velocity estimated from it by a
critically damped tracking loop (moteus's encoder PLL, ``pll_filter_hz`` -3 dB), the position setpoint advanced by
the velocity command at every step from the command's arrival (moteus's control position).
"""

from __future__ import annotations

import io
import math
import threading
import time
from typing import NamedTuple

import can
import numpy as np
from moteus import multiplex as mp
from moteus.protocol import Mode, Register, Writer, parse_registers

from hilbench.common.can import pad_fd
from hilbench.firmware_sim.devices import drive_sim
from hilbench.firmware_sim.devices.drive_sim import hold_step
from hilbench.firmware_sim.devices.sim_config import SimConfig, substeps_for
from hilbench.firmware_sim.devices.stall_grace import StallGrace
from hilbench.firmware_sim.engine.plant import Plant, PlantOutput

DEFAULT_TIMEOUT = 0.1   # s: moteus's servo.default_timeout_s
COAST_LIMIT = 0.2       # s of plant time one command frame may advance at most (clock "real")
CLOCKS = ("real", "sync")
MODEL, FIRMWARE, REGISTER_MAP = 0x0302, 0x0107, 5  # what the simulated controller says it is (moteus-c1-like)
SERIAL = (0x48425349, 0x4D4F5445, 0x00000001)   # "ISBH", "ETOM", 1: a simulated controller, not a real one
FAULT_OUTSIDE_LIMIT = 39
OVER_SPEED_FACTOR = 1.5
ENERGISED = (int(Mode.POSITION), int(Mode.CURRENT))
PLL_FILTER_HZ = 2000.0  # Hz, -3 dB: this simulator's encoder velocity filter (a controller's own config decides)
PLL_3DB_PER_NATURAL = 2.48  # -3 dB bandwidth over natural frequency of moteus's critically damped PLL (moteus_tool)

#: How each register's value is written (moteus.protocol.Writer's scalings); the rest are plain integers.
_WRITE = {Register.POSITION: "write_position", Register.VELOCITY: "write_velocity", Register.TORQUE: "write_torque",
          Register.CONTROL_TORQUE: "write_torque", Register.Q_CURRENT: "write_current",
          Register.D_CURRENT: "write_current", Register.VOLTAGE: "write_voltage",
          Register.TEMPERATURE: "write_temperature", Register.MOTOR_TEMPERATURE: "write_temperature"}


class Loop(NamedTuple):
    """A position command's loop at the motor, SI: torque = kp*e + I + kd*(velocity - v) + feedforward within
    +-torque_limit, e = position - x, I = clip(I + ki*e*dt, +-ilimit) (Plant.run_position)."""
    kp: float            # N*m/rad
    ki: float            # N*m/(rad*s)
    ilimit: float        # N*m: the integral term's bound
    kd: float            # N*m*s/rad
    position: float      # rad (NaN: no proportional term)
    velocity: float      # rad/s
    feedforward: float   # N*m
    torque_limit: float  # N*m


class SimMoteus:
    """One simulated moteus controller at ``controller_id`` (1..126) on an open python-can bus.

    Args:
        sim: plant and injected effects; torque_constant: N*m/A of the q-axis current; counts_per_rev: the
            plant's encoder; current_limit: A (moteus's servo.max_current_A).
        kp, ki, kd, ilimit: the controller's configured position loop (servo.pid_position): N*m/rev,
            N*m/(rev*s), N*m*s/rev, and the integral term's bound N*m (scaled by a command's ilimit_scale).
        max_velocity: rev/s (servo.max_velocity); clock, rate, oversample: see the module doc.
        pll_filter_hz: -3 dB bandwidth of the encoder's velocity estimate, Hz (motor_position.sources.0.pll_filter_hz).
    """

    def __init__(self, bus: can.BusABC, controller_id: int, sim: SimConfig, clock: str = "real",
                 rate: float = 1000.0, oversample: int = 10, torque_constant: float = 0.2,
                 counts_per_rev: int = 1 << 20, current_limit: float = 20.0, kp: float = 4.0, kd: float = 0.1,
                 max_velocity: float = 50.0, default_timeout: float = DEFAULT_TIMEOUT,
                 pll_filter_hz: float = PLL_FILTER_HZ, ki: float = 0.0, ilimit: float = 0.0) -> None:
        if clock not in CLOCKS:
            raise ValueError(f"clock must be one of {CLOCKS}, got {clock!r}")
        self.bus, self.id, self.clock, self.period = bus, controller_id, clock, 1.0 / rate
        self.kt, self.kp, self.kd, self.max_velocity = torque_constant, kp, kd, max_velocity
        self.pll_hz = pll_filter_hz / PLL_3DB_PER_NATURAL
        self.ki, self.ilimit = ki, ilimit
        self.default_timeout = default_timeout
        self.current_limit = current_limit
        self.mode, self.fault = int(Mode.STOPPED), 0
        self.command: dict[int, float] = {}
        self.timeout = default_timeout
        self.torque_held = 0.0          # N*m, acting on the plant since the last frame (the last step's)
        self.loop_held: Loop | None = None  # the position loop in force since the last frame, or None (torque)
        self.loop_steps = 0             # plant steps since loop_held took effect (its setpoint's advance)
        self.last_rx = -math.inf        # monotonic time of the last command addressed to this controller
        self._arrival = math.nan        # bus time of the previous command frame
        self.commands = 0
        self.cpr = counts_per_rev
        params = sim.plant_for(current_limit, torque_constant, counts_per_rev)
        dt = self.period / oversample
        self.plant = Plant(params, dt, sim.substeps or substeps_for(params, dt))
        self.sample = (0.0, 0.0, 0.0)   # position rev, velocity rev/s, measured torque N*m (the last sample)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._notifier = can.Notifier(bus, [self._on_message])
        self._monitor = threading.Thread(target=self._watch, name="moteus-watchdog", daemon=True)
        self._monitor.start()

    # ------------------------------------------------------------------ the bus
    def _on_message(self, msg: can.Message) -> None:
        arb = msg.arbitration_id
        if msg.is_remote_frame or arb & 0x7F != self.id or (arb >> 8) & 0x7F == self.id:
            return  # not for this controller, or its own reply handed back by the bus
        source = (arb >> 8) & 0x7F
        try:
            parsed = parse_registers(bytes(msg.data))
        except Exception:  # a frame the protocol cannot parse is dropped, as the firmware does
            return
        with self._lock:
            now = time.monotonic()
            if parsed.command:
                self.last_rx = now  # every command addressed to the controller feeds its watchdog
                self._apply(parsed.command)
            fresh = bool(parsed.command) and self.mode == Mode.POSITION  # a command resets the setpoint
            loop = self._loop()  # the position loop in force from this frame, closed inside the controller
            torque = self._torque() if loop is None else self.torque_held
            if self.clock == "real" or parsed.query:  # "sync": a period per queried frame (a cycle's)
                torque = self._advance(msg.timestamp or now, torque, loop, fresh)
            elif loop is not None and fresh:
                self.loop_steps = -1  # no plant step at this frame: the setpoint starts at the next one
            self.loop_held = loop if self.mode in ENERGISED else None
            self.torque_held = torque if self.mode in ENERGISED else 0.0  # a fault just latched: torque off
            reply = self._reply(parsed.query) if arb & 0x8000 and parsed.query else b""
        if reply:
            out = (self.id << 8) | source
            self.bus.send(can.Message(arbitration_id=out, data=pad_fd(reply), is_extended_id=out > 0x7FF,
                                      is_fd=True, bitrate_switch=True))

    def _apply(self, command: dict[int, float]) -> None:
        mode = command.get(Register.MODE)
        if mode is not None:
            mode = int(mode)
            if mode == Mode.STOPPED:
                self.mode, self.fault, self.command = int(Mode.STOPPED), 0, {}
            elif mode in ENERGISED and self.mode not in (Mode.FAULT, Mode.TIMEOUT):
                self.mode = mode
                self.command = dict(command)
                given = command.get(Register.COMMAND_TIMEOUT)
                self.timeout = given if given is not None and math.isfinite(given) and given > 0 \
                    else self.default_timeout
        self.commands += 1

    def _loop(self) -> Loop | None:
        """The position loop of the command in force (SI, at the motor), or None where there is none to close:
        not in position mode, or kp = kd = 0 with no integral term (moteus's torque command: position NaN,
        kp_scale = kd_scale = 0), held as a torque."""
        if self.mode != Mode.POSITION:
            return None
        cmd = self.command
        rev = 2 * math.pi
        position = rev * cmd.get(Register.COMMAND_POSITION, math.nan)
        kp = self.kp * cmd.get(Register.COMMAND_KP_SCALE, 1.0) / rev
        kd = self.kd * cmd.get(Register.COMMAND_KD_SCALE, 1.0) / rev
        ilimit = self.ilimit * cmd.get(Register.COMMAND_ILIMIT_SCALE, 1.0)
        if kp == 0.0 and kd == 0.0 and (math.isnan(position) or self.ki == 0.0 or ilimit == 0.0):
            return None
        limit = cmd.get(Register.COMMAND_POSITION_MAX_TORQUE, math.inf)
        limit = min(limit if math.isfinite(limit) else math.inf, self.current_limit * self.kt)
        return Loop(kp, self.ki / rev, max(ilimit, 0.0), kd, position, rev * cmd.get(Register.COMMAND_VELOCITY, 0.0),
                    cmd.get(Register.COMMAND_FEEDFORWARD_TORQUE, 0.0), limit)

    def _torque(self) -> float:
        """The torque the controller applies from now on (N*m): the command in force, its position loop closed
        on the last sample."""
        if self.mode not in ENERGISED:
            return 0.0
        cmd = self.command
        if self.mode == Mode.CURRENT:
            torque = self.kt * cmd.get(Register.COMMAND_Q_CURRENT, 0.0)
        else:
            position, velocity, _ = self.sample
            target = cmd.get(Register.COMMAND_POSITION, math.nan)
            kp = self.kp * cmd.get(Register.COMMAND_KP_SCALE, 1.0)
            kd = self.kd * cmd.get(Register.COMMAND_KD_SCALE, 1.0)
            torque = cmd.get(Register.COMMAND_FEEDFORWARD_TORQUE, 0.0)
            torque += kd * (cmd.get(Register.COMMAND_VELOCITY, 0.0) - velocity)
            if math.isfinite(target):
                torque += kp * (target - position)
            limit = cmd.get(Register.COMMAND_POSITION_MAX_TORQUE, math.inf)
            if math.isfinite(limit):
                torque = max(-limit, min(limit, torque))
        limit = self.current_limit * self.kt
        return max(-limit, min(limit, torque))

    def _advance(self, arrival: float, torque: float, loop: Loop | None, fresh: bool) -> float:
        """Sample the plant at this frame: advance it from the previous frame with the held torque or position
        loop; the last plant step is this frame's ``torque`` (N*m) or ``loop`` (``fresh``: its setpoint starts
        here), the sample is measured before it acts. Returns the torque the last step applies (N*m)."""
        if self.clock == "sync":
            elapsed = self.period
        elif math.isfinite(self._arrival):
            elapsed = min(max(arrival - self._arrival, 0.0), COAST_LIMIT)
        else:
            elapsed = 0.0
        self._arrival = arrival
        steps = round(elapsed / self.plant.dt)
        if steps < 1:
            if fresh:
                self.loop_steps = -1  # within one plant step of the previous frame: the setpoint starts next step
            return torque  # the same sample
        if loop is None and self.loop_held is None:  # torque held, torque new: one C call (torque mode's path)
            out = hold_step(self.plant, self.torque_held / self.kt, torque / self.kt, steps)
        else:
            held = self._hold(steps - 1)
            age = 0 if fresh or self.loop_held is None else self.loop_steps + steps
            last = self._close(loop, np.array([age])) if loop is not None else self.plant.run([torque / self.kt])
            out = last if held is None else PlantOutput.concatenate([held, last])
            self.loop_steps = age
            if loop is not None:
                torque = out.current_cmd[-1] * self.kt  # the loop's torque at this sample
        self.sample = (out.counts[-1] / self.cpr, out.omega[-1] / (2 * math.pi), out.current_meas[-1] * self.kt)
        if self.mode in ENERGISED and abs(self.sample[1]) > self.max_velocity * OVER_SPEED_FACTOR:
            self.mode, self.fault = int(Mode.FAULT), FAULT_OUTSIDE_LIMIT  # latched; torque off from now
        return torque

    def _hold(self, steps: int) -> PlantOutput | None:
        """``steps`` plant steps (>= 0) of what was held since the previous frame: its torque or its loop."""
        if steps == 0:
            return None
        if self.loop_held is None:
            return self.plant.run(np.full(steps, self.torque_held / self.kt))
        return self._close(self.loop_held, self.loop_steps + np.arange(1, steps + 1))

    def _close(self, loop: Loop, age: np.ndarray) -> PlantOutput:
        """Plant steps with ``loop`` closed at each, its setpoint ``age`` steps after the command arrived."""
        target = loop.position + loop.velocity * self.plant.dt * age  # moteus's control position
        return self.plant.run_position(target, loop.kp, loop.kd, loop.velocity, loop.feedforward, loop.torque_limit,
                                       self.pll_hz, loop.ki, loop.ilimit)

    def _values(self) -> dict:
        """Every register a query may read, as the controller holds them now (one dict per reply)."""
        position, velocity, torque = self.sample
        values = {Register.MODE: self.mode, Register.POSITION: position, Register.VELOCITY: velocity,
                  Register.TORQUE: torque, Register.Q_CURRENT: torque / self.kt, Register.D_CURRENT: 0.0,
                  Register.CONTROL_TORQUE: self.torque_held, Register.FAULT: self.fault,
                  Register.VOLTAGE: 24.0, Register.TEMPERATURE: 30.0, Register.MOTOR_TEMPERATURE: 30.0,
                  Register.TRAJECTORY_COMPLETE: 0, Register.MODEL_NUMBER: MODEL,
                  Register.FIRMWARE_VERSION: FIRMWARE, Register.REGISTER_MAP_VERSION: REGISTER_MAP,
                  Register.SERIAL_NUMBER1: SERIAL[0], Register.SERIAL_NUMBER2: SERIAL[1],
                  Register.SERIAL_NUMBER3: SERIAL[2]}
        return values

    def _reply(self, query: list[tuple[int, int]]) -> bytes:
        """The reply subframes for ``query`` ((register, resolution) pairs), grouped as moteus groups them."""
        buf = io.BytesIO()
        writer = Writer(buf)
        values = self._values()
        known = [(r, res) for r, res in sorted(query) if values.get(r) is not None]
        for register, _ in sorted(query):
            if values.get(register) is None:
                writer.write_int8(mp.READ_ERROR)
                writer.write_varuint(register)
                writer.write_varuint(1)
        runs: list[list[tuple[int, int]]] = []
        for register, resolution in known:
            if runs and runs[-1][-1][0] + 1 == register:
                runs[-1].append((register, resolution))
            else:
                runs.append([(register, resolution)])
        for run in runs:
            combiner = mp.WriteCombiner(writer, mp.REPLY_BASE, run[0][0], [res for _, res in run])
            for register, resolution in run:
                if combiner.maybe_write():
                    value = values[register]
                    method = _WRITE.get(register)
                    if method is None:
                        writer.write_int(value, resolution)
                    else:
                        getattr(writer, method)(value, resolution)
        return buf.getvalue()

    # ------------------------------------------------------------------ the watchdog
    def _watch(self) -> None:
        stalls = StallGrace()
        while not self._stop.wait(0.002):
            now = time.monotonic()
            if not stalls.may_judge(now, self.timeout):
                continue
            with self._lock:
                if self.mode in ENERGISED and now - self.last_rx > self.timeout:
                    self.mode, self.torque_held, self.loop_held = int(Mode.TIMEOUT), 0.0, None  # power off

    def energised(self) -> bool:
        return self.mode in ENERGISED

    def close(self) -> None:
        self._stop.set()
        self._monitor.join(1.0)
        self._notifier.stop()


def serve(interface: str, channel: str, controller_id: int, sim: SimConfig, clock: str = "real",
          stop: threading.Event | None = None, port: int | None = None, **gains: float) -> int:
    """Run one simulated moteus controller on a python-can bus (CAN-FD) until ``stop``; prints its URL first.
    ``gains``: its servo.pid_position ``kp``, ``ki``, ``kd``, ``ilimit`` (:class:`SimMoteus`)."""

    def start(bus) -> tuple[str, object]:
        controller = SimMoteus(bus, controller_id, sim, clock=clock, **gains)
        return f"moteus://{interface}/{channel}?id={controller_id}", controller.close

    return drive_sim.serve(interface, channel, port, stop, start, fd=True)  # CAN-FD frames
