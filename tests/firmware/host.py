"""A host talking to a :class:`CoreDevice` in protocol messages through Python's frame codec (an
implementation independent of the C codec), with time given explicitly in seconds."""

import numpy as np

from hilbench.drivers import protocol as p
from hilbench.firmware_sim.devices.core_c import CoreDevice


class Host:
    """A host talking to a CoreDevice through Python's frame codec; time is given explicitly (s)."""

    def __init__(self, device: CoreDevice) -> None:
        self.device = device
        self.decoder = p.FrameDecoder()

    def send(self, msg: p.Message, now: float = 0.0) -> list[p.Message]:
        self.device.rx_bytes(p.encode_frame(msg), now)
        return self.receive()

    def receive(self) -> list[p.Message]:
        return self.decoder.feed(self.device.take_bytes())

    def tick(self, now: float = 0.0) -> list[p.Message]:
        self.device.tick(now)
        return self.receive()


def samples(msgs):
    """The sample channels of the SAMPLES messages in ``msgs``, concatenated."""
    blocks = [m for m in msgs if isinstance(m, p.SampleBlock)]
    return {k: np.concatenate([getattr(b, k) for b in blocks]) for k in ("counts", "current_cmd", "current_meas",
                                                                         "status")}
