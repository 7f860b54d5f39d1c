"""A second CANopen stack for the tests: a CiA 301 slave with a CiA 402 drive in Cyclic Synchronous Torque,
written directly over python-can frames from the standards' texts.

It shares no code with ``hilbench.firmware_sim`` (whose drive is a ``canopen.LocalNode``), with
``hilbench.drivers`` or with the ``canopen`` package: its object dictionary, SDO server (expedited download,
expedited and segmented upload), NMT slave, heartbeat producer, PDO mapping and power state machine are its own,
so the suite no longer checks the driver only against the stack it was written with. Only the EDS the host loads
describes it (the simulated drive's file: a description, not code); objects the EDS names and this drive lacks
(0x607D, 0x6080, 0x1003) are answered with SDO abort 0x06020000, as a real drive would.

The plant is a rigid rotor with viscous friction, J dw/dt = tau - b w, integrated exactly over each cycle with the
torque held (zero-order hold). At SYNC k it advances over the cycle that ends, samples (position, velocity, torque
actual, statusword), sends its TPDOs, and holds the torque received before that SYNC until the next one. Every
sample it sends is kept in ``trace``: the oracle the run file is compared with.
"""

from __future__ import annotations

import math
import struct
import threading
import time

import can

# sizes (bytes, signed) of the objects this drive has; (index, sub) -> value
_U8, _U16, _U32, _I8, _I16, _I32 = (1, False), (2, False), (4, False), (1, True), (2, True), (4, True)
_OPERATION_ENABLED, _SWITCHED_ON, _READY, _DISABLED, _FAULT = 0x0027, 0x0023, 0x0021, 0x0040, 0x0008


class SecondStackDrive:
    """A CiA 402 drive at ``node`` on python-can ``virtual`` bus ``channel``; ``close()`` ends it."""

    def __init__(self, channel: str, node: int, rated_torque_mnm: int = 500, encoder: int = 1 << 20,
                 inertia: float = 2e-4, viscous: float = 1e-3, name: str = "SECOND-STACK-402") -> None:
        self.node, self.encoder = node, encoder
        self.inertia, self.viscous = inertia, viscous
        self.rated = rated_torque_mnm / 1000.0
        self.name = name.encode()
        self.size: dict[tuple[int, int], tuple[int, bool]] = {}
        self.od: dict[tuple[int, int], int] = {}
        for key, size, value in [
            ((0x1000, 0), _U32, 0x00020192), ((0x1001, 0), _U8, 0), ((0x1005, 0), _U32, 0x80),
            ((0x1006, 0), _U32, 1000), ((0x1014, 0), _U32, 0x80 + node), ((0x1017, 0), _U16, 0),
            ((0x1016, 0), _U8, 1), ((0x1016, 1), _U32, 0), ((0x1018, 0), _U8, 4), ((0x1018, 1), _U32, 0x5EC0),
            ((0x1018, 2), _U32, 402), ((0x1018, 3), _U32, 1), ((0x1018, 4), _U32, 7), ((0x6007, 0), _I16, 0),
            ((0x603F, 0), _U16, 0), ((0x6040, 0), _U16, 0), ((0x6041, 0), _U16, _DISABLED),
            ((0x6060, 0), _I8, 0), ((0x6061, 0), _I8, 0), ((0x6064, 0), _I32, 0), ((0x606C, 0), _I32, 0),
            ((0x6071, 0), _I16, 0), ((0x6072, 0), _U16, 3000), ((0x6076, 0), _U32, rated_torque_mnm),
            ((0x6077, 0), _I16, 0), ((0x608F, 0), _U8, 2), ((0x608F, 1), _U32, encoder), ((0x608F, 2), _U32, 1),
            ((0x60C2, 0), _U8, 2), ((0x60C2, 1), _U8, 1), ((0x60C2, 2), _I8, -3), ((0x6502, 0), _U32, 1 << 9),
        ]:
            self.size[key], self.od[key] = size, value
        for k in range(2):  # RPDO1..2 and TPDO1..2: communication and mapping parameters
            for comm, mapping, cob in ((0x1400 + k, 0x1600 + k, 0x200 + 0x100 * k + node),
                                       (0x1800 + k, 0x1A00 + k, 0x180 + 0x100 * k + node)):
                for sub, size, value in ((0, _U8, 6), (1, _U32, cob | 1 << 31), (2, _U8, 255), (3, _U16, 0),
                                         (5, _U16, 0), (6, _U8, 0)):
                    self.size[(comm, sub)], self.od[(comm, sub)] = size, value
                self.size[(mapping, 0)], self.od[(mapping, 0)] = _U8, 0
                for sub in range(1, 9):
                    self.size[(mapping, sub)], self.od[(mapping, sub)] = _U32, 0
        self.nmt = 0x7F  # pre-operational
        self.theta = self.omega = 0.0
        self.held = 0.0  # N*m held over the cycle that runs
        self.rpdo: dict[int, bytes] = {}  # received since the last SYNC, by RPDO number
        self.trace: list[tuple[int, int, int, int]] = []  # per SYNC: position inc, velocity inc/s, torque, status
        self._upload: tuple[bytes, int] | None = None  # segmented upload in progress: data, toggle
        self._stop = threading.Event()
        self.bus = can.Bus(interface="virtual", channel=channel)
        self._send(0x700 + node, b"\x00")  # boot-up
        self._threads = [threading.Thread(target=self._serve, daemon=True),
                         threading.Thread(target=self._heartbeat, daemon=True)]
        for t in self._threads:
            t.start()

    # ------------------------------------------------------------------ frames
    def _send(self, can_id: int, data: bytes) -> None:
        self.bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))

    def _serve(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.05)
            if msg is None or msg.is_extended_id:
                continue
            cid, data = msg.arbitration_id, bytes(msg.data)
            if cid == 0 and len(data) == 2 and data[1] in (0, self.node):
                self._nmt(data[0])
            elif cid == 0x600 + self.node and len(data) == 8:
                self._sdo(data)
            elif cid == self.od[(0x1005, 0)] & 0x7FF:
                self._sync()
            else:
                for k in range(2):
                    cob = self.od[(0x1400 + k, 1)]
                    if not cob >> 31 and cid == cob & 0x7FF:
                        self.rpdo[k] = data

    def _heartbeat(self) -> None:
        while not self._stop.wait(max(self.od[(0x1017, 0)], 20) / 1000.0):
            if self.od[(0x1017, 0)]:
                self._send(0x700 + self.node, bytes([self.nmt]))

    def _nmt(self, command: int) -> None:
        if command == 0x01:
            self.nmt = 0x05
        elif command == 0x02:
            self.nmt = 0x04
        elif command == 0x80:
            self.nmt = 0x7F
        elif command in (0x81, 0x82):
            self.nmt = 0x7F
            self._send(0x700 + self.node, b"\x00")
        if self.nmt != 0x05 and self.od[(0x6041, 0)] & 0x6F == _OPERATION_ENABLED:
            self._status(_DISABLED)  # leaving operational disables the drive

    # ------------------------------------------------------------------ SDO server (CiA 301 7.2.4)
    def _abort(self, index: int, sub: int, code: int) -> None:
        self._send(0x580 + self.node, struct.pack("<BHBI", 0x80, index, sub, code))

    def _sdo(self, data: bytes) -> None:
        ccs = data[0] >> 5
        if ccs == 3 and self._upload is not None:  # upload segment
            rest, toggle = self._upload
            if (data[0] >> 4) & 1 != toggle:
                self._upload = None
                self._abort(0, 0, 0x05030000)  # toggle bit not alternated
                return
            chunk, rest = rest[:7], rest[7:]
            last = not rest
            self._send(0x580 + self.node, bytes([toggle << 4 | (7 - len(chunk)) << 1 | last]) + chunk.ljust(7, b"\0"))
            self._upload = None if last else (rest, toggle ^ 1)
            return
        if ccs == 4:  # abort from the client
            self._upload = None
            return
        index, sub = struct.unpack_from("<HB", data, 1)
        if ccs == 2:  # initiate upload
            if (index, sub) == (0x1008, 0):
                self._upload = (self.name, 0)
                self._send(0x580 + self.node, struct.pack("<BHBI", 0x41, index, sub, len(self.name)))
                return
            if (index, sub) not in self.od:
                self._abort(index, sub, 0x06090011 if any(i == index for i, _ in self.od) else 0x06020000)
                return
            size, signed = self.size[(index, sub)]
            raw = self._value(index, sub).to_bytes(size, "little", signed=signed)
            self._send(0x580 + self.node, bytes([0x43 | (4 - size) << 2]) + data[1:4] + raw.ljust(4, b"\0"))
        elif ccs == 1:  # initiate download: expedited only (every object here is 4 bytes or less)
            if (index, sub) not in self.od:
                self._abort(index, sub, 0x06090011 if any(i == index for i, _ in self.od) else 0x06020000)
                return
            if not data[0] & 0x02:
                self._abort(index, sub, 0x05040001)  # command specifier not valid here
                return
            size, signed = self.size[(index, sub)]
            length = 4 - (data[0] >> 2 & 3) if data[0] & 0x01 else size
            value = int.from_bytes(data[4:4 + min(length, size)], "little", signed=signed)
            if index in (0x1000, 0x1018, 0x6041, 0x6061, 0x6064, 0x606C, 0x6077, 0x6502, 0x6076, 0x1014):
                self._abort(index, sub, 0x06010002)  # read only
                return
            self._write(index, sub, value)
            self._send(0x580 + self.node, struct.pack("<BHBI", 0x60, index, sub, 0))
        else:
            self._abort(index, sub, 0x05040001)

    def _value(self, index: int, sub: int) -> int:
        return self.od[(index, sub)]

    def _write(self, index: int, sub: int, value: int) -> None:
        self.od[(index, sub)] = value
        if index == 0x6040:
            self._controlword(value, at_once=True)
        elif index == 0x6060:
            self.od[(0x6061, 0)] = value if value == 10 else self.od[(0x6061, 0)]  # CST only

    # ------------------------------------------------------------------ CiA 402 power state machine
    def _status(self, bits: int) -> None:
        self.od[(0x6041, 0)] = bits | 0x0200 | (0x10 if bits in (_READY, _SWITCHED_ON, _OPERATION_ENABLED) else 0)

    def _controlword(self, cw: int, at_once: bool) -> None:
        now = self.od[(0x6041, 0)] & 0x6F
        if now & 0x4F == _FAULT:
            if cw & 0x80:
                self.od[(0x603F, 0)] = 0
                self._status(_DISABLED)
            return
        if not cw & 0x02:  # disable voltage
            self._status(_DISABLED)
        elif cw & 0x06 == 0x02:  # quick stop: in torque mode the torque is zero at once
            self._status(_DISABLED)
        elif cw & 0x87 == 0x06 and now in (_DISABLED & 0x6F, _SWITCHED_ON, _OPERATION_ENABLED):
            self._status(_READY)
        elif cw & 0x8F == 0x07 and now in (_READY, _OPERATION_ENABLED):
            self._status(_SWITCHED_ON)
        elif cw & 0x8F == 0x0F and now in (_READY, _SWITCHED_ON) and self.od[(0x6061, 0)] == 10:
            self._status(_OPERATION_ENABLED)
            if at_once:  # enabled between SYNCs: CST applies 0x6071 from now on
                self.held = self.od[(0x6071, 0)] / 1000.0 * self.rated
        if self.od[(0x6041, 0)] & 0x6F != _OPERATION_ENABLED:
            self.held = 0.0

    # ------------------------------------------------------------------ SYNC: apply, advance, sample, answer
    def _sync(self) -> None:
        if self.nmt != 0x05:
            return
        dt = self.od[(0x1006, 0)] * 1e-6 or 1e-3
        j, b, tau, w0 = self.inertia, self.viscous, self.held, self.omega
        a = math.exp(-b * dt / j)
        self.omega = a * w0 + (1 - a) * tau / b
        self.theta += tau / b * dt + (w0 - tau / b) * (1 - a) * j / b
        position = round(self.theta * self.encoder / (2 * math.pi))
        velocity = round(self.omega * self.encoder / (2 * math.pi))
        torque = round(self.held / self.rated * 1000.0)
        wrapped = (position + 2**31) % 2**32 - 2**31
        self.od[(0x6064, 0)], self.od[(0x606C, 0)], self.od[(0x6077, 0)] = wrapped, velocity, torque
        for k, data in sorted(self.rpdo.items()):  # what arrived before this SYNC applies from now on
            self._apply_rpdo(k, data)
        self.rpdo.clear()
        status = self.od[(0x6041, 0)]
        self.trace.append((position, velocity, torque, status))
        for k in range(2):
            cob, kind = self.od[(0x1800 + k, 1)], self.od[(0x1800 + k, 2)]
            if not cob >> 31 and 1 <= kind <= 240:
                self._send(cob & 0x7FF, self._pack(0x1A00 + k))

    def _entries(self, mapping: int) -> list[tuple[int, int, int]]:
        out = []
        for sub in range(1, self.od[(mapping, 0)] + 1):
            entry = self.od[(mapping, sub)]
            out.append((entry >> 16, entry >> 8 & 0xFF, (entry & 0xFF) // 8))
        return out

    def _pack(self, mapping: int) -> bytes:
        return b"".join(self.od[(i, s)].to_bytes(n, "little", signed=self.size[(i, s)][1])
                        for i, s, n in self._entries(mapping))

    def _apply_rpdo(self, k: int, data: bytes) -> None:
        offset, cw = 0, None
        for index, sub, n in self._entries(0x1600 + k):
            value = int.from_bytes(data[offset:offset + n], "little", signed=self.size[(index, sub)][1])
            offset += n
            if index == 0x6040:
                cw = value
            self.od[(index, sub)] = value
        if cw is not None:
            self._controlword(cw, at_once=False)
        if self.od[(0x6041, 0)] & 0x6F == _OPERATION_ENABLED:
            self.held = self.od[(0x6071, 0)] / 1000.0 * self.rated

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(1.0)
        time.sleep(0.01)
        self.bus.shutdown()
