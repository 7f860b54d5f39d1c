"""A bare protocol client for black-box device tests: frames on the wire and nothing of the host stack, so
the same tests hold for any firmware core behind ``python -m hilbench.firmware_sim``."""

from __future__ import annotations

import time

import numpy as np

from hilbench.drivers import protocol as p
from hilbench.drivers.links import SerialLink


class Wire:
    """Send messages to a device and collect what it sends back, by type."""

    def __init__(self, path: str) -> None:
        self.link = SerialLink(path)
        self.blocks: list[p.SampleBlock] = []
        self._token = 0

    def close(self) -> None:
        """Drop the connection without a word to the device (what a killed host does)."""
        self.link.close()

    def _collect(self, want, timeout: float):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = self.link.recv(max(0.0, deadline - time.monotonic()))
            if msg is None:
                continue
            if isinstance(msg, p.SampleBlock):
                self.blocks.append(msg)
            if want(msg):
                return msg
        raise TimeoutError(f"no answer from the device within {timeout} s")

    def request(self, msg: p.Message, timeout: float = 2.0):
        self.link.send(msg)
        t = msg.TYPE
        return self._collect(lambda m: (m.TYPE == p.MsgType.REPLY and m.request == t)
                             or (t == p.MsgType.GET_IDENTITY and m.TYPE == p.MsgType.IDENTITY), timeout)

    def status(self, timeout: float = 2.0) -> p.Status:
        self._token = self._token % 0xFFFF + 1
        token = self._token
        self.link.send(p.Heartbeat(token))
        return self._collect(lambda m: m.TYPE == p.MsgType.STATUS and m.token == token, timeout)

    def setpoints(self, seq: int, values, end: bool = False) -> None:
        self.link.send(p.SetpointBlock(seq, np.asarray(values, dtype=np.float32), end=end))

    def drain(self, seconds: float) -> None:
        """Read whatever the device sends for ``seconds`` (sample blocks are kept in ``blocks``)."""
        try:
            self._collect(lambda m: False, seconds)
        except TimeoutError:
            pass

    def start_stream(self, rate: int, watchdog: float, current: float, n: int, block: int = 100) -> None:
        """Configure (current mode), clear faults, arm, and send ``n`` setpoints of ``current`` A that do
        not end the stream."""
        cfg = p.Config(sample_rate=rate, current_limit=3.0, watchdog_timeout=watchdog, torque_constant=0.2,
                       counts_per_rev=4096)
        assert self.request(p.GetIdentity()).TYPE == p.MsgType.IDENTITY
        assert self.request(p.Disarm()).result == p.Result.OK
        assert self.request(p.ClearFaults()).result == p.Result.OK
        assert self.request(cfg).result == p.Result.OK
        assert self.request(p.Arm()).result == p.Result.OK
        for seq in range(n // block):
            self.setpoints(seq, np.full(block, current))
