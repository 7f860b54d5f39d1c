"""The firmware core in C (``firmware/core/``) on the host target: the simulated device runs the same C
code a microcontroller runs, with the C plant behind its HAL (``firmware/targets/host/``).

:class:`CoreDevice` is one device: bytes (serial) or CAN frames in, bytes or CAN frames out, time in
seconds of the monotonic clock. :func:`serve_core` is its serve loop on a pseudo-terminal
(:class:`CorePtyTransport`) or a python-can bus (:class:`CoreCanTransport`). Design, HAL and float
policy: ``docs/firmware.md``.
"""

from __future__ import annotations

import threading
import time

from hilbench.firmware_sim._fwcore import ffi, lib
from hilbench.firmware_sim.device import TX_BUFFER_LIMIT, CanTransport, PtyTransport
from hilbench.firmware_sim.plant import PlantParameterError, _CParams, validate
from hilbench.firmware_sim.plant import ffi as plant_ffi
from hilbench.firmware_sim.sim_config import SimConfig

FIRMWARE_VERSION = "hilbench-sim c-core 2.0.0"
PACINGS = {"realtime": 0, "lockstep": 1}
RATES = (1000, 2000, 5000, 10000, 20000)  # Hz, the order of hb_host.substeps_by_rate
LINKS = {"serial": 0, "can": 1, "can-fd": 2}


def _us(now: float) -> int:
    return int(now * 1e6)


class CoreDevice:
    """One device of the C firmware core with the simulator's plant.

    Args:
        sim: simulator configuration (identity, buffer size, plant; the plant's velocity_kp/ki are the
            gains of the core's velocity PI loop).
        pacing: ``"realtime"`` or ``"lockstep"`` (docs/protocol.md).
        link: ``"serial"``, ``"can"`` or ``"can-fd"``.
        node: CAN node id, 1..15.
        max_block: largest setpoint block accepted and sample block sent, samples.
    """

    def __init__(self, sim: SimConfig, pacing: str = "realtime", link: str = "serial", node: int = 1,
                 max_block: int = 512) -> None:
        if pacing not in PACINGS:
            raise ValueError(f"pacing must be one of {tuple(PACINGS)}, got {pacing!r}")
        if link not in LINKS:
            raise ValueError(f"link must be one of {tuple(LINKS)}, got {link!r}")
        self.pacing = pacing
        self._host = ffi.new("hb_host *")
        h = self._host
        self._params = _CParams(sim.plant)  # keeps the arrays the C struct points to alive
        ffi.memmove(ffi.addressof(h.sim, "base"), plant_ffi.buffer(self._params.struct), ffi.sizeof("hb_params"))
        for i, rate in enumerate(RATES):
            substeps = sim.substeps_at(rate)
            try:
                validate(sim.plant, 1.0 / rate, substeps)
            except PlantParameterError:
                substeps = 0  # CONFIG at this rate is refused (INVALID_CONFIG)
            h.sim.substeps_by_rate[i] = substeps
        h.sim.seed = int(sim.plant.seed)
        self._strings = [ffi.new("char[]", s.encode()) for s in (sim.model, sim.serial, FIRMWARE_VERSION)]
        setup = ffi.new("hb_device_setup *")
        setup.model, setup.serial, setup.firmware = self._strings
        setup.capacity = sim.buffer_capacity
        setup.max_block = max_block
        setup.pacing = PACINGS[pacing]
        setup.link = LINKS[link]
        setup.can_node = node
        setup.velocity_kp = sim.plant.velocity_kp
        setup.velocity_ki = sim.plant.velocity_ki
        lib.hb_host_init(h, setup)
        self._dev = ffi.addressof(h, "device")

    def rx_bytes(self, data: bytes, now: float) -> None:
        """Bytes received on the serial link at ``now`` (s)."""
        lib.hb_device_rx_bytes(self._dev, data, len(data), _us(now))

    def rx_can(self, arbitration_id: int, data: bytes, now: float) -> None:
        """One CAN frame received at ``now`` (s)."""
        lib.hb_device_rx_can(self._dev, arbitration_id, data, len(data), _us(now))

    def tick(self, now: float) -> None:
        """Run the sample clock up to ``now`` (s): the samples due, the watchdog."""
        lib.hb_device_tick(self._dev, _us(now))
        if self._host.sim.plant_failed:
            raise FloatingPointError("plant state became non-finite; check the simulator's parameters")

    def take_bytes(self) -> bytes:
        """Everything the device wrote to its serial link since the last call."""
        h = self._host
        out = ffi.buffer(h.tx, h.tx_len)[:]
        h.tx_len = 0
        return out

    def take_can(self) -> list[tuple[int, bytes]]:
        """The CAN frames the device sent since the last call, as (arbitration id, data)."""
        h = self._host
        out = [(h.can[i].id, ffi.buffer(h.can[i].data, h.can[i].len)[:]) for i in range(h.can_n)]
        h.can_n = 0
        return out

    def count_dropped(self, frames: int) -> None:
        """Frames the transport could not deliver (reported in the device's dropped_frames)."""
        if frames > 0:
            lib.hb_device_count_dropped(self._dev, frames)

    @property
    def busy(self) -> bool:
        return bool(lib.hb_device_busy(self._dev))

    @property
    def identity_requests(self) -> int:
        return int(self._dev.identity_requests)

    def status(self) -> dict[str, int | float]:
        """The STATUS fields as the device would send them (token 0)."""
        s = ffi.new("hb_status *")
        lib.hb_device_status(self._dev, 0, s)
        names = ("state", "faults", "index", "free", "received", "fault_index", "fault_silence",
                 "current_applied", "crc_errors", "dropped_frames", "rx_frames", "tx_frames")
        return {name: getattr(s, name) for name in names}


class _Inbox:
    """Stands in for PtyTransport's frame decoder: the C core parses the bytes itself."""

    crc_errors = 0

    def __init__(self) -> None:
        self.data = bytearray()

    def feed(self, chunk: bytes) -> list:
        self.data += chunk
        return []

    def take(self) -> bytes:
        out = bytes(self.data)
        self.data.clear()
        return out


class CorePtyTransport(PtyTransport):
    """PtyTransport's pseudo-terminal and output queue, carrying the C core's bytes unparsed."""

    def __init__(self) -> None:
        super().__init__()
        self._decoder = _Inbox()

    def exchange(self, device: CoreDevice, timeout: float) -> None:
        """Wait up to ``timeout`` s for host bytes and hand them to the device."""
        self.poll(timeout)
        data = self._decoder.take()
        if data:
            before = device.identity_requests
            device.rx_bytes(data, time.monotonic())
            if device.identity_requests != before:  # a new host: drop what the previous one left unread
                self._discard_backlog()

    def deliver(self, device: CoreDevice) -> None:
        """Queue the device's output frames (0x00-delimited) and write what the pty takes."""
        out = device.take_bytes()
        start = 0
        while start < len(out):
            end = out.index(0, start) + 1
            if len(self._tx) > TX_BUFFER_LIMIT:
                self.dropped_frames += 1
            else:
                self._tx_starts.append(len(self._tx))
                self._tx += out[start:end]
                self.frames_tx += 1
            start = end
        self._flush()


class CoreCanTransport(CanTransport):
    """CanTransport's bus, carrying the C core's CAN frames (the core segments and reassembles)."""

    def exchange(self, device: CoreDevice, timeout: float) -> None:
        frame = self.bus.recv(max(0.0, timeout))
        while frame is not None:
            if not (frame.is_error_frame or frame.is_remote_frame):
                device.rx_can(frame.arbitration_id, bytes(frame.data), time.monotonic())
            frame = self.bus.recv(0.0)

    def deliver(self, device: CoreDevice) -> None:
        for arb, data in device.take_can():
            try:
                self.bus.send(self._can.Message(arbitration_id=arb, data=data, is_extended_id=False,
                                                is_fd=self.fd, bitrate_switch=self.fd), timeout=0.1)
                self.frames_tx += 1
            except self._can.CanError:
                self.dropped_frames_tx += 1

    @property
    def dropped_frames(self) -> int:
        return self.dropped_frames_tx


def serve_core(transport: CorePtyTransport | CoreCanTransport, device: CoreDevice, tick: float = 0.004,
               stop: threading.Event | None = None) -> None:
    """Run the device until ``stop`` is set (forever when None).

    ``tick`` (s) is the realtime loop period; in lockstep the loop waits only when nothing is buffered.
    The core checks its watchdog on every pass, whatever the pacing and the buffer hold.
    """
    next_tick = time.monotonic()
    reported = 0
    while stop is None or not stop.is_set():
        now = time.monotonic()
        if device.pacing == "realtime":
            timeout = next_tick - now
        else:
            timeout = 0.0 if device.busy else 0.01
        transport.exchange(device, timeout)
        now = time.monotonic()
        if device.pacing == "lockstep" or now >= next_tick:
            device.tick(now)
            next_tick = max(next_tick + tick, now)
        transport.deliver(device)
        dropped = transport.dropped_frames
        device.count_dropped(dropped - reported)
        reported = dropped
