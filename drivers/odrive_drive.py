"""An ODrive axis over its CAN Simple protocol, in torque control.

    with OdriveDrive("socketcan", "can0", node_id=0, tvl_endpoint=394) as drive:
        drive.configure(Config(sample_rate=1000, current_limit=20.0, torque_constant=0.2))
        drive.arm()
        for block in drive.stream(setpoints_in_amperes):
            use(block.time, block.position, block.torque, block.host_time)

The host sends Set_Input_Torque once per cycle (host-clocked commands). The ODrive sends
Get_Encoder_Estimates and Get_Torques as cyclic messages on its own timer (``encoder_msg_rate_ms`` and
``torques_msg_rate_ms`` = 1 ms), so the samples are the drive's: sample k is its k-th cyclic pair after the
stream's first command, ``t = k / rate``, with the host time it arrived. The torque channels are the drive's
own torque target and estimate of that tick, not the host's command.

Set-up: torque control with passthrough input (Set_Controller_Mode), limits (Set_Limits), and
``controller.config.enable_torque_mode_vel_limit`` written to false with CAN Simple's RxSdo (endpoint id
``tvl_endpoint`` from the firmware's flat_endpoints.json) and read back. With it on, ODrive scales the
commanded torque down near ``vel_limit``, so the motor would not get the torque the run file records.
Arming feeds ODrive's watchdog with zero-torque commands until the stream's own commands take over; errors
come from the heartbeat and latch until Clear_Errors.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np

from hilbench.common.runfile.schema import DRIVE_CLOCK, DeviceIdentity
from hilbench.drivers import odrive_can as o
from hilbench.drivers import protocol as p
from hilbench.drivers.device import Capabilities, CycleSamples
from hilbench.drivers.errors import (
    CommandRefusedError,
    ConfigError,
    DeviceFaultError,
    DeviceTimeoutError,
    PortBusyError,
    SampleLossError,
)
from hilbench.drivers.host_clocked import GuardFrame, HostClockedDevice
from hilbench.drivers.host_cycle import CanCycle, CanCycleSpec

OWNER_LISTEN = 0.15  # s the host listens, sending nothing, for another host's commands to the axis


class OdriveDrive(HostClockedDevice):
    """One ODrive axis at ``node_id`` (0..63) on a python-can bus."""

    capabilities = Capabilities({"current": (1000,)})
    feeds_watchdog = True

    def __init__(self, interface: str, channel: str, node_id: int, tvl_endpoint: int, timeout: float = 2.0,
                 **bus_kwargs) -> None:
        import can

        self.name = f"odrive://{interface}/{channel}?node={node_id}"
        self.node_id, self.tvl_endpoint, self.timeout = node_id, tvl_endpoint, timeout
        self.label = f"ODrive node {node_id}"
        self.interface, self.channel, self.bus_kwargs = interface, channel, dict(bus_kwargs)
        self.config: p.Config | None = None
        self.axis_error = 0
        self.axis_state = 0
        self._heartbeat = threading.Event()
        self._sdo: dict[int, int] = {}
        self._sdo_event = threading.Event()
        self._last_cmd = 0.0  # A, the last current command sent
        self._others: set[int] = set()  # host commands for this axis heard before this host sent any
        self._sent_any = False
        if not 0 <= tvl_endpoint <= 0xFFFF:
            raise ConfigError(f"{self.name}: tvl_endpoint must be 0..65535 (a CAN Simple endpoint id), "
                              f"got {tvl_endpoint}")
        self.bus = self._open_bus(interface, channel, **bus_kwargs)
        started = time.monotonic()
        self.notifier = can.Notifier(self.bus, [self._on_message])
        if not self._heartbeat.wait(timeout):
            self.close()
            raise DeviceTimeoutError(f"ODrive node {node_id} did not answer: no heartbeat (CAN id "
                                     f"0x{o.can_id(node_id, o.Cmd.HEARTBEAT):03X}) within {timeout:g} s")
        time.sleep(max(0.0, started + OWNER_LISTEN - time.monotonic()))
        if self.axis_state == o.AxisState.CLOSED_LOOP_CONTROL or self._others:
            heard = ", ".join(sorted(o.Cmd(cmd).name for cmd in self._others))
            why = "the axis is in closed loop control" + (f" and another host sends it {heard}" if heard else "")
            self.close()
            raise PortBusyError(f"{self.name} is in use by another host ({why}); nothing was sent to it: stop "
                                f"that host's run first")

    # ------------------------------------------------------------------ bus
    def _on_message(self, msg) -> None:
        node, cmd = o.split_id(msg.arbitration_id)
        if node != self.node_id or msg.is_remote_frame:
            return
        if cmd in o.HOST_COMMANDS and not self._sent_any:  # not ours: this host has sent nothing yet
            self._others.add(cmd)
        if cmd == o.Cmd.HEARTBEAT and len(msg.data) >= 5:
            self.axis_error, self.axis_state = o.HEARTBEAT.unpack(bytes(msg.data).ljust(8, b"\0"))[:2]
            self._heartbeat.set()
        elif cmd == o.Cmd.TX_SDO and len(msg.data) == 8:
            _, endpoint, _, value = o.SDO.unpack(msg.data)
            self._sdo[endpoint] = value
            self._sdo_event.set()

    def _send(self, cmd: o.Cmd, data: bytes = b"") -> None:
        import can

        self._sent_any = True
        self.bus.send(can.Message(arbitration_id=o.can_id(self.node_id, cmd), data=data, is_extended_id=False))

    def _wait_heartbeat(self, ok, what: str) -> None:
        deadline = time.monotonic() + self.timeout
        while time.monotonic() < deadline:
            self._heartbeat.clear()
            self._heartbeat.wait(0.2)
            if ok():
                return
        raise DeviceTimeoutError(f"ODrive node {self.node_id}: {what} not reported by its heartbeat within "
                                 f"{self.timeout:g} s (axis state {self.axis_state}, errors: "
                                 f"{o.describe_errors(self.axis_error)})")

    def info(self) -> DeviceIdentity:
        # the ODrive samples on its own timer: host_time is when a sample arrived, t = k/rate is its time
        return DeviceIdentity(protocol="ODrive CAN Simple", url=self.name, sample_times=DRIVE_CLOCK,
                              details={"node": self.node_id, "axis_state": self.axis_state,
                                       "axis_error": f"0x{self.axis_error:08X}"})

    def state(self) -> str:
        names = {int(s): s.name.lower().replace("_", " ") for s in o.AxisState}
        return f"{names.get(self.axis_state, 'unknown')} (axis state {self.axis_state})"

    def faults(self) -> list[str]:
        return [self.fault_line()] if self.axis_error else []

    def status(self) -> int:
        return self.axis_state

    def live_state(self) -> dict:
        names = {int(s): s.name.lower().replace("_", " ") for s in o.AxisState}
        return {"state": f"axis state {self.axis_state} ({names.get(self.axis_state, '?')})",
                "armed": self.axis_state == o.AxisState.CLOSED_LOOP_CONTROL, "streaming": self._cycle is not None,
                "faults": [self.fault_line()] if self.axis_error else [], "cycle": self._progress,
                "current_cmd": self._last_cmd if self._cycle is not None else 0.0,
                "counters": self.timing_counters()}

    # ------------------------------------------------------------------ Device API
    def configure(self, config: p.Config) -> None:
        self._check_config(config)
        self._send(o.Cmd.SET_CONTROLLER_MODE, o.U32x2.pack(o.CONTROL_MODE_TORQUE, o.INPUT_MODE_PASSTHROUGH))
        self._send(o.Cmd.SET_LIMITS, o.FLOAT2.pack(config.velocity_limit / (2 * math.pi), config.current_limit))
        # enable_torque_mode_vel_limit off, then read back (it reshapes the commanded torque near vel_limit)
        self._sdo.pop(self.tvl_endpoint, None)
        self._send(o.Cmd.RX_SDO, o.SDO.pack(1, self.tvl_endpoint, 0, 0))
        self._sdo_event.clear()
        self._send(o.Cmd.RX_SDO, o.SDO.pack(0, self.tvl_endpoint, 0, 0))
        if not self._sdo_event.wait(self.timeout) or self._sdo.get(self.tvl_endpoint) != 0:
            raise CommandRefusedError(f"ODrive node {self.node_id}: enable_torque_mode_vel_limit (endpoint "
                                      f"{self.tvl_endpoint}) did not read back as false")
        self.config = config

    def arm(self) -> None:
        self._configured("arming")
        if self.axis_error:
            raise DeviceFaultError(f"ODrive node {self.node_id}: {o.describe_errors(self.axis_error)}; "
                                   f"clear it with `hilbench fault clear --device URL` first")
        self._start_feed()
        self._send(o.Cmd.SET_AXIS_STATE, o.U32.pack(o.AxisState.CLOSED_LOOP_CONTROL))
        self._wait_heartbeat(lambda: self.axis_state == o.AxisState.CLOSED_LOOP_CONTROL, "closed loop control")

    def _feed_message(self):
        import can

        self._sent_any = True
        return can.Message(arbitration_id=o.can_id(self.node_id, o.Cmd.SET_INPUT_TORQUE), data=o.FLOAT.pack(0.0),
                           is_extended_id=False)

    def clear_faults(self) -> None:
        self._send(o.Cmd.CLEAR_ERRORS)
        self._wait_heartbeat(lambda: self.axis_error == 0, "no error")

    def disarm(self) -> None:
        self._stop_cycle()  # joined: no keepalive frame of the cycle follows the stop sent below
        self._stop_feed()
        self._send(o.Cmd.SET_INPUT_TORQUE, o.FLOAT.pack(0.0))
        self._send(o.Cmd.SET_AXIS_STATE, o.U32.pack(o.AxisState.IDLE))

    def estop(self) -> None:
        cycle = self._cycle
        if cycle is not None:
            cycle.estop()
        self._send(o.Cmd.ESTOP)

    # ------------------------------------------------------------------ the stream loop's hooks
    def _check_ready(self) -> None:
        if self.axis_error or self.axis_state != o.AxisState.CLOSED_LOOP_CONTROL:
            raise CommandRefusedError(f"cannot stream: ODrive node {self.node_id} is not in closed loop control "
                                      f"({o.describe_errors(self.axis_error)}); arm it first")

    def _cycle_spec(self, values: np.ndarray) -> tuple[CanCycleSpec, np.ndarray]:
        """Per cycle: Set_Input_Torque (k_t * i, N*m); collected: the axis's cyclic estimates and torques."""
        cfg = self.config
        n = len(values)
        tx = np.zeros((n, 1, 8), np.uint8)
        tx[:, 0, :4] = (values * cfg.torque_constant).astype("<f4").view(np.uint8).reshape(n, 4)
        zero = o.FLOAT.pack(0.0)
        spec = CanCycleSpec(self.interface, self.channel, self.bus_kwargs, float(cfg.sample_rate),
                            (o.can_id(self.node_id, o.Cmd.SET_INPUT_TORQUE),), (4,),
                            (o.can_id(self.node_id, o.Cmd.GET_ENCODER_ESTIMATES),
                             o.can_id(self.node_id, o.Cmd.GET_TORQUES)), (zero,), (zero,), guards=self._guards(cfg),
                            rx_len=(o.FLOAT2.size, o.FLOAT2.size))
        return spec, tx

    def _poll(self, cycle: CanCycle, n: int) -> str:
        if self.axis_error or self.axis_state != o.AxisState.CLOSED_LOOP_CONTROL:
            return f"{o.describe_errors(self.axis_error)} (axis state {self.axis_state})"
        return ""

    def _rows(self, done: int, ready: int, arrays: dict) -> tuple[CycleSamples | None, int, bool]:
        return self._block(done, ready, arrays), ready, False

    def _silence_line(self, done: int, n: int) -> str:
        return (f"ODrive node {self.node_id} stopped sending its cyclic messages at sample {done} of {n} "
                f"(none for {self.timeout:g} s)")

    def _end_stream(self, cycle: CanCycle, done: int, n: int, allow_loss: bool) -> None:
        if done < n:  # a run that ends short is never complete
            raise SampleLossError(f"ODrive node {self.node_id}: {done} of {n} samples arrived (its cyclic "
                                  f"messages stopped or were lost after {cycle.sent} commands)")

    def _block(self, i: int, j: int, a: dict) -> CycleSamples:
        cal_ratio, cfg = self.config.ratio, self.config
        est = a["rx"][0, i:j].copy().view("<f4").reshape(j - i, 2).astype(np.float64)
        torques = a["rx"][1, i:j].copy().view("<f4").reshape(j - i, 2).astype(np.float64) * cal_ratio
        turns = est[:, 0]
        self._last_cmd = float(torques[-1, 0] / (cfg.torque_constant * cal_ratio))
        counts = np.rint(turns * cfg.counts_per_rev).astype(np.int64)
        return CycleSamples(np.arange(i, j, dtype=np.int64), a["rx_time"][0, i:j].copy(), counts,
                            torques[:, 0] / (cfg.torque_constant * cal_ratio),
                            torques[:, 1] / (cfg.torque_constant * cal_ratio), torques[:, 0], torques[:, 1],
                            2 * math.pi * turns / cal_ratio, 2 * math.pi * est[:, 1] / cal_ratio, cfg.sample_rate,
                            np.full(j - i, self.axis_state, np.uint16))

    def _guard_frame(self) -> GuardFrame:
        """Get_Encoder_Estimates: position (turns) and velocity (turns/s), float32, at the motor shaft."""
        turn = 2 * math.pi
        return GuardFrame(0, "<f", 0, 4, 1 / turn, 1 / turn)

    def fault_line(self) -> str:
        if not self.axis_error:
            return ""
        return f"ODrive axis error 0x{self.axis_error:08X}: {o.describe_errors(self.axis_error)}"

    def _release(self) -> None:
        self._stop_feed()
        if getattr(self, "notifier", None) is not None:
            self.notifier.stop()
        if getattr(self, "bus", None) is not None:
            self.bus.shutdown()
