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
from collections.abc import Iterator

import numpy as np

from hilbench.common.runfile.schema import DRIVE_CLOCK, HOST_TIME, DeviceIdentity
from hilbench.drivers import odrive_can as o
from hilbench.drivers import protocol as p
from hilbench.drivers.amplifier import check_setpoints
from hilbench.drivers.can_buffer import enlarge_receive_buffer
from hilbench.drivers.can_frames import drop_malformed_frames
from hilbench.drivers.device import Capabilities, CycleSamples
from hilbench.drivers.errors import (
    CommandRefusedError,
    ConfigError,
    DeviceFaultError,
    DeviceTimeoutError,
    DriverError,
    PortBusyError,
    SampleLossError,
)
from hilbench.drivers.host_cycle import CanCycle, CanCycleSpec, Guard, HostClockedDevice, timing_summary

FEED_PERIOD = 0.02  # s between watchdog feeds while armed and not streaming
OWNER_LISTEN = 0.15  # s the host listens, sending nothing, for another host's commands to the axis


class OdriveDrive(HostClockedDevice):
    """One ODrive axis at ``node_id`` (0..63) on a python-can bus."""

    capabilities = Capabilities({"current": (1000,)})

    def __init__(self, interface: str, channel: str, node_id: int, tvl_endpoint: int, timeout: float = 2.0,
                 **bus_kwargs) -> None:
        import can

        self.name = f"odrive://{interface}/{channel}?node={node_id}"
        self.node_id, self.tvl_endpoint, self.timeout = node_id, tvl_endpoint, timeout
        self.interface, self.channel, self.bus_kwargs = interface, channel, dict(bus_kwargs)
        self.config: p.Config | None = None
        self.axis_error = 0
        self.axis_state = 0
        self._heartbeat = threading.Event()
        self._sdo: dict[int, int] = {}
        self._sdo_event = threading.Event()
        self._feed = None
        self._cycle: CanCycle | None = None
        self._last_cmd = 0.0  # A, the last current command sent
        self._progress = 0    # cycles sent in the current (or last) stream
        self._others: set[int] = set()  # host commands for this axis heard before this host sent any
        self._malformed_cycle = 0
        self._sent_any = False
        if not 0 <= tvl_endpoint <= 0xFFFF:
            raise ConfigError(f"{self.name}: tvl_endpoint must be 0..65535 (a CAN Simple endpoint id), "
                              f"got {tvl_endpoint}")
        try:
            self.bus = can.Bus(interface=interface, channel=channel, **bus_kwargs)
        except Exception as exc:
            raise DriverError(f"{self.name}: cannot open the CAN bus: {' '.join(str(exc).split())}") from exc
        enlarge_receive_buffer(self.bus)
        self.malformed = drop_malformed_frames(self.bus)  # a stray datagram is counted, never fatal
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
        if self.config is None:
            raise CommandRefusedError("configure() the drive before arming")
        if self.axis_error:
            raise DeviceFaultError(f"ODrive node {self.node_id}: {o.describe_errors(self.axis_error)}; "
                                   f"clear it with `hilbench fault clear --device URL` first")
        self._start_feed()
        self._send(o.Cmd.SET_AXIS_STATE, o.U32.pack(o.AxisState.CLOSED_LOOP_CONTROL))
        self._wait_heartbeat(lambda: self.axis_state == o.AxisState.CLOSED_LOOP_CONTROL, "closed loop control")

    def _start_feed(self) -> None:
        import can

        if self._feed is None:
            self._sent_any = True
            msg = can.Message(arbitration_id=o.can_id(self.node_id, o.Cmd.SET_INPUT_TORQUE), data=o.FLOAT.pack(0.0),
                              is_extended_id=False)
            self._feed = self.bus.send_periodic(msg, FEED_PERIOD)

    def _stop_feed(self) -> None:
        if self._feed is not None:
            self._feed.stop()
            self._feed = None

    def clear_faults(self) -> None:
        self._send(o.Cmd.CLEAR_ERRORS)
        self._wait_heartbeat(lambda: self.axis_error == 0, "no error")

    def disarm(self) -> None:
        if self._cycle is not None:
            self._cycle.stop()
        self._stop_feed()
        self._send(o.Cmd.SET_INPUT_TORQUE, o.FLOAT.pack(0.0))
        self._send(o.Cmd.SET_AXIS_STATE, o.U32.pack(o.AxisState.IDLE))

    def estop(self) -> None:
        cycle = self._cycle
        if cycle is not None:
            cycle.estop()
        self._send(o.Cmd.ESTOP)

    # ------------------------------------------------------------------ the cycle
    def stream(self, setpoints, allow_loss: bool = False) -> Iterator[CycleSamples]:
        """Send ``setpoints`` (A, as torque k_t*i) one per cycle; yield the drive's cyclic samples.

        Raises :class:`DeviceFaultError`, after yielding every sample received, when the heartbeat reports
        an axis error or the axis leaves closed loop control.
        """
        cfg = self.config
        if cfg is None:
            raise CommandRefusedError("configure() the drive before streaming")
        values = check_setpoints(setpoints, cfg)
        if self.axis_error or self.axis_state != o.AxisState.CLOSED_LOOP_CONTROL:
            raise CommandRefusedError(f"cannot stream: ODrive node {self.node_id} is not in closed loop control "
                                      f"({o.describe_errors(self.axis_error)}); arm it first")
        return self._stream(values)

    def _stream(self, values: np.ndarray) -> Iterator[CycleSamples]:
        cfg = self.config
        n, rate = len(values), cfg.sample_rate
        tx = np.zeros((n, 1, 8), np.uint8)
        tx[:, 0, :4] = (values * cfg.torque_constant).astype("<f4").view(np.uint8).reshape(n, 4)
        zero = o.FLOAT.pack(0.0)
        spec = CanCycleSpec(self.interface, self.channel, self.bus_kwargs, float(rate),
                            (o.can_id(self.node_id, o.Cmd.SET_INPUT_TORQUE),), (4,),
                            (o.can_id(self.node_id, o.Cmd.GET_ENCODER_ESTIMATES),
                             o.can_id(self.node_id, o.Cmd.GET_TORQUES)), (zero,), (zero,), guards=self._guards(cfg))
        cycle = CanCycle(spec, tx)
        self._cycle, self._timing, self._progress = cycle, None, 0
        a = cycle.arrays
        done, fault = 0, ""
        heard = time.monotonic()  # when the number of samples last grew (reset once the first command is out)
        try:
            started = time.monotonic()
            cycle.start()
            # The zero-torque feed keeps the axis's watchdog fed until the cycle's first command is out: starting
            # the cycle process takes longer than the watchdog timeout on a loaded host. A feed frame that lands
            # between the first commands makes the axis hold zero for one tick, which its torque target records.
            while not cycle.sent and cycle.alive() and not a["ctl"][1]:
                time.sleep(0.0005)
                cycle.check_started(started, f"ODrive node {self.node_id}")
            self._stop_feed()  # the cycle's commands feed the watchdog now
            heard = time.monotonic()
            while True:
                time.sleep(0.02)
                ended = not cycle.alive() or bool(a["ctl"][1])
                if self.axis_error or self.axis_state != o.AxisState.CLOSED_LOOP_CONTROL:
                    fault = f"{o.describe_errors(self.axis_error)} (axis state {self.axis_state})"
                    cycle.stop()
                    ended = True
                if ended:
                    cycle.join()
                self._progress = cycle.sent
                if (cycle.sent >= n or cycle.limit is not None) and not fault and not self._closed:
                    # the cycle's last command is out: zero torque keeps the watchdog fed while it collects the tail
                    self._start_feed()
                ready = min(cycle.received(0), cycle.received(1))
                if cycle.limit is not None:  # the sample that tripped a limit is the last one
                    ready = min(ready, cycle.limit[1] + 1)
                if ready > done:
                    yield self._block(done, ready, a)
                    done, heard = ready, time.monotonic()
                elif not ended and cycle.sent and time.monotonic() - heard > self.timeout:
                    cycle.stop()  # the axis went silent: its heartbeat and cyclic messages stopped
                    cycle.join()
                    raise DeviceTimeoutError(f"ODrive node {self.node_id} stopped sending its cyclic messages at "
                                             f"sample {done} of {n} (none for {self.timeout:g} s)")
                if ended:
                    break
            if cycle.error:
                raise DriverError(f"{self.name}: the cycle process could not open the CAN bus")
            if cycle.limit is not None:
                guard, row = cycle.limit
                raise DeviceFaultError(self._limit_line(guard, row, a), int(p.Fault[guard.name]))
            if fault:
                raise DeviceFaultError(f"ODrive node {self.node_id} stopped at sample {done}: {fault}")
            if done < n:  # a run that ends short is never complete
                raise SampleLossError(f"ODrive node {self.node_id}: {done} of {n} samples arrived (its cyclic "
                                      f"messages stopped or were lost after {cycle.sent} commands)")
        finally:
            cycle.stop()
            cycle.join()
            if cycle.sent:
                self._timing = timing_summary(a[HOST_TIME][:cycle.sent], a["scheduled"][:cycle.sent], rate)
            self._cycle = None
            self._malformed_cycle += cycle.malformed
            cycle.close()
            if not self._closed and not fault:
                self._start_feed()

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

    def _guards(self, cfg: p.Config) -> tuple[Guard, ...]:
        """The host's check of the position window and the velocity limit on every Get_Encoder_Estimates
        (turns and turns/s at the motor shaft, as the hilbench device checks them)."""
        turn = 2 * math.pi
        out = []
        if math.isfinite(cfg.position_min) or math.isfinite(cfg.position_max):
            out.append(Guard("POSITION_WINDOW", 0, 0, "<f", cfg.position_min / turn, cfg.position_max / turn))
        out.append(Guard("OVER_SPEED", 0, 4, "<f", -cfg.velocity_limit / turn, cfg.velocity_limit / turn))
        return tuple(out)

    def _limit_line(self, guard: Guard, row: int, a: dict) -> str:
        turns = float(a["rx"][0, row, guard.offset:guard.offset + 4].view("<f4")[0])
        rad, cfg = turns * 2 * math.pi, self.config
        if guard.name == "POSITION_WINDOW":
            what = (f"position {rad:.6g} rad outside the window [{cfg.position_min:.6g}, {cfg.position_max:.6g}] "
                    f"rad")
        else:
            what = f"speed {abs(rad):.6g} rad/s above the velocity limit {cfg.velocity_limit:.6g} rad/s"
        return (f"stream stopped by the host at sample {row}: {guard.name} ({what}, at the motor shaft); "
                f"zero torque sent")

    def run_events(self) -> list[tuple[str, str]]:
        out = super().run_events()
        dropped = self.malformed.count + self._malformed_cycle
        if dropped:
            out.append(("info", f"{dropped} malformed frame(s) on the bus were counted and dropped"))
        return out

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
