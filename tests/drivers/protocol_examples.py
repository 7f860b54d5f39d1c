"""Canonical messages of protocol versions 1, 2 and 3, shared by the golden-frame tests (Python and the C
core's firmware/tests/test_core.c) and their generator."""

import math

import numpy as np

from hilbench.drivers import protocol as p

#: Position-loop gains of the canonical v2 CONFIG (every field distinct, exact in binary).
V2_GAINS = {"position_kp": 2500.0, "position_ki": 125000.0, "position_kd": 4.5, "position_i_limit": 3.25,
            "position_d_cutoff": 250.0}


def canonical_messages(version: int = p.PROTOCOL_VERSION) -> dict[str, p.Message]:
    """One message of every type, with values that exercise every field (name -> message), as a host and a
    device of protocol ``version`` (1, 2 or 3) exchange them. v2 adds a position-mode CONFIG with feed-forward
    and its two-values-per-sample SETPOINTS; v3 an IDENTITY naming a temperature sensor and a SAMPLES header
    with the winding temperature."""
    v1 = version == 1
    config_gains = dict.fromkeys(p.Config.GAINS, 0.0) if v1 else {}
    msgs = {
        "estop": p.EStop(),
        "disarm": p.Disarm(),
        "arm": p.Arm(),
        "clear_faults": p.ClearFaults(),
        "get_config": p.GetConfig(),
        "get_identity": p.GetIdentity(version),
        "identity": p.Identity("HB-AMP-1", "SIM-0001", "1.0.0+sim", version, 8192, 256,
                               p.Sensor.TEMPERATURE if version >= 3 else 0),
        "config": p.Config(10000, p.Mode.VELOCITY, 4.5, 150.0, -math.inf, 12.5, 0.1, 0.0452, 16384, 3.0,
                           **config_gains),
        "heartbeat": p.Heartbeat(0xDEADBEEF),
        "status": p.Status(7, p.State.STREAMING, p.Fault.WATCHDOG | p.Fault.OVER_SPEED, 600000, 8000, 600192,
                           599000, 1001, 0.0, 3, 2, 5000, 6000),
        "reply": p.Reply(p.MsgType.ARM, p.Result.FAULT_LATCHED, p.Fault.ESTOP),
        "setpoints": p.SetpointBlock(41, np.array([0.0, -1.5, 2.25, 1e-3], dtype=np.float32), end=True),
        "samples": p.SampleBlock(3, 2**33 + 5, 100, 2**33 + 9, 0, p.State.STREAMING,
                                 np.array([0, -1, 2**31 - 1, -(2**31)], dtype=np.int32),
                                 np.array([0.5, 0.0, -0.25, 1.0], dtype=np.float32),
                                 np.array([0.49, 0.01, -0.26, 0.99], dtype=np.float32),
                                 np.array([1, 1, 3, 5], dtype=np.uint16),
                                 36.625 if version >= 3 else math.nan),  # degC, exact in float32
    }
    if not v1:
        msgs["config_position"] = p.Config(20000, p.Mode.POSITION, 8.0, 300.0, -0.5, 0.75, 0.5, 0.2, 65536, 1.0,
                                           **V2_GAINS, feedforward=True)
        # (angle rad, feed-forward A) per sample, interleaved
        msgs["setpoints_position"] = p.SetpointBlock(
            7, np.array([[0.0, 0.5], [2.5e-4, -0.75], [-1e-3, 1.25]], dtype=np.float32).reshape(-1), end=False)
    return msgs


if __name__ == "__main__":  # regenerate tests/data/protocol/*.hex (only when a protocol version changes)
    from pathlib import Path

    out = Path(__file__).resolve().parents[1] / "data" / "protocol"
    for version in (1, 2, 3):
        for name, msg in canonical_messages(version).items():
            (out / f"v{version}_{name}.hex").write_text(p.encode_frame(msg, version).hex() + "\n")
