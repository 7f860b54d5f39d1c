"""A simulated CiA 402 servo drive: a ``canopen`` LocalNode with the C plant behind it.

What it implements, as a real drive on the bus would:

- NMT slave with boot-up and producer heartbeat (0x1017); a heartbeat consumer for the host (0x1016);
- SDO server on its object dictionary (the EDS ``hb_cia402.eds`` next to this module, or another);
- the CiA 402 power state machine driven by the controlword 0x6040 (by SDO or RPDO), reported in 0x6041;
- Cyclic Synchronous Torque (mode 10, 0x6060/0x6061), announced in 0x6502; other modes are refused by
  staying in mode display 0;
- synchronous RPDOs (applied at the next SYNC) and SYNC-triggered TPDOs, which it sends itself, since
  LocalNode does not transmit TPDOs on SYNC;
- EMCY with the error register 0x1001 and error code 0x603F; faults latch until a fault reset;
- loss of the host (no heartbeat within 0x1016, or no SYNC for ``sync_timeout`` s once SYNCs have started
  while operation is enabled, ``sync_timeout``, default 0.1 s) triggers the reaction 0x6007 selects.

Two behaviours CiA 301/402 allow and real drives show, selectable: ``order="apply-then-sample"`` (default)
applies the controlword received before a SYNC and then reports the state in that SYNC's TPDO;
``"sample-then-apply"`` reports the state from before it. ``enable_latency`` (0..3 SYNCs) delays "operation
enabled" after an enable operation received by RPDO, as a drive that closes its current loop first.

As a CST drive does, it applies the target torque 0x6071 as soon as operation is enabled, and 0x6071 holds the
last value written, by SDO or by an RPDO (at the SYNC that applies it). ``stale_torque`` (per mille)
starts it with the value a killed run left there; ``spin`` (rad/s) starts the axis moving (a machine still
coasting when the host arrives). Both are for the host's check of the run's first samples.

What its object dictionary says, it does: SYNC on the COB-ID of 0x1005, EMCY on that of 0x1014; position 0x6064
and velocity 0x606C in the units of the factor objects where the EDS has them (0x6093 position factor, else 0x6091
gear ratio with 0x6092 feed constant; 0x6094 velocity encoder factor), else in increments of 0x608F.
``loss_in_any_state``: the loss reaction 0x6007 applies in every state, not only in operation enabled, as some
drives do (a host that leaves its heartbeat consumer armed on close then faults the drive).

The plant: at each SYNC the drive samples the plant (position 0x6064, velocity 0x606C, torque 0x6077) and then
applies the target torque received before that SYNC, held until the next SYNC. Internally the plant runs at
``oversample`` times the SYNC rate. With ``clock="sync"`` each SYNC advances the plant by exactly one
communication cycle (an ideal drive, deterministic, for tests); with ``clock="real"`` it advances by the
time that really passed since the previous SYNC, so a late SYNC holds the torque longer, as on a real drive;
there the axis also coasts, torque off, while operation is disabled (a fault, a killed host, between streams),
simulated when operation is enabled again (at most ``COAST_LIMIT`` s).
"""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path

import canopen
import numpy as np

from hilbench.drivers import cia402 as c
from hilbench.firmware_sim.devices import drive_sim
from hilbench.firmware_sim.devices.drive_sim import hold_step
from hilbench.firmware_sim.devices.sim_config import SimConfig, substeps_for
from hilbench.firmware_sim.devices.stall_grace import StallGrace
from hilbench.firmware_sim.engine.plant import Plant

EDS_PATH = Path(__file__).with_name("hb_cia402.eds")
SYNC_TIMEOUT = 0.1  # s without SYNC (while operation is enabled) that count as a lost host
EMCY_HEARTBEAT = 0x8130
EMCY_SYNC_LOST = 0x8250  # the synchronous RPDOs stop with the SYNC
EMCY_POSITION_LIMIT = 0x8612  # software position limit 0x607D passed
EMCY_OVER_SPEED = 0x8400      # max motor speed 0x6080 passed
COAST_LIMIT = 10.0            # s of coasting simulated at most between operation disabled and enabled again
HISTORY_LENGTH = 8            # entries of the error history 0x1003 (the EDS's sub-indices)
CLOCKS = ("sync", "real")
ORDERS = ("apply-then-sample", "sample-then-apply")


class SimCia402Drive:
    """One simulated drive on a :class:`canopen.Network`.

    Args:
        network: a connected network (python-can ``virtual``, ``udp_multicast`` or SocketCAN).
        node_id: 1..127.
        sim: plant and injected effects (firmware_sim.devices.sim_config).
        eds: the object dictionary; ``supported_modes`` overrides 0x6502 (e.g. a drive without CST).
        clock: ``"sync"`` or ``"real"`` (see the module doc); ``oversample``: plant steps per cycle.
        sync_timeout: s without SYNC, once started, before the drive reacts as 0x6007 says.
        order: whether a SYNC's TPDO reports the state after (``apply-then-sample``) or before
            (``sample-then-apply``) the controlword received with that SYNC.
        enable_latency: SYNCs between an enable operation received by RPDO and "operation enabled" (0..3).
        stale_torque: per mille in 0x6071 at start (what a killed run left); spin: the axis' speed at start, rad/s.
    """

    def __init__(self, network: canopen.Network, node_id: int, sim: SimConfig, eds: str | Path = EDS_PATH,
                 clock: str = "real", oversample: int = 10, supported_modes: int | None = None,
                 sync_timeout: float = SYNC_TIMEOUT, order: str = "apply-then-sample", enable_latency: int = 0,
                 stale_torque: int = 0, spin: float = 0.0, loss_in_any_state: bool = False) -> None:
        if clock not in CLOCKS:
            raise ValueError(f"clock must be one of {CLOCKS}, got {clock!r}")
        if order not in ORDERS:
            raise ValueError(f"order must be one of {ORDERS}, got {order!r}")
        if not 0 <= enable_latency <= 3:
            raise ValueError(f"enable_latency must be 0..3 SYNCs, got {enable_latency}")
        self.order, self.enable_latency = order, int(enable_latency)
        self._enable_in = 0          # SYNCs until a pending enable takes effect
        self._reported: int | None = None  # the statusword this SYNC's TPDO reports (sample-then-apply)
        self.network = network
        self.sim = sim
        self.clock = clock
        self.oversample = int(oversample)
        self.sync_timeout = float(sync_timeout)
        self.node = canopen.LocalNode(node_id, str(eds))
        if supported_modes is not None:
            self.node.data_store.setdefault(c.SUPPORTED_MODES, {})[0] = int(supported_modes).to_bytes(4, "little")
        self._state = c.State.SWITCH_ON_DISABLED
        self._idle_since = math.inf  # when operation was last disabled (monotonic s): the axis coasts since
        self.mode_display = 0
        self.error_code = 0
        self.error_register = 0
        self.plant: Plant | None = None
        self._plant_key: tuple | None = None
        self.cycle = 0              # SYNCs processed while operational
        self.u_held = 0.0           # current command held since the previous SYNC, A
        self.target_pm = int(stale_torque)  # target torque 0x6071, per mille: the last value written
        self.spin = float(spin)
        self.loss_in_any_state = bool(loss_in_any_state)
        self.meas = (0, 0, 0, 0)    # position inc, velocity inc/s, torque per mille, current per mille
        self.last_sync = math.inf
        self._arrival = math.inf    # bus timestamp of the previous SYNC, s
        self._lag = 0.0             # real time not yet simulated (rounding to plant steps), s
        self.last_host_heartbeat = math.inf
        self._host_hb: tuple[int, float] | None = None  # (node, timeout s)
        self._lock = threading.RLock()
        self._settings: tuple[float, float, float, int] | None = None  # period s, limit A, kt N*m/A, counts/rev
        self._rpdos: list = []
        self._tpdos: list = []
        self._stop = threading.Event()
        self.emcy_sent: list[int] = []
        self.history: list[int] = []  # error history 0x1003, newest first
        self.node.add_write_callback(self._on_write)
        self.node.add_read_callback(self._on_read)
        network.add_node(self.node)
        od = self.node.object_dictionary
        self.sync_id = self._raw(c.SYNC_COB_ID) & 0x7FF if c.SYNC_COB_ID in od else 0x80
        if c.EMCY_COB_ID in od:
            self.node.emcy.cob_id = self._raw(c.EMCY_COB_ID) & 0x7FF
        network.subscribe(self.sync_id, self._on_sync)
        network.subscribe(0, self._on_nmt)
        self._monitor = threading.Thread(target=self._watch, name="cia402-sim-monitor", daemon=True)
        self._monitor.start()
        self.node.nmt.send_command(130)  # reset communication: boot-up message
        self.node.nmt.send_command(128)  # pre-operational; starts the producer heartbeat

    @property
    def state(self) -> c.State:
        return self._state

    @state.setter
    def state(self, value: c.State) -> None:
        if self._state is c.State.OPERATION_ENABLED and value is not c.State.OPERATION_ENABLED:
            self._idle_since = time.monotonic()
        self._state = value

    # ------------------------------------------------------------------ object dictionary
    def _raw(self, index: int, sub: int | None = None) -> int:
        obj = self.node.sdo[index]
        return int(obj[sub].raw if sub is not None else obj.raw)

    def statusword(self) -> int:
        word = c.STATUS_BITS[self.state] | c.REMOTE
        if self.state in (c.State.READY, c.State.SWITCHED_ON, c.State.OPERATION_ENABLED, c.State.QUICK_STOP):
            word |= c.VOLTAGE_ENABLED
        return word

    def _on_read(self, index: int, subindex: int, od) -> int | None:
        values = {c.STATUSWORD: self.statusword(), c.MODES_DISPLAY: self.mode_display, c.ERROR_CODE: self.error_code,
                  c.ERROR_REGISTER: self.error_register, c.POSITION_ACTUAL: self.meas[0],
                  c.VELOCITY_ACTUAL: self.meas[1], c.TORQUE_ACTUAL: self.meas[2], 0x6078: self.meas[3],
                  0x6074: self.target_pm if self.state is c.State.OPERATION_ENABLED else 0}
        if index == c.ERROR_HISTORY:
            return len(self.history) if subindex == 0 else (self.history[subindex - 1]
                                                             if subindex <= len(self.history) else 0)
        return values.get(index)

    def _on_write(self, index: int, subindex: int, od, data: bytes) -> None:
        value = od.decode_raw(data)
        with self._lock:
            if index in (c.COMM_CYCLE_PERIOD, c.MAX_TORQUE, c.RATED_TORQUE, c.RATED_CURRENT, c.ENCODER_RESOLUTION,
                         c.GEAR_RATIO, c.FEED_CONSTANT, c.POSITION_FACTOR, c.VELOCITY_ENCODER_FACTOR):
                self._settings = None
            if index == c.ERROR_HISTORY and subindex == 0 and int(value) == 0:
                self.history.clear()  # CiA 301: writing 0 to sub 0 clears the history
            elif index == c.CONTROLWORD:
                self._command(int(value))
            elif index == c.TARGET_TORQUE:
                self.target_pm = int(value)
            elif index == c.MODES_OF_OPERATION:
                self.mode_display = int(value) if self._supports(int(value)) else self.mode_display
            elif index == c.CONSUMER_HEARTBEAT and subindex == 1:
                node, ms = (int(value) >> 16) & 0x7F, int(value) & 0xFFFF
                if node == self.node.id:  # its own heartbeat would feed it: a drive never counts its own frames
                    node = 0
                if self._host_hb is not None:
                    self.network.unsubscribe(0x700 + self._host_hb[0], self._on_host_heartbeat)
                self._host_hb = (node, ms / 1000.0) if ms and node else None
                if self._host_hb is not None:
                    self.last_host_heartbeat = time.monotonic()
                    self.network.subscribe(0x700 + node, self._on_host_heartbeat)

    def _supports(self, mode: int) -> bool:
        return 1 <= mode <= 32 and bool(self._raw(c.SUPPORTED_MODES) & (1 << (mode - 1)))

    # ------------------------------------------------------------------ state machine, faults
    def _command(self, controlword: int, by_rpdo: bool = False) -> None:
        command = c.command_of(controlword)
        before = self.state
        if self._enable_in and command is not c.Command.ENABLE_OPERATION:
            self._enable_in = 0  # a pending enable is cancelled by any other command
        if self.state is c.State.FAULT and command is c.Command.FAULT_RESET:
            self.error_code = 0
            self.error_register = 0
            self.node.emcy.reset()
        if command is c.Command.ENABLE_OPERATION and self.mode_display != c.MODE_CST:
            command = None  # only CST is simulated: operation is not enabled in another mode
        self.state = c.next_state(self.state, command)
        if self.state is c.State.QUICK_STOP:
            self.state = c.next_state(self.state, c.Command.DISABLE_VOLTAGE)  # torque zero at once
        if self.state is c.State.OPERATION_ENABLED and before is not c.State.OPERATION_ENABLED:
            if by_rpdo and self.enable_latency:
                if not self._enable_in:
                    self._enable_in = self.enable_latency
                self.state = c.State.SWITCHED_ON  # the power stage takes its time: enabled after the latency
                return
            self._enabled()
            if not by_rpdo:  # CST: 0x6071 acts as soon as operation is enabled (by RPDO: from this SYNC on)
                self._ensure_plant()
                self.u_held = self.target_pm / 1000.0 * self._rated / self._settings[2]

    def _enabled(self) -> None:
        if self.clock == "real" and self.plant is not None and math.isfinite(self._idle_since):
            # the axis coasted, torque off, since operation was disabled (a fault, a killed host): real time
            # passed for it, as for a real machine; at most COAST_LIMIT s are simulated
            steps = int(min(time.monotonic() - self._idle_since, COAST_LIMIT) / self.plant.dt)
            if steps:
                self.plant.run(np.zeros(steps))
        self._idle_since = math.inf
        self.state = c.State.OPERATION_ENABLED
        self.last_sync = math.inf  # SYNC monitoring starts with the first SYNC in operation enabled
        self._arrival, self._lag = math.inf, 0.0

    def fault(self, code: int, register: int = 0x01) -> None:
        """Latch a fault: torque off, state fault, 0x603F/0x1001 set, EMCY sent (thread-safe)."""
        with self._lock:
            if self.state is c.State.FAULT:
                return
            self.state = c.State.FAULT
            self.error_code = code
            self.error_register = register | 0x01
            self.history = [code, *self.history][:HISTORY_LENGTH]
            self.emcy_sent.append(code)
            self.node.emcy.send(code, self.error_register)

    def _lost(self, code: int) -> None:
        action = int(self._raw(c.ABORT_CONNECTION))
        if action == 1:
            self.fault(code, 0x10)
        elif action in (2, 3):
            self.state = c.State.SWITCH_ON_DISABLED
            self.emcy_sent.append(code)
            self.node.emcy.send(code, 0x10)

    def _on_host_heartbeat(self, can_id, data, timestamp) -> None:
        self.last_host_heartbeat = time.monotonic()

    def _watch(self) -> None:
        stalls = StallGrace()
        while not self._stop.wait(0.002):
            now = time.monotonic()
            shortest = min(self.sync_timeout, self._host_hb[1] if self._host_hb is not None else math.inf)
            if not stalls.may_judge(now, shortest):
                continue
            with self._lock:
                if self.loss_in_any_state and self.state not in (c.State.FAULT, c.State.OPERATION_ENABLED):
                    if self._host_hb is not None and now - self.last_host_heartbeat > self._host_hb[1]:
                        self._lost(EMCY_HEARTBEAT)
                    continue
                if self.state is not c.State.OPERATION_ENABLED:
                    continue
                if self._host_hb is not None and now - self.last_host_heartbeat > self._host_hb[1]:
                    self._lost(EMCY_HEARTBEAT)
                    continue
                if now - self.last_sync > self.sync_timeout:  # +inf before the first SYNC
                    self._lost(EMCY_SYNC_LOST)

    # ------------------------------------------------------------------ NMT, PDOs, SYNC
    def _on_nmt(self, can_id, data, timestamp) -> None:
        with self._lock:
            if self.node.nmt.state == "OPERATIONAL":
                for m in self._rpdos:
                    self.network.unsubscribe(m.cob_id, m.on_message)
                self.node.rpdo.read()
                self.node.tpdo.read()
                self._rpdos = [m for m in self.node.rpdo.map.values() if m.enabled]
                self._tpdos = [m for m in self.node.tpdo.map.values()
                               if m.enabled and 1 <= (m.trans_type or 0) <= 240]
                for m in self._rpdos:
                    m.is_received = False
                    self.network.subscribe(m.cob_id, m.on_message)
            elif self.state is c.State.OPERATION_ENABLED:
                self.state = c.State.SWITCH_ON_DISABLED  # leaving OPERATIONAL disables the drive

    def _pair(self, index: int) -> tuple[int, int] | None:
        if index not in self.node.object_dictionary:
            return None
        one, two = self._raw(index, 1), self._raw(index, 2)
        return (one, two) if one and two else None

    def _in_units(self, counts: int, velocity: float) -> tuple[int, int]:
        """Position (increments) and velocity (increments/s) in the units 0x6064 and 0x606C report."""
        per_unit, velocity_factor = self._factors
        per_velocity_unit = velocity_factor[0] / velocity_factor[1] if velocity_factor else per_unit
        return round(counts / per_unit), round(velocity / per_velocity_unit)

    def _ensure_plant(self) -> Plant:
        if self._settings is None:
            rated_torque = self._raw(c.RATED_TORQUE) / 1000.0
            kt = rated_torque / (self._raw(c.RATED_CURRENT) / 1000.0)
            limit = self._raw(c.MAX_TORQUE) / 1000.0 * rated_torque / kt
            cpr = round(self._raw(c.ENCODER_RESOLUTION, 1) / self._raw(c.ENCODER_RESOLUTION, 2))
            period = self._raw(c.COMM_CYCLE_PERIOD) * 1e-6 or 1e-3
            self._settings = (period, limit, kt, cpr)
            self._rated = rated_torque
            self._factors = (c.increments_per_unit(cpr, self._pair(c.GEAR_RATIO), self._pair(c.FEED_CONSTANT),
                                                   self._pair(c.POSITION_FACTOR)),
                             self._pair(c.VELOCITY_ENCODER_FACTOR))
        period, limit, kt, cpr = self._settings
        if self._plant_key != self._settings:
            params = self.sim.plant_for(max(limit, 1e-9), kt, cpr)
            dt = period / self.oversample
            theta = self.plant.theta if self.plant is not None else 0.0
            omega = self.plant.omega if self.plant is not None else self.spin
            self.plant = Plant(params, dt, self.sim.substeps or substeps_for(params, dt), theta0=theta, omega0=omega)
            self._plant_key = self._settings
        return self.plant

    def _on_sync(self, can_id, data, timestamp) -> None:
        now = time.monotonic()
        with self._lock:
            if self.node.nmt.state != "OPERATIONAL":
                return
            self._reported = self.statusword() if self.order == "sample-then-apply" else None
            if self._enable_in:
                self._enable_in -= 1
                if not self._enable_in and self.state is c.State.SWITCHED_ON:
                    self._enabled()
            for m in self._rpdos:  # synchronous RPDOs: what arrived before this SYNC applies now
                if not m.is_received:
                    continue
                m.is_received = False
                for var in m.map:
                    if var.index == c.CONTROLWORD:
                        self._command(int(var.raw), by_rpdo=True)
                    elif var.index == c.TARGET_TORQUE:
                        self.target_pm = int(var.raw)
            plant = self._ensure_plant()
            _, _, kt, cpr = self._settings
            n = self.oversample
            arrival = timestamp if timestamp else now
            if self.clock == "real" and math.isfinite(self._arrival):
                # the time between the SYNCs' arrivals on the bus (kernel timestamps where the bus has them),
                # not this process's: a real drive samples when SYNC arrives, and this process may be late
                # to read it. Rounding to plant steps is carried over, so the plant keeps real time.
                elapsed = arrival - self._arrival + self._lag
                cap = max(10 * self.oversample, math.ceil(self.sync_timeout / plant.dt))
                # 0 steps: a SYNC within one plant step of the previous one (overdue SYNCs sent back to back)
                # samples the same state, and its target replaces the previous one, as in a drive's control tick
                n = int(min(max(round(elapsed / plant.dt), 0), cap))
                self._lag = elapsed - n * plant.dt if n < cap else 0.0
            self._arrival = arrival
            self.last_sync = now
            enabled = self.state is c.State.OPERATION_ENABLED
            u_new = self.target_pm / 1000.0 * self._rated / kt if enabled else 0.0
            if n == 0:
                self.u_held = u_new
                self._answer()
                return
            out = hold_step(plant, self.u_held, u_new, n)  # the last row is measured now, before u_new acts
            self.u_held = u_new
            position, velocity = self._in_units(int(out.counts[-1]), out.omega[-1] * cpr / (2 * math.pi))
            wrap = (position + 2**31) % 2**32 - 2**31
            # torque actual: the measured current (mean over the cycle that ends now) times the nominal k_t,
            # as a drive computes it; per mille of the rated torque
            torque_pm = round(out.current_meas[-1] * kt / self._rated * 1000.0)
            self.meas = (wrap, velocity, int(np.clip(torque_pm, -32768, 32767)),
                         int(np.clip(round(out.current_meas[-1] / (self._rated / kt) * 1000.0), -32768, 32767)))
            if enabled:
                self._check_limits(int(out.counts[-1]), float(out.omega[-1]))
            self._answer()

    def _check_limits(self, counts: int, omega: float) -> None:
        """The drive's own limits: software position limit 0x607D (increments) and max motor speed 0x6080 (rpm),
        checked on the sample just taken; either faults the drive (torque off at once)."""
        od = self.node.object_dictionary
        if c.SOFTWARE_POSITION_LIMIT in od:  # in position units
            low, high = self._raw(c.SOFTWARE_POSITION_LIMIT, 1), self._raw(c.SOFTWARE_POSITION_LIMIT, 2)
            if not low <= self._in_units(counts, 0.0)[0] <= high:
                self.fault(EMCY_POSITION_LIMIT)
                return
        if c.MAX_MOTOR_SPEED in od and abs(omega) * 60 / (2 * math.pi) > self._raw(c.MAX_MOTOR_SPEED):
            self.fault(EMCY_OVER_SPEED)

    def _answer(self) -> None:
        """Count the SYNC and send the TPDOs it triggers (with the lock held)."""
        self.cycle += 1
        for m in self._tpdos:
            if self.cycle % m.trans_type == 0:
                for var in m.map:
                    value = self._on_read(var.index, var.subindex, var.od)
                    if var.index == c.STATUSWORD and self._reported is not None:
                        value = self._reported  # sampled before this SYNC's controlword applied
                    if value is not None:
                        var.raw = value
                m.transmit()

    def close(self) -> None:
        self._stop.set()
        self.node.nmt.stop_heartbeat()
        self._monitor.join(timeout=1.0)
        self.network.unsubscribe(self.sync_id, self._on_sync)
        self.network.unsubscribe(0, self._on_nmt)


def serve(interface: str, channel: str, node_id: int, sim: SimConfig, clock: str = "real",
          supported_modes: int | None = None, stop: threading.Event | None = None, port: int | None = None,
          order: str = "apply-then-sample", enable_latency: int = 0) -> int:
    """Run one simulated drive on a python-can bus until ``stop`` is set (or Ctrl-C). Prints the device
    URL to connect to as its first line."""

    def start(bus) -> tuple[str, object]:
        network = canopen.Network(bus)
        network.connect()
        drive = SimCia402Drive(network, node_id, sim, clock=clock, supported_modes=supported_modes, order=order,
                               enable_latency=enable_latency)

        def close() -> None:
            drive.close()
            network.disconnect()

        return f"canopen://{interface}/{channel}?node={node_id}&eds={EDS_PATH}", close

    return drive_sim.serve(interface, channel, port, stop, start)
