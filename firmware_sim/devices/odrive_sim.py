"""A simulated ODrive axis on its CAN Simple protocol, with the C plant behind it.

It runs its own control tick at ``rate`` (1 kHz, as ``encoder_msg_rate_ms = torques_msg_rate_ms = 1``):
each tick samples the plant and sends Get_Encoder_Estimates (turns, turns/s) and Get_Torques (target,
estimate in N*m) as cyclic messages, then applies the latest Set_Input_Torque in closed loop control (zero
otherwise), held until the next tick. The plant runs at ``oversample`` times the tick rate and advances one
tick per tick: an ODrive's control loop and its cyclic messages run on a hardware timer, so the samples are
uniform in the drive's time whatever this process's scheduling does to when the frames go out.
Heartbeat every 100 ms (axis error, axis state). Watchdog: in closed loop control, no
host command for the axis within ``watchdog_timeout`` latches WATCHDOG_TIMER_EXPIRED and drops to idle; so
does Estop (ESTOP_REQUESTED). Only host commands feed it: a bus that hands a sender its own frames back
(udp_multicast always) also delivers the axis's heartbeat and cyclic messages to the axis, and those never
count as the host. Over-speed, as ODrive's ``enable_overspeed_error``: in closed loop, a speed above
``vel_limit`` x ``VEL_LIMIT_TOLERANCE`` latches CONTROLLER_FAILED and drops to idle.
Errors latch until Clear_Errors. RxSdo serves one endpoint:
``enable_torque_mode_vel_limit`` (id ``TVL_ENDPOINT``); with it true the simulated controller does what
ODrive's does, scaling the torque down to zero over the last 10 % below ``vel_limit``.
"""

from __future__ import annotations

import math
import threading
import time

import can

from hilbench.drivers import odrive_can as o
from hilbench.drivers.protocol import ProtocolError
from hilbench.firmware_sim.devices import drive_sim
from hilbench.firmware_sim.devices.drive_sim import hold_step
from hilbench.firmware_sim.devices.sim_config import SimConfig, substeps_for
from hilbench.firmware_sim.devices.stall_grace import StallGrace
from hilbench.firmware_sim.engine.plant import Plant

TVL_ENDPOINT = 394
HEARTBEAT_PERIOD = 0.1
VEL_LIMIT_TOLERANCE = 1.2  # ODrive's controller.config.vel_limit_tolerance default
CONTROLLER_FAILED = 0x00000200


class SimOdrive:
    def __init__(self, bus: can.BusABC, node_id: int, sim: SimConfig, rate: float = 1000.0, oversample: int = 10,
                 torque_constant: float = 0.2, counts_per_rev: int = 1 << 20, watchdog_timeout: float = 0.2) -> None:
        self.bus, self.node, self.sim, self.rate = bus, node_id, sim, float(rate)
        self.kt, self.cpr, self.watchdog_timeout = torque_constant, counts_per_rev, watchdog_timeout
        self.state = o.AxisState.IDLE
        self.error = 0
        self.input_torque = 0.0
        self.vel_limit = math.inf    # turns/s
        self.current_limit = 10.0    # A
        self.tvl = True              # ODrive's default: enable_torque_mode_vel_limit on
        self.last_rx = -math.inf
        self.ticks = 0
        dt = 1.0 / (self.rate * oversample)
        self._params = sim.plant_for(self.current_limit, torque_constant, counts_per_rev)
        self.plant = Plant(self._params, dt, sim.substeps or substeps_for(self._params, dt))
        self._lock = threading.Lock()
        self.malformed_commands = 0
        self._stop = threading.Event()
        self._notifier = can.Notifier(bus, [self._on_message])
        self._thread = threading.Thread(target=self._run, name="odrive-sim", daemon=True)
        self._thread.start()

    def _send(self, cmd: o.Cmd, data: bytes) -> None:
        self.bus.send(can.Message(arbitration_id=o.can_id(self.node, cmd), data=data, is_extended_id=False))

    def _on_message(self, msg) -> None:
        try:
            self._take(msg)
        except ProtocolError:  # a command too short for its fields: counted and dropped, the axis keeps listening
            self.malformed_commands += 1

    def _take(self, msg) -> None:
        node, cmd = o.split_id(msg.arbitration_id)
        if node != self.node or msg.is_remote_frame:
            return
        if cmd not in o.HOST_COMMANDS:  # the axis's own frames, handed back by the bus: never the host
            return
        with self._lock:
            self.last_rx = time.monotonic()  # every host command for the axis feeds the watchdog
            data = bytes(msg.data)
            if cmd == o.Cmd.SET_INPUT_TORQUE:
                self.input_torque = o.unpack(o.FLOAT, data, "SET_INPUT_TORQUE")[0]
            elif cmd == o.Cmd.SET_AXIS_STATE:
                want = o.unpack(o.U32, data, "SET_AXIS_STATE")[0]
                if want == o.AxisState.CLOSED_LOOP_CONTROL and not self.error:
                    self.state = o.AxisState.CLOSED_LOOP_CONTROL
                elif want == o.AxisState.IDLE:
                    self.state = o.AxisState.IDLE
            elif cmd == o.Cmd.SET_LIMITS:
                self.vel_limit, current_limit = o.unpack(o.FLOAT2, data, "SET_LIMITS")
                if current_limit != self.current_limit:
                    self.current_limit = current_limit
                    state = self.plant.get_state()
                    self._params = self.sim.plant_for(current_limit, self.kt, self.cpr)
                    self.plant = Plant(self._params, self.plant.dt, self.plant.substeps)
                    self.plant.set_state(state)
            elif cmd == o.Cmd.ESTOP:
                self._trip(o.ESTOP_REQUESTED)
            elif cmd == o.Cmd.CLEAR_ERRORS:
                self.error = 0
            elif cmd == o.Cmd.RX_SDO and len(data) == 8:
                opcode, endpoint, _, value = o.SDO.unpack(data)
                if endpoint == TVL_ENDPOINT:
                    if opcode == 1:
                        self.tvl = bool(value & 0xFF)
                    self._send(o.Cmd.TX_SDO, o.SDO.pack(0, endpoint, 0, int(self.tvl)))

    def _trip(self, error: int) -> None:
        self.error |= error
        self.state = o.AxisState.IDLE

    def _torque(self, omega: float) -> float:
        torque = self.input_torque
        if self.tvl and math.isfinite(self.vel_limit):  # ODrive's torque-mode velocity limiter
            v, limit = abs(omega) / (2 * math.pi), self.vel_limit
            if v >= limit or (v > 0.9 * limit and torque * omega > 0):
                torque *= max(0.0, (limit - v) / (0.1 * limit))
        return torque

    def _run(self) -> None:
        period = 1.0 / self.rate
        t0 = time.monotonic()
        next_heartbeat = t0
        u_held = 0.0
        stalls = StallGrace()
        while not self._stop.is_set():
            self.ticks += 1
            due = t0 + self.ticks * period
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            now = time.monotonic()
            judge = stalls.may_judge(now, self.watchdog_timeout)  # not right after this process's own stall
            with self._lock:
                if (judge and self.state == o.AxisState.CLOSED_LOOP_CONTROL
                        and now - self.last_rx > self.watchdog_timeout):
                    self._trip(o.WATCHDOG_TIMER_EXPIRED)
                closed = self.state == o.AxisState.CLOSED_LOOP_CONTROL
                u_new = self._torque(self.plant.omega) / self.kt if closed else 0.0
                out = hold_step(self.plant, u_held, u_new, round(period / self.plant.dt))  # last row: now
                u_held = u_new
                position, velocity = out.counts[-1] / self.cpr, out.omega[-1] / (2 * math.pi)
                if closed and abs(velocity) > self.vel_limit * VEL_LIMIT_TOLERANCE:
                    self._trip(CONTROLLER_FAILED)
                state, error = self.state, self.error
            self._send(o.Cmd.GET_ENCODER_ESTIMATES, o.FLOAT2.pack(position, velocity))
            self._send(o.Cmd.GET_TORQUES, o.FLOAT2.pack(u_new * self.kt, out.current_meas[-1] * self.kt))
            if now >= next_heartbeat:
                self._send(o.Cmd.HEARTBEAT, o.HEARTBEAT.pack(error, state, 0, 0))
                next_heartbeat = now + HEARTBEAT_PERIOD

    def close(self) -> None:
        self._stop.set()
        self._thread.join(1.0)
        self._notifier.stop()


def serve(interface: str, channel: str, node_id: int, sim: SimConfig, stop: threading.Event,
          port: int | None = None) -> int:
    """Run a simulated ODrive until ``stop``; prints the device URL first."""

    def start(bus) -> tuple[str, object]:
        drive = SimOdrive(bus, node_id, sim)
        return f"odrive://{interface}/{channel}?node={node_id}&tvl_endpoint={TVL_ENDPOINT}", drive.close

    return drive_sim.serve(interface, channel, port, stop, start)
