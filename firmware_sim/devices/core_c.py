"""The firmware core in C (``firmware/core/``) on the host target: the simulated device runs the same C
code a microcontroller runs, with the C plant behind its HAL (``firmware/targets/host/``).

:class:`CoreDevice` is one device: bytes (serial) or CAN frames in, bytes or CAN frames out, time in
seconds of the monotonic clock. Its serve loop and transports are in :mod:`firmware_sim.devices.device`. Design,
HAL and float policy: ``docs/firmware.md``.
"""

from __future__ import annotations

from hilbench.firmware_sim.devices._fwcore import ffi, lib
from hilbench.firmware_sim.devices.sim_config import SimConfig
from hilbench.firmware_sim.engine.plant import PlantParameterError, _CParams, validate
from hilbench.firmware_sim.engine.plant import ffi as plant_ffi

FIRMWARE_VERSION = "hilbench-sim c-core 3.0.0"
PACINGS = {"realtime": 0, "lockstep": 1}
RATES = (1000, 2000, 5000, 10000, 20000)  # Hz, the order of hb_host.substeps_by_rate
LINKS = {"serial": 0, "can": 1, "can-fd": 2}
SENSOR_TEMPERATURE = 0x01  # hb_sensors (protocol v3 IDENTITY)
STATE_STREAMING = 3        # hb_state


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
        if sim.drift is not None:  # a motor that warms up and wears, with a winding temperature sensor
            d = h.sim.drift
            for name, value in vars(sim.drift).items():
                setattr(d, name, value)
            d.block = sim.drift_block
            d.ambient = d.temperature = sim.ambient
            d.distance = 0.0
            d.on = 1
            setup.sensors = SENSOR_TEMPERATURE
        lib.hb_host_init(h, setup)
        self._dev = ffi.addressof(h, "device")
        self._idle_since: float | None = None

    def rx_bytes(self, data: bytes, now: float) -> None:
        """Bytes received on the serial link at ``now`` (s)."""
        lib.hb_device_rx_bytes(self._dev, data, len(data), _us(now))

    def rx_can(self, arbitration_id: int, data: bytes, now: float) -> None:
        """One CAN frame received at ``now`` (s)."""
        lib.hb_device_rx_can(self._dev, arbitration_id, data, len(data), _us(now))

    def tick(self, now: float) -> None:
        """Run the sample clock up to ``now`` (s): the samples due, the watchdog. Between streams the
        winding cools towards ambient for the wall-clock time that passes (the samples heat it)."""
        if self._host.sim.drift.on:
            if self._dev.state != STATE_STREAMING:
                if self._idle_since is not None:
                    lib.hb_plant_hal_rest(ffi.addressof(self._host, "sim"), now - self._idle_since)
                self._idle_since = now
            else:
                self._idle_since = None
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

    def drift_state(self) -> dict[str, float]:
        """The drift laws' state: winding temperature (degC), distance slid (rad), friction level L and
        viscous factor b(T)/b_ref (NaN without [drift])."""
        d = self._host.sim.drift
        if not d.on:
            return dict.fromkeys(("temperature", "distance", "level", "viscous"), float("nan"))
        return {"temperature": d.temperature, "distance": d.distance, "level": lib.hb_drift_level(ffi.addressof(d)),
                "viscous": lib.hb_drift_viscous(ffi.addressof(d))}
