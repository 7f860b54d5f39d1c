"""CiA 402 (drives and motion control) definitions shared by the host driver and the simulated drive.

Pure functions and constants, no I/O: the power state machine (statusword decoding, controlword commands),
the object indices the bench uses, per-mille torque scaling and the text of EMCY error codes (CiA 301 and
CiA 402 tables, the codes a torque-mode bench meets).
"""

from __future__ import annotations

import enum
import math

import numpy as np

# Object indices (CiA 301 communication, CiA 402 profile)
DEVICE_TYPE = 0x1000
ERROR_REGISTER = 0x1001
ERROR_HISTORY = 0x1003        # pre-defined error field: sub 0 count, sub 1.. newest first (code | info << 16)
SYNC_COB_ID = 0x1005          # bits 0..10: the SYNC's CAN id (default 0x80)
COMM_CYCLE_PERIOD = 0x1006    # us
DEVICE_NAME = 0x1008
EMCY_COB_ID = 0x1014          # bits 0..10: the EMCY's CAN id (default 0x80 + node); bit 31 set: no EMCY
CONSUMER_HEARTBEAT = 0x1016   # sub 1: (node << 16) | time_ms
PRODUCER_HEARTBEAT = 0x1017   # ms
IDENTITY = 0x1018
ABORT_CONNECTION = 0x6007     # reaction to lost communication (heartbeat or SYNC)
ERROR_CODE = 0x603F
CONTROLWORD = 0x6040
STATUSWORD = 0x6041
QUICK_STOP_OPTION = 0x605A
MODES_OF_OPERATION = 0x6060
MODES_DISPLAY = 0x6061
POSITION_ACTUAL = 0x6064      # increments
VELOCITY_ACTUAL = 0x606C      # increments/s
TARGET_TORQUE = 0x6071        # per mille of rated torque
MAX_TORQUE = 0x6072           # per mille of rated torque
RATED_CURRENT = 0x6075        # mA
RATED_TORQUE = 0x6076         # mN*m
TORQUE_ACTUAL = 0x6077        # per mille of rated torque
SOFTWARE_POSITION_LIMIT = 0x607D  # sub 1 min, sub 2 max, INTEGER32 increments
MAX_MOTOR_SPEED = 0x6080      # UNSIGNED32, rpm
ENCODER_RESOLUTION = 0x608F   # sub 1 increments per sub 2 motor revolutions
GEAR_RATIO = 0x6091           # sub 1 motor revolutions per sub 2 shaft revolutions
FEED_CONSTANT = 0x6092        # sub 1 feed (position units) per sub 2 shaft revolutions
POSITION_FACTOR = 0x6093      # sub 1 numerator / sub 2 divisor: increments per position unit
VELOCITY_ENCODER_FACTOR = 0x6094  # sub 1 numerator / sub 2 divisor: increments/s per velocity unit
INTERPOLATION_PERIOD = 0x60C2  # sub 1 value (UNSIGNED8), sub 2 index (INTEGER8): value * 10**index s
SUPPORTED_MODES = 0x6502

PROFILE_402 = 402
MODE_CST = 10                 # cyclic synchronous torque
CST_BIT = 1 << 9              # 0x6502 bit for mode 10

#: 0x6007 values: what the drive does when it loses the host (heartbeat or SYNC)
ABORT_ACTIONS = {0: "no action", 1: "fault", 2: "disable voltage", 3: "quick stop"}


class State(enum.Enum):
    NOT_READY = "not ready to switch on"
    SWITCH_ON_DISABLED = "switch on disabled"
    READY = "ready to switch on"
    SWITCHED_ON = "switched on"
    OPERATION_ENABLED = "operation enabled"
    QUICK_STOP = "quick stop active"
    FAULT_REACTION = "fault reaction active"
    FAULT = "fault"


# (mask, value) of the statusword for each state, CiA 402 table
_STATUS_PATTERNS = (
    (0x4F, 0x00, State.NOT_READY),
    (0x4F, 0x40, State.SWITCH_ON_DISABLED),
    (0x6F, 0x21, State.READY),
    (0x6F, 0x23, State.SWITCHED_ON),
    (0x6F, 0x27, State.OPERATION_ENABLED),
    (0x6F, 0x07, State.QUICK_STOP),
    (0x4F, 0x0F, State.FAULT_REACTION),
    (0x4F, 0x08, State.FAULT),
)
STATUS_BITS = {
    State.NOT_READY: 0x00, State.SWITCH_ON_DISABLED: 0x40, State.READY: 0x21, State.SWITCHED_ON: 0x23,
    State.OPERATION_ENABLED: 0x27, State.QUICK_STOP: 0x07, State.FAULT_REACTION: 0x0F, State.FAULT: 0x08,
}
VOLTAGE_ENABLED = 0x10
REMOTE = 0x200


def state_of(statusword: int) -> State | None:
    """The power state a statusword reports (None for a pattern the table does not have)."""
    for mask, value, state in _STATUS_PATTERNS:
        if statusword & mask == value:
            return state
    return None


class Command(enum.IntEnum):
    """Controlword values of the state-machine commands (bit 7 = fault reset, on its rising edge)."""

    SHUTDOWN = 0x0006
    SWITCH_ON = 0x0007
    ENABLE_OPERATION = 0x000F
    DISABLE_VOLTAGE = 0x0000
    QUICK_STOP = 0x0002
    FAULT_RESET = 0x0080


def command_of(controlword: int) -> Command | None:
    """Decode a controlword into its command (CiA 402 table; bit 7 first)."""
    if controlword & 0x80:
        return Command.FAULT_RESET
    if controlword & 0x02 == 0:
        return Command.DISABLE_VOLTAGE
    if controlword & 0x06 == 0x02:
        return Command.QUICK_STOP
    if controlword & 0x07 == 0x06:
        return Command.SHUTDOWN
    if controlword & 0x0F == 0x07:
        return Command.SWITCH_ON
    if controlword & 0x0F == 0x0F:
        return Command.ENABLE_OPERATION
    return None


def next_state(state: State, command: Command | None) -> State:
    """The drive's state after ``command`` (the device side of the CiA 402 power state machine).

    Quick stop in torque mode zeroes the torque at once, so quick stop active ends in switch on disabled
    as soon as the drive has applied it (the simulated drive calls this twice); a fault reset leaves
    fault for switch on disabled.
    """
    if command is None:
        return state
    if state is State.FAULT:
        return State.SWITCH_ON_DISABLED if command is Command.FAULT_RESET else state
    if state in (State.FAULT_REACTION, State.NOT_READY):
        return state
    if command is Command.DISABLE_VOLTAGE:
        return State.SWITCH_ON_DISABLED
    if command is Command.QUICK_STOP:
        return State.QUICK_STOP if state is State.OPERATION_ENABLED else State.SWITCH_ON_DISABLED
    if state is State.QUICK_STOP:
        return state
    table = {
        (State.SWITCH_ON_DISABLED, Command.SHUTDOWN): State.READY,
        (State.READY, Command.SHUTDOWN): State.READY,
        (State.READY, Command.SWITCH_ON): State.SWITCHED_ON,
        (State.READY, Command.ENABLE_OPERATION): State.OPERATION_ENABLED,
        (State.SWITCHED_ON, Command.SHUTDOWN): State.READY,
        (State.SWITCHED_ON, Command.SWITCH_ON): State.SWITCHED_ON,
        (State.SWITCHED_ON, Command.ENABLE_OPERATION): State.OPERATION_ENABLED,
        (State.OPERATION_ENABLED, Command.SHUTDOWN): State.READY,
        (State.OPERATION_ENABLED, Command.SWITCH_ON): State.SWITCHED_ON,
        (State.OPERATION_ENABLED, Command.ENABLE_OPERATION): State.OPERATION_ENABLED,
    }
    return table.get((state, command), state)


def torque_to_permille(torque: np.ndarray, rated_torque: float) -> np.ndarray:
    """Torque in N*m to the INTEGER16 per-mille of the rated torque (N*m) that 0x6071 carries (rounded)."""
    pm = np.rint(np.asarray(torque, dtype=np.float64) * (1000.0 / rated_torque))
    if np.any(np.abs(pm) > 32767):
        raise ValueError(f"torque beyond 32.767 x the rated torque {rated_torque} N*m cannot be sent in 0x6071")
    return pm.astype(np.int16)


def permille_to_torque(pm: np.ndarray, rated_torque: float) -> np.ndarray:
    """Per-mille of the rated torque (N*m) to N*m."""
    return np.asarray(pm, dtype=np.float64) * (rated_torque / 1000.0)


def max_torque_permille(current_limit: float, torque_constant: float, rated_torque: float) -> int:
    """0x6072 (per mille, UNSIGNED16) from the host's current limit (A) and torque constant (N*m/A)."""
    value = math.floor(current_limit * torque_constant / rated_torque * 1000.0)
    return int(min(max(value, 0), 65535))


INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1


def position_limit_increments(position_min: float, position_max: float, counts_per_rev: int) -> tuple[int, int]:
    """0x607D sub 1 and 2 (INTEGER32 increments) from a position window in rad at the motor shaft: rounded
    outwards (the drive's limit is never tighter than the host's, which checks the exact window), an
    infinite end or one beyond INTEGER32 is the type's end (no limit there)."""
    scale = counts_per_rev / (2 * math.pi)
    low = math.floor(position_min * scale) if math.isfinite(position_min) else INT32_MIN
    high = math.ceil(position_max * scale) if math.isfinite(position_max) else INT32_MAX
    return max(low, INT32_MIN), min(high, INT32_MAX)


def max_motor_speed_rpm(velocity_limit: float) -> int:
    """0x6080 (UNSIGNED32, rpm) from a velocity limit in rad/s at the motor shaft, rounded up."""
    return int(min(math.ceil(velocity_limit * 60.0 / (2 * math.pi)), 2**32 - 1))


def interpolation_period(period: float) -> tuple[int, int]:
    """0x60C2 sub 1 and sub 2 for a cycle period in s: the value (1..255) and the power of ten (-128..63) with
    value * 10**index == period, the index as large as it can be (1 ms: (1, -3); 0.5 ms: (5, -4))."""
    for index in range(2, -10, -1):
        value = round(period / 10.0**index)
        if 1 <= value <= 255 and math.isclose(value * 10.0**index, period, rel_tol=1e-9):
            return value, index
    raise ValueError(f"a cycle period of {period} s has no 0x60C2 form (value 1..255 times a power of ten)")


def increments_per_unit(encoder: float, gear: tuple[int, int] | None = None, feed: tuple[int, int] | None = None,
                        factor: tuple[int, int] | None = None) -> float:
    """Encoder increments per position unit of 0x6064 (CiA 402 factor group).

    ``encoder``: increments per motor revolution (0x608F); ``gear``: motor revolutions per shaft revolution
    (0x6091 sub 1, sub 2); ``feed``: position units per shaft revolution (0x6092 sub 1, sub 2); ``factor``: the
    position factor 0x6093 (numerator, divisor), which states the ratio directly and takes precedence. Without
    them a position unit is an increment."""
    if factor is not None:
        return factor[0] / factor[1]
    if gear is not None and feed is not None:
        return encoder * (gear[0] / gear[1]) / (feed[0] / feed[1])
    return 1.0


#: Error codes (CiA 301 table and CiA 402 annex): code -> text
EMCY_TEXT = {
    0x0000: "error reset or no error",
    0x1000: "generic error",
    0x2310: "continuous over-current (device output side)",
    0x2320: "short circuit at outputs",
    0x3210: "DC link over-voltage",
    0x3220: "DC link under-voltage",
    0x4210: "excess temperature device",
    0x4310: "excess temperature drive",
    0x5530: "data storage (non-volatile memory)",
    0x6320: "parameter error",
    0x7121: "motor blocked",
    0x7305: "incremental sensor 1 fault",
    0x8110: "CAN overrun (objects lost)",
    0x8120: "CAN in error passive mode",
    0x8130: "life guard error or heartbeat error",
    0x8140: "recovered from bus off",
    0x8250: "RPDO timeout",
    0x8400: "velocity speed controller (over-speed)",
    0x8611: "following error",
    0x8612: "reference limit (software position limit)",
    0xFF00: "device specific",
}
_CLASS_TEXT = {0x1: "generic", 0x2: "current", 0x3: "voltage", 0x4: "temperature", 0x5: "device hardware",
               0x6: "device software", 0x7: "additional modules", 0x8: "monitoring", 0x9: "external error",
               0xF: "additional functions"}


def emcy_text(code: int) -> str:
    """The text of an EMCY error code: the exact entry, else its class (first hex digit)."""
    if code in EMCY_TEXT:
        return EMCY_TEXT[code]
    if code >> 8 == 0xFF:
        return "device specific"
    return f"{_CLASS_TEXT.get(code >> 12, 'unknown')} error (code not in the CiA 301/402 tables)"
