"""ODrive's CAN Simple protocol: message ids, encodings and axis errors (pure functions, no I/O).

Shared by the host driver and the simulated ODrive. A frame's 11-bit id is ``node << 5 | command``; payloads
are little endian. Units as ODrive's: positions in turns, velocities in turns/s, torques in N*m, currents in A.
"""

from __future__ import annotations

import enum
import struct

from hilbench.drivers.errors import ProtocolError


class Cmd(enum.IntEnum):
    HEARTBEAT = 0x01            # axis -> host: axis error u32, axis state u8, procedure result u8, traj done u8
    ESTOP = 0x02
    RX_SDO = 0x04               # host -> axis: opcode u8 (0 read, 1 write), endpoint id u16, reserved u8, value
    TX_SDO = 0x05               # axis -> host: reserved u8, endpoint id u16, reserved u8, value
    SET_AXIS_STATE = 0x07       # u32
    GET_ENCODER_ESTIMATES = 0x09  # axis -> host, cyclic: position f32 (turns), velocity f32 (turns/s)
    SET_CONTROLLER_MODE = 0x0B  # control mode u32, input mode u32
    SET_INPUT_TORQUE = 0x0E     # f32, N*m
    SET_LIMITS = 0x0F           # velocity limit f32 (turns/s), current limit f32 (A)
    CLEAR_ERRORS = 0x18
    GET_TORQUES = 0x1C          # axis -> host, cyclic: torque target f32, torque estimate f32 (N*m)


#: Commands only a host sends to an axis: what feeds the axis's watchdog, and what tells another host is there.
#: The rest (heartbeat, TxSdo, the cyclic estimates) are the axis's own frames, which a bus that hands a sender
#: its frames back (udp_multicast, SocketCAN with loopback) also delivers to the axis itself.
HOST_COMMANDS = frozenset({Cmd.ESTOP, Cmd.RX_SDO, Cmd.SET_AXIS_STATE, Cmd.SET_CONTROLLER_MODE, Cmd.SET_INPUT_TORQUE,
                           Cmd.SET_LIMITS, Cmd.CLEAR_ERRORS})


class AxisState(enum.IntEnum):
    IDLE = 1
    CLOSED_LOOP_CONTROL = 8


CONTROL_MODE_TORQUE = 1
INPUT_MODE_PASSTHROUGH = 1

#: Axis error bits (ODrive firmware 0.5 enums)
AXIS_ERRORS = {
    0x00000001: "invalid state",
    0x00000040: "motor failed",
    0x00000100: "encoder failed",
    0x00000200: "controller failed (over-speed: |vel| above vel_limit x vel_limit_tolerance)",
    0x00000800: "watchdog timer expired",
    0x00004000: "e-stop requested",
    0x00040000: "over temperature",
}
WATCHDOG_TIMER_EXPIRED = 0x00000800
ESTOP_REQUESTED = 0x00004000


def describe_errors(error: int) -> str:
    if not error:
        return "no error"
    names = [text for bit, text in AXIS_ERRORS.items() if error & bit]
    rest = error & ~sum(AXIS_ERRORS)
    if rest:
        names.append(f"0x{rest:08X}")
    return ", ".join(names)


def can_id(node: int, cmd: int) -> int:
    return (node << 5) | int(cmd)


def split_id(arbitration_id: int) -> tuple[int, int]:
    """(node, command) of a frame id."""
    return arbitration_id >> 5, arbitration_id & 0x1F


HEARTBEAT = struct.Struct("<IBBBx")
FLOAT = struct.Struct("<f")
FLOAT2 = struct.Struct("<ff")
U32 = struct.Struct("<I")
U32x2 = struct.Struct("<II")
SDO = struct.Struct("<BHBI")


def unpack(layout: struct.Struct, data: bytes, what: str) -> tuple:
    """The fields of ``layout`` at the start of ``data`` (an ODrive frame carries them first; a classic frame may be
    padded to 8 bytes). Raises only :class:`ProtocolError`, for a frame too short to hold them."""
    if len(data) < layout.size:
        raise ProtocolError(f"ODrive {what}: {len(data)} data bytes, needs {layout.size}")
    return layout.unpack_from(data)
