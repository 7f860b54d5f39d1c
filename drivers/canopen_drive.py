"""A CiA 402 servo drive over CANopen, in Cyclic Synchronous Torque mode, with the ``canopen`` package.

    with CanopenDrive("socketcan", "can0", node_id=1, eds="epos4.eds") as drive:
        drive.configure(Config(sample_rate=1000, current_limit=5.0, torque_constant=0.2))
        drive.arm()
        for block in drive.stream(setpoints_in_amperes):
            use(block.time, block.position, block.torque, block.host_time)

The host owns the clock. Per cycle k it sends the RPDO (controlword, target torque 0x6071 in per mille of
the rated torque 0x6076) and then SYNC k; at SYNC k the drive samples position 0x6064, velocity 0x606C,
torque 0x6077 and statusword 0x6041, sends them in two SYNC-triggered TPDOs and applies the target torque
received before the SYNC. That is the plant's own convention (outputs of sample k measured at t_k, input k
held over [t_k, t_k+1)), so a host-clocked run reads like a device-clocked one, plus a host timestamp and
the cycle counter per sample.

Set-up (``configure``): NMT pre-operational; SDO: mode 10 (checked against 0x6502 first), communication
cycle period 0x1006, max torque 0x6072 from the host's current limit, producer heartbeat 0x1017, the host
as heartbeat consumer 0x1016 (timeout = the watchdog timeout), lost-communication reaction 0x6007 = fault;
PDO mapping by SDO; NMT operational; the host starts its own heartbeat. ``arm`` walks the CiA 402 state
machine to operation enabled (fault reset first if needed), with 0x6071 = 0 by SDO and in one RPDO first; the
run's first sample is checked for motion the host did not command. EMCY messages latch a fault host-side with
the code's text; ``estop`` sends quick stop.

What the drive says is used, not assumed: the encoder resolution 0x608F (adopted), the factor objects for the
units of 0x6064 and 0x606C (0x6091-0x6094 where present), the SYNC and EMCY COB-IDs (0x1005, 0x1014); 0x60C2 gets
the cycle period where the drive has it. docs/drives.md lists every object the host assumes.
"""

from __future__ import annotations

import math
import struct
import threading
import time

import numpy as np

from hilbench.common.runfile.schema import HOST_TIME, DeviceIdentity
from hilbench.drivers import cia402 as c
from hilbench.drivers import protocol as p
from hilbench.drivers.calibration import Calibration, CountUnwrapper
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
from hilbench.drivers.host_clocked import GuardFrame, HostClockedDevice
from hilbench.drivers.host_cycle import CanCycle, CanCycleSpec

HOST_NODE_ID = 127          # the host's node id for its heartbeat (0x700 + 127)
DRIVE_HEARTBEAT_MS = 100    # producer heartbeat the host asks of the drive
RATES = (1000, 2000)        # Hz; 2 kHz is near a 1 Mbit/s bus's limit for SYNC + 1 RPDO + 2 TPDOs
#: SYNCs a stream allows the drive before its TPDO must report "operation enabled" (CiA 301 lets a drive apply
#: the controlword after sampling, and a drive may take cycles to close its loops): configurable, bounded.
ENABLE_CYCLES = 4  # an enable latency of 3 SYNCs, reported one SYNC late by a sample-then-apply drive
REST_SPEED = 0.01           # of the velocity limit: a first sample faster than this is motion the host did not command
REST_TORQUE = 0.05          # of the rated torque: likewise for the first sample's torque actual 0x6077
OWNER_LISTEN = 0.3          # s the host listens, sending nothing, for another host's traffic before its first SDO

#: The objects the host maps into PDOs and their CiA 402 data types (canopen.objectdictionary codes): an EDS
#: that declares another type is refused before anything is sent (the PDO layout is fixed by these).
PDO_TYPES = {c.CONTROLWORD: (0x6, "UNSIGNED16"), c.TARGET_TORQUE: (0x3, "INTEGER16"),
             c.STATUSWORD: (0x6, "UNSIGNED16"), c.TORQUE_ACTUAL: (0x3, "INTEGER16"),
             c.POSITION_ACTUAL: (0x4, "INTEGER32"), c.VELOCITY_ACTUAL: (0x4, "INTEGER32")}
#: Objects the host reads or writes and cannot run without (beyond the PDO-mapped ones).
REQUIRED = (c.DEVICE_TYPE, c.SUPPORTED_MODES, c.RATED_TORQUE, c.ENCODER_RESOLUTION, c.MODES_OF_OPERATION,
            c.MODES_DISPLAY, c.COMM_CYCLE_PERIOD, c.MAX_TORQUE, c.PRODUCER_HEARTBEAT)
#: The TPDOs' layouts as the host maps them (TPDO1: statusword, torque actual; TPDO2: position, velocity actual).
TPDO1 = np.dtype([("status", "<u2"), ("torque", "<i2")])
TPDO2 = np.dtype([("position", "<i4"), ("velocity", "<i4")])
DATA_TYPE_NAMES = {0x1: "BOOLEAN", 0x2: "INTEGER8", 0x3: "INTEGER16", 0x4: "INTEGER32", 0x5: "UNSIGNED8",
                   0x6: "UNSIGNED16", 0x7: "UNSIGNED32", 0x8: "REAL32", 0x9: "VISIBLE_STRING", 0x11: "REAL64",
                   0x15: "INTEGER64", 0x1B: "UNSIGNED64"}


class CanopenDrive(HostClockedDevice):
    """A CiA 402 drive at ``node_id`` on a python-can bus (``interface``, ``channel``), OD from ``eds``."""

    capabilities = Capabilities({"current": RATES})
    row_name = "cycle"
    end_text = "zero torque sent, operation disabled"

    def __init__(self, interface: str, channel: str, node_id: int, eds: str, timeout: float = 2.0,
                 enable_cycles: int = ENABLE_CYCLES, **bus_kwargs) -> None:
        import canopen  # imported here: only CANopen users need it loaded

        self.name = f"canopen://{interface}/{channel}?node={node_id}"
        self.node_id = node_id
        self.timeout = timeout
        self.label = f"CANopen node {node_id}"
        self.config: p.Config | None = None
        self._emcy: list[tuple[int, int, float]] = []
        self._emcy_event = threading.Event()
        self._heartbeat_task = None
        self._estop_requested = False
        self._last_status = 0       # statusword of the last sample streamed
        self._last_cmd = 0.0        # A, the last current command sent
        self._sdo_lock = threading.RLock()  # canopen's SDO client serves one transfer at a time
        self._notes: list[str] = []  # one-line remarks on the streams, for the run events
        self.enable_cycles = enable_cycles
        self.interface, self.channel, self.bus_kwargs = interface, channel, dict(bus_kwargs)
        self._skipped: list[str] = []  # optional objects the drive lacks, said once in the run events
        self._restore: dict[tuple[int, int | None], int] = {}  # objects to put back on close
        self._check_rest = False  # set by configure: the next stream's first sample is checked for motion
        od = _check_eds(eds, node_id)  # before the bus is even opened
        self.network = canopen.Network(self._open_bus(interface, channel, **bus_kwargs))
        self.network.connect()
        try:
            self._refuse_if_owned()  # listens only: nothing is sent to a drive another host runs
            self.node = self.network.add_node(node_id, od)
            self.node.sdo.RESPONSE_TIMEOUT = timeout
            self.node.sdo.MAX_RETRIES = 1  # tries in all: the timeout is the whole wait
            self.node.emcy.add_callback(self._on_emcy)
            self._identify()
        except BaseException:
            self.close()
            raise

    def _refuse_if_owned(self) -> None:
        """Refuse, having sent nothing, a drive another host is running (one owner per drive).

        The owner's traffic tells: while it streams, the drive's RPDO1 and TPDO1 are on the bus at every
        SYNC; between streams, the drive stays NMT operational (its heartbeat) and the owner's heartbeat
        (node 127) goes on until it closes, which puts the drive back to pre-operational."""
        node = self.node_id
        seen: dict[str, float] = {}
        nmt: list[int] = []

        def heard(can_id, data, timestamp) -> None:
            if can_id == 0x700 + node and data:
                nmt.append(data[0] & 0x7F)
            else:
                seen.setdefault({0x80: "SYNC", 0x200 + node: "its RPDO1", 0x180 + node: "its TPDO1",
                                 0x700 + HOST_NODE_ID: "a host heartbeat (0x77F)"}[can_id], time.monotonic())

        ids = (0x80, 0x200 + node, 0x180 + node, 0x700 + HOST_NODE_ID, 0x700 + node)
        for cob in ids:
            self.network.subscribe(cob, heard)
        try:
            time.sleep(OWNER_LISTEN)
        finally:
            for cob in ids:
                self.network.unsubscribe(cob, heard)
        operational = (nmt[-1] == 5) if nmt else None  # None: the drive sends no heartbeat
        cycling = [what for what in ("its RPDO1", "its TPDO1") if what in seen]
        host = "a host heartbeat (0x77F)" in seen
        # a drive that sends no heartbeat was never configured by a host (configure asks for one): only a
        # stream's own frames tell then; another drive's host heartbeat on a shared bus must not
        if cycling or (operational and (host or "SYNC" in seen)):
            evidence = ", ".join(cycling + [w for w in ("SYNC", "a host heartbeat (0x77F)") if w in seen])
            raise PortBusyError(f"{self.name} is in use by another host ({evidence} on the bus; the drive is "
                                f"{'NMT operational' if operational else 'not NMT operational'}); nothing "
                                f"was sent to it: stop that host's run first")

    # ------------------------------------------------------------------ SDO helpers
    def _read(self, index: int, sub: int | None = None, what: str = ""):
        import canopen

        try:
            with self._sdo_lock:
                obj = self.node.sdo[index]
                return (obj[sub] if sub is not None else obj).raw
        except canopen.SdoCommunicationError as exc:
            raise DeviceTimeoutError(f"CANopen node {self.node_id} did not answer: SDO upload of 0x{index:04X}"
                                     f"{'' if sub is None else f':{sub}'} ({what or 'object'}) timed out after "
                                     f"{self.timeout:g} s") from exc
        except canopen.SdoAbortedError as exc:
            raise CommandRefusedError(f"CANopen node {self.node_id} refused reading 0x{index:04X} "
                                      f"({what or 'object'}): {exc}") from exc
        except KeyError:
            raise ConfigError(f"CANopen node {self.node_id}: the EDS has no object 0x{index:04X}"
                              f"{'' if sub is None else f':{sub}'} ({what or 'object'})") from None

    def _write(self, index: int, value, sub: int | None = None, what: str = "") -> None:
        import canopen

        try:
            with self._sdo_lock:
                obj = self.node.sdo[index]
                (obj[sub] if sub is not None else obj).raw = value
        except canopen.SdoCommunicationError as exc:
            raise DeviceTimeoutError(f"CANopen node {self.node_id} did not answer: SDO download of 0x{index:04X}"
                                     f" ({what or 'object'}) timed out after {self.timeout:g} s") from exc
        except canopen.SdoAbortedError as exc:
            raise CommandRefusedError(f"CANopen node {self.node_id} refused 0x{index:04X} ({what or 'object'}) "
                                      f"= {value}: {exc}") from exc
        except KeyError:
            raise ConfigError(f"CANopen node {self.node_id}: the EDS has no object 0x{index:04X}"
                              f"{'' if sub is None else f':{sub}'} ({what or 'object'})") from None

    def _has(self, index: int, sub: int | None = None) -> bool:
        od = self.node.object_dictionary
        if index not in od:
            return False
        return sub is None or sub in od[index]

    def _write_optional(self, index: int, value, sub: int | None = None, what: str = "",
                        restore: bool = False) -> None:
        """Write an optional object where the EDS and the drive have it; say so once where they do not.
        ``restore``: read its value first and put it back on close."""
        import canopen

        name = f"0x{index:04X}{'' if sub is None else f':{sub}'} ({what})"
        if not self._has(index, sub):
            self._skip(f"{name} is not in the EDS: not written")
            return
        try:
            if restore and (index, sub) not in self._restore:
                self._restore[(index, sub)] = int(self._read(index, sub, what))
            self._write(index, value, sub, what)
        except CommandRefusedError as exc:
            if isinstance(exc.__cause__, canopen.SdoAbortedError) and exc.__cause__.code in (0x06020000,
                                                                                              0x06090011):
                self._skip(f"{name} is not in the drive (SDO abort 0x{exc.__cause__.code:08X}): not written")
                self._restore.pop((index, sub), None)
                return
            raise

    def _skip(self, line: str) -> None:
        if line not in self._skipped:
            self._skipped.append(line)

    def _identify(self) -> None:
        device_type = int(self._read(c.DEVICE_TYPE, what="device type"))
        if device_type & 0xFFFF != c.PROFILE_402:
            raise CommandRefusedError(f"CANopen node {self.node_id} is not a CiA 402 drive (device type "
                                      f"0x{device_type:08X}, profile {device_type & 0xFFFF})")
        supported = int(self._read(c.SUPPORTED_MODES, what="supported drive modes"))
        if not supported & c.CST_BIT:
            raise CommandRefusedError(f"CANopen node {self.node_id} does not support Cyclic Synchronous Torque "
                                      f"(mode 10): supported drive modes 0x6502 = 0x{supported:08X}")
        self.rated_torque = int(self._read(c.RATED_TORQUE, what="motor rated torque")) / 1000.0  # N*m
        if self.rated_torque <= 0:
            raise ConfigError(f"CANopen node {self.node_id}: motor rated torque 0x6076 is 0")
        inc = int(self._read(c.ENCODER_RESOLUTION, 1, "encoder increments"))
        revs = int(self._read(c.ENCODER_RESOLUTION, 2, "motor revolutions"))
        self.counts_per_rev = inc // max(revs, 1)
        self._units()
        self._cob_ids()
        details = {"device_type": f"0x{device_type:08X}", "supported_modes": f"0x{supported:08X}",
                   "rated_torque_Nm": self.rated_torque, "encoder_counts_per_rev": self.counts_per_rev,
                   "units": self._adopted[0].removeprefix("units adopted from the drive: ")}
        try:
            model = str(self._read(c.DEVICE_NAME, what="device name"))
        except (CommandRefusedError, KeyError):
            model = "unknown"
        for sub, key in ((1, "vendor_id"), (2, "product_code"), (3, "revision"), (4, "serial")):
            try:
                details[key] = int(self._read(c.IDENTITY, sub, key))
            except (CommandRefusedError, KeyError):
                pass
        serial = details.pop("serial", "")
        # the drive samples at each SYNC: the analysis resamples on host_time (analysis/record.py)
        self._info = DeviceIdentity(protocol="CiA 402 over CANopen", url=self.name, sample_times=HOST_TIME,
                                    model=model, serial=str(serial), details=details)

    def _read_optional(self, index: int, sub: int | None = None, what: str = "") -> int | None:
        """An optional object's value, None where the EDS or the drive lacks it."""
        if not self._has(index, sub):
            return None
        try:
            return int(self._read(index, sub, what))
        except CommandRefusedError:  # SDO abort: the drive lacks it
            return None

    def _pair(self, index: int, what: str) -> tuple[int, int] | None:
        one, two = self._read_optional(index, 1, what), self._read_optional(index, 2, what)
        return (one, two) if one and two else None  # a zero is no ratio: the object is not in use

    def _units(self) -> None:
        """Position and velocity units from what the drive says: 0x608F, and the factor objects where present
        (0x6093 position factor, else 0x6091 gear ratio with 0x6092 feed constant; 0x6094 velocity encoder
        factor, else the velocity is in position units per second). One line says what was adopted."""
        gear, feed = self._pair(c.GEAR_RATIO, "gear ratio"), self._pair(c.FEED_CONSTANT, "feed constant")
        factor = self._pair(c.POSITION_FACTOR, "position factor")
        velocity = self._pair(c.VELOCITY_ENCODER_FACTOR, "velocity encoder factor")
        self.position_factor = c.increments_per_unit(self.counts_per_rev, gear, feed, factor)  # increments/unit
        self.velocity_factor = velocity[0] / velocity[1] if velocity else self.position_factor  # (inc/s)/unit
        if factor:
            how = f"position factor 0x6093 = {factor[0]}/{factor[1]}"
        elif gear and feed:
            how = f"gear ratio 0x6091 = {gear[0]}/{gear[1]}, feed constant 0x6092 = {feed[0]}/{feed[1]}"
        else:
            how = "no factor objects: 0x6064 in increments"
        vel = f"velocity encoder factor 0x6094 = {velocity[0]}/{velocity[1]}" if velocity else \
            "0x606C in position units/s"
        self._adopted = [f"units adopted from the drive: encoder 0x608F = {self.counts_per_rev} increments/rev; "
                         f"{how} ({self.position_factor:.6g} increments per position unit); {vel}"]

    def _cob_ids(self) -> None:
        """The SYNC and EMCY COB-IDs the drive uses (0x1005, 0x1014), where it has them; CiA 301 defaults else."""
        sync = self._read_optional(c.SYNC_COB_ID, what="COB-ID SYNC")
        self.sync_id = sync & 0x7FF if sync is not None else 0x80
        emcy = self._read_optional(c.EMCY_COB_ID, what="COB-ID EMCY")
        self.emcy_id = None if emcy is not None and emcy >> 31 else (emcy & 0x7FF if emcy is not None
                                                                      else 0x80 + self.node_id)
        if self.emcy_id is not None and self.emcy_id != 0x80 + self.node_id:  # canopen listens on the default
            self.network.subscribe(self.emcy_id, self.node.emcy.on_emcy)
        if self.sync_id != 0x80 or self.emcy_id != 0x80 + self.node_id:
            emcy_text = "none (0x1014 bit 31)" if self.emcy_id is None else f"0x{self.emcy_id:03X}"
            self._adopted.append(f"COB-IDs from the drive: SYNC 0x{self.sync_id:03X} (0x1005), EMCY {emcy_text} "
                                 f"(0x1014)")

    def info(self) -> DeviceIdentity:
        return self._info

    # ------------------------------------------------------------------ EMCY, state
    def _on_emcy(self, err) -> None:
        if err.code == 0:
            return
        self._emcy.append((err.code, err.register, time.monotonic()))
        self._emcy_event.set()

    def emcy_line(self) -> str:
        if not self._emcy:
            return ""
        code, register, _ = self._emcy[-1]
        return f"EMCY 0x{code:04X} {c.emcy_text(code)} (error register 0x{register:02X})"

    def statusword(self) -> int:
        return int(self._read(c.STATUSWORD, what="statusword"))

    def status(self) -> int:
        """The statusword (a keepalive for callers that poll a device while a run is paused)."""
        return self.statusword()

    def power_state(self) -> c.State | None:
        """The CiA 402 power state the statusword reports (read by SDO)."""
        return c.state_of(self.statusword())

    def live_state(self) -> dict:
        streaming = self._cycle is not None
        word = self._last_status if streaming else self.statusword()  # no SDO while the cycle runs
        state = c.state_of(word)
        return {"state": f"{state.value if state else 'unknown'} (statusword 0x{word:04X})",
                "armed": state in (c.State.OPERATION_ENABLED, c.State.QUICK_STOP), "streaming": streaming,
                "faults": [self.emcy_line()] if self._emcy else [], "cycle": self._progress,
                "current_cmd": self._last_cmd if streaming else 0.0, "counters": self.timing_counters()}

    # ------------------------------------------------------------------ Device API
    def configure(self, config: p.Config) -> None:
        self._check_config(config)
        if config.counts_per_rev != self.counts_per_rev:  # the drive knows its encoder: adopted, and said
            self._notes.append(f"CANopen node {self.node_id}: counts_per_rev {config.counts_per_rev} replaced by "
                               f"the drive's encoder resolution 0x608F = {self.counts_per_rev} increments/rev")
            config.counts_per_rev = self.counts_per_rev
        node = self.node
        node.nmt.state = "PRE-OPERATIONAL"
        self._write(c.MODES_OF_OPERATION, c.MODE_CST, what="modes of operation")
        self._write(c.COMM_CYCLE_PERIOD, round(1e6 / config.sample_rate), what="communication cycle period")
        value, power = c.interpolation_period(1.0 / config.sample_rate)
        self._write_optional(c.INTERPOLATION_PERIOD, value, 1, "interpolation time period value")
        self._write_optional(c.INTERPOLATION_PERIOD, power, 2, "interpolation time index")
        max_pm = c.max_torque_permille(config.current_limit, config.torque_constant, self.rated_torque)
        self._write(c.MAX_TORQUE, max_pm, what="max torque")
        # the drive's own limits, where it has the objects; the host also watches them every cycle
        low, high = c.position_limit_increments(config.position_min, config.position_max,
                                                self.counts_per_rev / self.position_factor)  # position units
        self._write_optional(c.SOFTWARE_POSITION_LIMIT, low, 1, "software position limit, min")
        self._write_optional(c.SOFTWARE_POSITION_LIMIT, high, 2, "software position limit, max")
        self._write_optional(c.MAX_MOTOR_SPEED, c.max_motor_speed_rpm(config.velocity_limit), what="max motor speed")
        self._write(c.PRODUCER_HEARTBEAT, DRIVE_HEARTBEAT_MS, what="producer heartbeat")
        hb_ms = min(round(config.watchdog_timeout * 1000), 0xFFFF)
        self._write_optional(c.CONSUMER_HEARTBEAT, (HOST_NODE_ID << 16) | hb_ms, 1, "consumer heartbeat",
                             restore=True)
        self._write_optional(c.ABORT_CONNECTION, 1, what="abort connection option (1 = fault)", restore=True)
        self._map_pdos()
        self._start_heartbeat(config.watchdog_timeout)
        node.nmt.state = "OPERATIONAL"
        self._wait_nmt("OPERATIONAL")
        self.config = config
        self.calibration = Calibration(config.torque_constant, self.counts_per_rev, config.ratio)
        # the run's first sample is checked for motion the host did not command (not a resume's: the runner
        # configures once per run and arms again after a pause)
        self._check_rest = True

    def _map_pdos(self) -> None:
        node = self.node
        try:
            with self._sdo_lock:  # PDO reads and saves are SDO transfers too
                node.rpdo.read()
                node.tpdo.read()
        except Exception as exc:
            raise DeviceTimeoutError(f"CANopen node {self.node_id}: reading the PDO configuration failed: "
                                     f"{exc}") from exc
        layout = {1: (node.rpdo, (c.CONTROLWORD, c.TARGET_TORQUE)),
                  2: (node.tpdo, (c.STATUSWORD, c.TORQUE_ACTUAL)),
                  3: (node.tpdo, (c.POSITION_ACTUAL, c.VELOCITY_ACTUAL))}
        for pdos in (node.rpdo, node.tpdo):
            for m in pdos.map.values():
                m.enabled = False
        for which, (pdos, objects) in layout.items():
            m = pdos.map[1 if which < 3 else 2]
            m.clear()
            for index in objects:
                m.add_variable(index)
            m.trans_type = 1  # synchronous, every SYNC
            m.enabled = True
        try:
            with self._sdo_lock:
                node.rpdo.save()
                node.tpdo.save()
        except Exception as exc:
            raise CommandRefusedError(f"CANopen node {self.node_id} refused the PDO mapping: {exc}") from exc
        self._rpdo = node.rpdo.map[1]
        self._tpdo1, self._tpdo2 = node.tpdo.map[1], node.tpdo.map[2]

    def _wait_nmt(self, state: str) -> None:
        """Wait until the drive's heartbeat reports NMT ``state``."""
        import canopen

        deadline = time.monotonic() + self.timeout + DRIVE_HEARTBEAT_MS / 1000
        while time.monotonic() < deadline:
            try:
                if self.node.nmt.wait_for_heartbeat(max(0.0, deadline - time.monotonic())) == state:
                    return
            except canopen.nmt.NmtError:
                break
        raise DeviceTimeoutError(f"CANopen node {self.node_id} did not report NMT {state} in its heartbeat within "
                                 f"{self.timeout + DRIVE_HEARTBEAT_MS / 1000:g} s")

    def _start_heartbeat(self, timeout: float) -> None:
        if self._heartbeat_task is not None:
            self._heartbeat_task.stop()
        period = min(0.1, timeout / 4) if timeout > 0 else 0.1
        self._heartbeat_task = self.network.send_periodic(0x700 + HOST_NODE_ID, [5], period)

    def _controlword(self, word: int) -> None:
        self._write(c.CONTROLWORD, word, what="controlword")

    def _walk_to(self, target: c.State, commands: tuple[c.Command, ...]) -> None:
        for command in commands:
            self._controlword(int(command))
        deadline = time.monotonic() + self.timeout
        while True:
            word = self.statusword()
            if c.state_of(word) is target:
                return
            if time.monotonic() > deadline:
                now = c.state_of(word)
                extra = f"; {self.emcy_line()}" if self._emcy else ""
                raise CommandRefusedError(f"CANopen node {self.node_id} did not reach '{target.value}' "
                                          f"(statusword 0x{word:04X}: {now.value if now else 'unknown'}){extra}")
            time.sleep(0.005)

    def arm(self) -> None:
        self._configured("arming")
        if self.power_state() in (c.State.FAULT, c.State.FAULT_REACTION):
            raise DeviceFaultError(f"CANopen node {self.node_id} is in fault ({self.fault_text()}); "
                                   f"clear it with `hilbench fault clear --device URL` first")
        self._estop_requested = False
        self._zero_torque()
        self._walk_to(c.State.OPERATION_ENABLED, (c.Command.SHUTDOWN, c.Command.SWITCH_ON,
                                                  c.Command.ENABLE_OPERATION))
        display = int(self._read(c.MODES_DISPLAY, what="modes of operation display"))
        if display != c.MODE_CST:
            self.disarm()
            raise CommandRefusedError(f"CANopen node {self.node_id} runs mode {display}, not CST (10)")

    def _zero_torque(self) -> None:
        """Zero torque before the enable transition, every time: a CST drive applies 0x6071 as soon as operation
        is enabled, and a killed run may have left a torque there, in the object or in a received RPDO. So 0x6071
        = 0 by SDO, and one RPDO (shutdown, zero torque) that replaces whatever RPDO the drive holds."""
        self._write(c.TARGET_TORQUE, 0, what="target torque")
        self.network.send_message(self._rpdo.cob_id, _pdo_format(self._rpdo).pack(int(c.Command.SHUTDOWN), 0))

    def _uncommanded(self, t1: np.ndarray, t2: np.ndarray) -> str:
        """Why the run's first sample shows motion the host did not command ('' when it is at rest). Sample 0 is
        taken at the first SYNC, before the first commanded torque acts: its speed and its torque are the drive's
        own. Limits: 1 % of the velocity limit, 5 % of the rated torque (well above a resting encoder's and
        current sensor's noise)."""
        speed = abs(float(t2["velocity"][0])) * self.velocity_factor * 2 * math.pi / self.counts_per_rev
        torque = abs(float(c.permille_to_torque(t1["torque"][0], self.rated_torque)))
        speed_limit = REST_SPEED * self.config.velocity_limit
        torque_limit = REST_TORQUE * self.rated_torque
        if speed <= speed_limit and torque <= torque_limit:
            return ""
        return (f"UNFIT: uncommanded motion at the start of the run: the first sample shows {speed:.4g} rad/s "
                f"(limit {speed_limit:.4g}) and {torque:.4g} N*m (limit {torque_limit:.4g}) at the motor before any "
                f"commanded torque acted (a stale target torque in the drive, or an axis still moving)")

    def clear_faults(self) -> None:
        """Fault reset (controlword bit 7), then back to switch on disabled; forgets the latched EMCY."""
        self._controlword(0)
        self._walk_to(c.State.SWITCH_ON_DISABLED, (c.Command.FAULT_RESET, c.Command.DISABLE_VOLTAGE))
        self._emcy.clear()
        self._emcy_event.clear()

    def disarm(self) -> None:
        """Shutdown (power stage off, torque zero): ready to switch on. A drive in fault stays there."""
        if self._cycle is not None:
            self._cycle.stop()
        if self.power_state() in (c.State.FAULT, c.State.FAULT_REACTION, c.State.SWITCH_ON_DISABLED):
            return
        self._controlword(int(c.Command.SHUTDOWN))

    def estop(self) -> None:
        """Quick stop: in the next cycle's RPDO when streaming, else by SDO. Safe from any thread."""
        self._estop_requested = True
        cycle = self._cycle
        if cycle is not None:
            cycle.estop()
        else:
            self._controlword(int(c.Command.QUICK_STOP))

    # ------------------------------------------------------------------ the stream loop's hooks
    def _check_ready(self) -> None:
        if self._emcy:
            raise DeviceFaultError(f"cannot stream: {self.emcy_line()}")
        if self.power_state() not in (c.State.OPERATION_ENABLED, c.State.SWITCHED_ON):
            raise CommandRefusedError(f"cannot stream: CANopen node {self.node_id} is not switched on "
                                      f"(arm it first)")

    def _cycle_spec(self, values: np.ndarray) -> tuple[CanCycleSpec, np.ndarray]:
        """Per cycle: the RPDO (enable operation, target torque in per mille of the rated torque), then SYNC."""
        cfg = self.config
        n = len(values)
        self._pm = c.torque_to_permille(values * cfg.torque_constant, self.rated_torque)
        rpdo_fmt = _pdo_format(self._rpdo)
        fmt1, fmt2 = _pdo_format(self._tpdo1), _pdo_format(self._tpdo2)
        assert fmt1.size == TPDO1.itemsize and fmt2.size == TPDO2.itemsize
        tx = np.zeros((n, 2, 8), np.uint8)
        frame = np.zeros(n, dtype=np.dtype([("cw", "<u2"), ("torque", "<i2")]))
        frame["cw"] = int(c.Command.ENABLE_OPERATION)
        frame["torque"] = self._pm
        tx[:, 0, :4] = frame.view(np.uint8).reshape(n, 4)
        spec = CanCycleSpec(self.interface, self.channel, self.bus_kwargs, float(cfg.sample_rate),
                            (self._rpdo.cob_id, self.sync_id), (rpdo_fmt.size, 0),
                            (self._tpdo1.cob_id, self._tpdo2.cob_id),
                            (rpdo_fmt.pack(int(c.Command.QUICK_STOP), 0), b""),
                            (rpdo_fmt.pack(int(c.Command.SWITCH_ON), 0), b""),  # zero torque, operation disabled
                            echo_id=self.sync_id,  # host_time: when SYNC k was on the bus
                            guards=self._guards(cfg), rx_len=(fmt1.size, fmt2.size))
        self._unwrap = CountUnwrapper()
        self._enabled_at: int | None = None  # the first cycle whose TPDO reported operation enabled
        return spec, tx

    def _rows(self, done: int, ready: int, arrays: dict) -> tuple[CycleSamples | None, int, bool]:
        t1 = arrays["rx"][0, done:ready, :4].copy().view(TPDO1).ravel()
        t2 = arrays["rx"][1, done:ready, :8].copy().view(TPDO2).ravel()
        if self._check_rest and done == 0:
            self._check_rest = False
            moving = self._uncommanded(t1, t2)
            if moving:
                self._notes.append(moving)
        states = [c.state_of(int(w)) for w in t1["status"]]
        enabled = np.array([s is c.State.OPERATION_ENABLED for s in states])
        end = False
        if self._enabled_at is None:  # the enable handshake: a drive may report "enabled" a few SYNCs late
            lead = int(np.argmax(enabled)) if enabled.any() else len(enabled)
            if all(s in (c.State.SWITCHED_ON, c.State.READY) for s in states[:lead]):
                if done + lead > self.enable_cycles:
                    raise CommandRefusedError(
                        f"CANopen node {self.node_id} did not report operation enabled within "
                        f"{self.enable_cycles} cycles of the stream (statusword "
                        f"0x{int(t1['status'][0]):04X}: {states[0].value if states[0] else '?'}); "
                        f"give it longer with &enable_cycles=N in the device URL")
                enabled[:lead] = True  # samples before the drive enabled: kept, their status says so
            if lead < len(enabled):
                self._enabled_at = done + lead
        if not enabled.all():  # the drive left operation enabled: keep the sample that says so
            first = int(np.argmin(enabled))
            # ...unless it is switched on: only the end-of-stream SWITCH_ON gets there, so this TPDO
            # answers the end's own SYNC, and arrived as a cycle's because TPDOs were lost before it
            ours = c.state_of(int(t1["status"][first])) is c.State.SWITCHED_ON
            ready = done + first + (0 if ours and not self._estop_requested else 1)
            t1, t2 = t1[: ready - done], t2[: ready - done]
            end = True
        block = self._block(done, ready, t1, t2, arrays[HOST_TIME]) if ready > done else None
        return block, ready, end

    def _answer_slack(self, rate: float) -> float:
        return rate * 0.25  # a quarter second of SYNCs unanswered before the silence is timed

    def _silence_line(self, done: int, n: int) -> str:
        return f"CANopen node {self.node_id} stopped answering SYNC at cycle {done} (no TPDO for {self.timeout:g} s)"

    def _end_stream(self, cycle: CanCycle, done: int, n: int, allow_loss: bool) -> None:
        if done >= n:
            return
        arrays, sent = cycle.arrays, cycle.sent
        word = int(arrays["rx"][0, done - 1, :2].view("<u2")[0]) if done else 0
        last = c.state_of(word)
        if done and last is not c.State.OPERATION_ENABLED:
            if not self._emcy:
                self._emcy_event.wait(0.2)
            why = self.emcy_line() or f"statusword 0x{word:04X} ({last.value if last else '?'})"
            if self._estop_requested:
                why = f"quick stop (e-stop); {why}"
            raise DeviceFaultError(f"CANopen node {self.node_id} left operation enabled at cycle {done - 1}: {why}")
        lost = sent - done
        if lost and not allow_loss:
            raise SampleLossError(f"CANopen node {self.node_id}: {lost} of {sent} SYNCs got no TPDO back "
                                  "(TPDOs are matched to SYNCs in order: the samples after the first loss are shifted)")

    def _after_stream(self, finished: bool, fault: str) -> None:
        if finished and self._enabled_at:
            self._notes.append(f"CANopen node {self.node_id} reported operation enabled from cycle "
                               f"{self._enabled_at} of a stream on (the samples before it are kept; their "
                               f"drive_status says so)")
        if not finished and not self._closed:
            try:
                self.disarm()
            except DriverError:
                pass

    def _block(self, a: int, b: int, t1: np.ndarray, t2: np.ndarray, host_time: np.ndarray) -> CycleSamples:
        cal = self.calibration
        counts = self._unwrap(t2["position"])  # position units
        if self.position_factor != 1.0:  # to encoder increments, to the nearest one
            counts = np.rint(counts * self.position_factor).astype(np.int64)
        torque = c.permille_to_torque(t1["torque"], self.rated_torque) * cal.ratio
        torque_cmd = c.permille_to_torque(self._pm[a:b], self.rated_torque) * cal.ratio
        velocity = t2["velocity"] * (self.velocity_factor * 2 * math.pi / (self.counts_per_rev * cal.ratio))
        self._last_status, self._last_cmd = int(t1["status"][-1]), float(cal.current(torque_cmd[-1]))
        return CycleSamples(np.arange(a, b, dtype=np.int64), host_time[a:b].copy(), counts,
                            cal.current(torque_cmd), cal.current(torque), torque_cmd, torque,
                            cal.position(counts), velocity, self.config.sample_rate, t1["status"].copy())

    def _guard_frame(self) -> GuardFrame:
        """TPDO2: position and velocity actual (0x6064, 0x606C), int32, in the drive's units."""
        scale = self.counts_per_rev / (2 * math.pi)  # increments per rad at the motor
        return GuardFrame(1, "<i", 0, 4, scale / self.position_factor, scale / self.velocity_factor)

    def fault_line(self) -> str:
        return self.emcy_line()

    def fault_text(self) -> str:
        """The drive's fault in words: the latched EMCY, else its error code 0x603F."""
        if self._emcy:
            return self.emcy_line()
        try:
            code = int(self._read(c.ERROR_CODE, what="error code"))
        except DriverError:
            return "error code unreadable"
        return f"error code 0x{code:04X} {c.emcy_text(code)}" if code else "no error code"

    def state(self) -> str:
        word = self.statusword()
        now = c.state_of(word)
        return f"{now.value if now else 'unknown'} (statusword 0x{word:04X})"

    def faults(self) -> list[str]:
        """The drive's active fault: error code 0x603F and error register 0x1001 by name, and the EMCY this
        host saw ([] when the drive is not in fault and reports no error)."""
        out = []
        code = int(self._read(c.ERROR_CODE, what="error code")) if self._has(c.ERROR_CODE) else 0
        register = int(self._read(c.ERROR_REGISTER, what="error register")) if self._has(c.ERROR_REGISTER) else 0
        if code:
            out.append(f"0x603F error code 0x{code:04X} {c.emcy_text(code)} (error register 0x{register:02X})")
        elif self.power_state() in (c.State.FAULT, c.State.FAULT_REACTION):
            out.append(f"in fault, error code 0x603F = 0 (error register 0x{register:02X})")
        if self._emcy and not (code and self._emcy[-1][0] == code):
            out.append(self.emcy_line())
        return out

    def history(self) -> list[str]:
        """The drive's error history 0x1003, newest first, decoded (EMCY codes by name)."""
        if not self._has(c.ERROR_HISTORY, 0):
            return ["0x1003 error history: not in the EDS"]
        count = int(self._read(c.ERROR_HISTORY, 0, "number of errors"))
        entries = []
        for sub in range(1, min(count, 254) + 1):
            if not self._has(c.ERROR_HISTORY, sub):
                break
            value = int(self._read(c.ERROR_HISTORY, sub, "standard error field"))
            code = value & 0xFFFF
            info = f" (info 0x{value >> 16:04X})" if value >> 16 else ""
            entries.append(f"0x{code:04X} {c.emcy_text(code)}{info}")
        return [f"0x1003 error history ({count}, newest first): " + ("; ".join(entries) if entries else "empty")]

    def _drive_events(self) -> list[tuple[str, str]]:
        out = [("info", f"CANopen node {self.node_id}: {line}") for line in self._adopted + self._skipped]
        out += [("info", line) for line in dict.fromkeys(self._notes)]
        self._notes.clear()
        return out

    def _release(self) -> None:
        node = getattr(self, "node", None)
        if node is not None and (self._restore or self.config is not None):
            # leave the drive as found: heartbeat consumer and loss reaction back (a drive that applies 0x6007
            # in every state would otherwise fault once this host's heartbeat stops), and NMT pre-operational,
            # which also tells the next host that nobody owns it any more
            for (index, sub), value in self._restore.items():
                try:
                    self._write(index, value, sub, "restored on close")
                except DriverError:
                    pass
            try:
                node.nmt.state = "PRE-OPERATIONAL"
            except Exception:  # closing must release the bus whatever the bus says
                pass
        if self._heartbeat_task is not None:
            self._heartbeat_task.stop()
        self.network.disconnect()


_STRUCT = {8: "b", 16: "h", 32: "i"}


def _pdo_format(pdo_map) -> struct.Struct:
    """A struct for a PDO whose variables are byte-aligned integers (the layouts this driver maps)."""
    fmt = "<"
    for var in pdo_map.map:
        code = _STRUCT[var.length]
        fmt += code.upper() if var.od.data_type in (5, 6, 7) else code  # UNSIGNED8/16/32
    return struct.Struct(fmt)


def _check_eds(eds: str, node_id: int):
    """Load the EDS and check, before anything is sent, that it has the objects the host uses with the types
    it maps them as; one line naming the object otherwise. Returns the object dictionary."""
    import canopen

    try:
        od = canopen.import_od(eds, node_id)
    except Exception as exc:  # the parser raises many types for a broken file
        raise ConfigError(f"EDS {eds} cannot be read: {' '.join(str(exc).split())}") from exc
    missing = [f"0x{i:04X}" for i in (*PDO_TYPES, *REQUIRED) if i not in od]
    if missing:
        raise ConfigError(f"EDS {eds} lacks object(s) {', '.join(missing)} that the host needs (CiA 402)")
    for index, (code, name) in PDO_TYPES.items():
        declared = od[index].data_type
        if declared != code:
            raise ConfigError(f"EDS {eds} declares 0x{index:04X} ({od[index].name}) as "
                              f"{DATA_TYPE_NAMES.get(declared, hex(declared))}; CiA 402 and this host's PDO "
                              f"mapping take it as {name}")
    return od
