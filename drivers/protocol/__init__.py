"""The hilbench wire protocol (version :data:`PROTOCOL_VERSION`): pure encode/decode, no I/O.

Build a message, then send it: ``link.send(Arm())``. Serial links frame messages with
:func:`encode_frame` / :class:`FrameDecoder`, CAN links with :func:`encode_can` / :class:`CanReassembler`.
Specified in ``docs/protocol.md``. The only exception decoding raises is :class:`ProtocolError`.
"""

from hilbench.drivers.errors import ProtocolError
from hilbench.drivers.protocol.can_framing import (
    DEVICE_TO_HOST,
    HOST_TO_DEVICE,
    CanReassembler,
    can_id,
    encode_can,
    max_payload,
    split_can_id,
)
from hilbench.drivers.protocol.messages import (
    FRAME_VERSIONS,
    MESSAGE_CLASSES,
    POSITION_GAINS,
    PROTOCOL_VERSION,
    SAMPLE_RATES,
    Arm,
    ClearFaults,
    Config,
    Disarm,
    EStop,
    Fault,
    GetConfig,
    GetIdentity,
    Heartbeat,
    Identity,
    Message,
    Mode,
    MsgType,
    Reply,
    Result,
    SampleBlock,
    SampleStatus,
    Sensor,
    SetpointBlock,
    State,
    Status,
    decode_message,
    describe_faults,
    encode_message,
    make_setpoint_blocks,
)
from hilbench.drivers.protocol.serial_framing import MAX_FRAME_BYTES, FrameDecoder, decode_frame, encode_frame

__all__ = [
    "PROTOCOL_VERSION", "FRAME_VERSIONS", "POSITION_GAINS", "SAMPLE_RATES", "MAX_FRAME_BYTES",
    "MESSAGE_CLASSES",
    "ProtocolError",
    "Message", "MsgType", "Mode", "State", "Fault", "SampleStatus", "Sensor", "Result",
    "Arm", "ClearFaults", "Config", "Disarm", "EStop", "GetConfig", "GetIdentity", "Heartbeat", "Identity",
    "Reply", "SampleBlock", "SetpointBlock", "Status",
    "decode_message", "encode_message", "describe_faults", "make_setpoint_blocks",
    "encode_frame", "decode_frame", "FrameDecoder",
    "HOST_TO_DEVICE", "DEVICE_TO_HOST", "can_id", "split_can_id", "encode_can", "max_payload",
    "CanReassembler",
]
