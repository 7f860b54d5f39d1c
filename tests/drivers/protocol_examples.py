"""Canonical messages of protocol version 1, shared by the golden-frame tests and their generator."""

import math

import numpy as np

from hilbench.drivers import protocol as p


def canonical_messages() -> dict[str, p.Message]:
    """One message of every type, with values that exercise every field (name -> message)."""
    return {
        "estop": p.EStop(),
        "disarm": p.Disarm(),
        "arm": p.Arm(),
        "clear_faults": p.ClearFaults(),
        "get_config": p.GetConfig(),
        "get_identity": p.GetIdentity(),
        "identity": p.Identity("HB-AMP-1", "SIM-0001", "1.0.0+sim", 1, 8192, 256),
        "config": p.Config(10000, p.Mode.VELOCITY, 4.5, 150.0, -math.inf, 12.5, 0.1, 0.0452, 16384, 3.0),
        "heartbeat": p.Heartbeat(0xDEADBEEF),
        "status": p.Status(7, p.State.STREAMING, p.Fault.WATCHDOG | p.Fault.OVER_SPEED, 600000, 8000, 600192,
                           599000, 1001, 0.0, 3, 2, 5000, 6000),
        "reply": p.Reply(p.MsgType.ARM, p.Result.FAULT_LATCHED, p.Fault.ESTOP),
        "setpoints": p.SetpointBlock(41, np.array([0.0, -1.5, 2.25, 1e-3], dtype=np.float32), end=True),
        "samples": p.SampleBlock(3, 2**33 + 5, 100, 2**33 + 9, 0, p.State.STREAMING,
                                 np.array([0, -1, 2**31 - 1, -(2**31)], dtype=np.int32),
                                 np.array([0.5, 0.0, -0.25, 1.0], dtype=np.float32),
                                 np.array([0.49, 0.01, -0.26, 0.99], dtype=np.float32),
                                 np.array([1, 1, 3, 5], dtype=np.uint16)),
    }


if __name__ == "__main__":  # regenerate tests/data/protocol/*.hex (only when the protocol version changes)
    from pathlib import Path

    out = Path(__file__).resolve().parents[1] / "data" / "protocol"
    for name, msg in canonical_messages().items():
        (out / f"v{p.PROTOCOL_VERSION}_{name}.hex").write_text(p.encode_frame(msg).hex() + "\n")
