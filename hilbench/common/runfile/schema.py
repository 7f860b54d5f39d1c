"""The run-file contract, owned here and only here: the schema's name and versions, the channel catalogue with
units, statuses, event kinds, record kinds, torque timings and size bounds (docs/run-file.md).

The writer and the reader (:mod:`hilbench.common.runfile.store`), the record loader
(:mod:`hilbench.analysis.record`), the bench, importers and every analysis take these names from this module.
It lives in the bottom layer (``hilbench.common``) so that drivers, the simulated devices, ``bench`` (which writes
runs) and ``analysis`` (which reads them) share one definition; it imports nothing else of hilbench.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from hilbench.common.errors import InputError
from hilbench.common.units import AXES, AXIS_UNITS

SCHEMA = "hilbench-run"
#: root attribute ``record``: what drives the run (absent in older files: torque-driven)
RECORDS = ("torque-driven", "displacement-driven")
SCHEMA_VERSION = 2
#: Versions this reader opens (2 added the position-mode channels position_cmd and current_ff).
SCHEMA_VERSIONS = (1, 2)
FINAL_STATUSES = ("completed", "aborted")
#: ``failed``: the writer itself could not go on (disk full, I/O error); the file keeps every flushed sample.
STATUSES = ("running", "completed", "aborted", "failed", "crashed")
#: Bytes kept in the lock file while a writer runs, given back when a write fails so that the writer can
#: still roll the file back and mark it ``failed`` on a full disk (HDF5 needs a few KiB of metadata for it).
RESERVE_BYTES = 1 << 18
#: The largest chunk, samples: the writer buffers one chunk per channel (``flush_interval`` of device time,
#: capped here so that an absurd sample rate cannot ask for absurd memory).
MAX_CHUNK = 1 << 20
EVENT_KINDS = ("fault", "pause", "resume", "abort", "error", "info", "crash")
EVENT_MESSAGE_BYTES = 256


@dataclass(frozen=True)
class ChannelSpec:
    """A known sample channel: unit on a rotary and on a linear axis, dtype and a one-line description."""

    rotary_unit: str
    linear_unit: str
    dtype: str
    description: str

    def unit(self, axis: str) -> str:
        return self.rotary_unit if axis == AXES[0] else self.linear_unit


def _axis(quantity: str) -> tuple[str, str]:
    """(rotary unit, linear unit) of ``quantity`` (hilbench.common.units)."""
    return AXIS_UNITS["rotary"][quantity], AXIS_UNITS["linear"][quantity]


#: the channel names of a sample block (channel -> array) a device yields and a run file keeps, named once: no
#: module outside this package spells them (tests/common/test_runfile_keys.py)
SAMPLE_INDEX, TIME, CYCLE, DRIVE_STATUS = "sample_index", "t", "cycle", "drive_status"
#: the commanded channels: current, torque (force), velocity, the position reference and its feed-forward current
CURRENT_CMD, TORQUE_CMD, VELOCITY_CMD = "current_cmd", "torque_cmd", "velocity_cmd"
POSITION_CMD, CURRENT_FF = "position_cmd", "current_ff"
#: the host-clocked drive's time channel: the one spelling of its key
HOST_TIME = "host_time"

CHANNELS: dict[str, ChannelSpec] = {
    SAMPLE_INDEX: ChannelSpec("1", "1", "i8", "device sample counter"),
    TIME: ChannelSpec("s", "s", "f8", "device time of the sample"),
    CURRENT_CMD: ChannelSpec("A", "A", "f8", "commanded motor current"),
    "current": ChannelSpec("A", "A", "f8", "measured motor current"),
    "torque": ChannelSpec(*_axis("torque"), "f8", "motor torque (force on a linear axis)"),
    TORQUE_CMD: ChannelSpec(*_axis("torque"), "f8", "commanded torque (force on a linear axis)"),
    "position": ChannelSpec(*_axis("position"), "f8", "measured position"),
    POSITION_CMD: ChannelSpec(*_axis("position"), "f8", "position reference"),
    "counts": ChannelSpec("counts", "counts", "i8", "raw encoder counts"),
    "velocity": ChannelSpec(*_axis("velocity"), "f8", "measured velocity"),
    VELOCITY_CMD: ChannelSpec(*_axis("velocity"), "f8", "commanded velocity (velocity mode)"),
    CURRENT_FF: ChannelSpec("A", "A", "f8", "feed-forward current streamed with the position reference"),
    "temperature": ChannelSpec("degC", "degC", "f8", "winding temperature the device reports (one reading per "
                                                        "sample block, held over its samples)"),
    # what a host-clocked drive adds (docs/drives.md): when each cycle's trigger left the host, the cycle count
    # and the drive's status word
    HOST_TIME: ChannelSpec("s", "s", "f8", "host monotonic time at which the cycle's trigger (SYNC) was sent"),
    CYCLE: ChannelSpec("1", "1", "f8", "cycle counter of a host-clocked drive (SYNC or cyclic message count)"),
    DRIVE_STATUS: ChannelSpec("1", "1", "f8", "the drive's status word per sample (CiA 402 0x6041, ODrive "
                                                "axis state); 0 when it reports none"),
}
DEVICE_CHANNELS = (SAMPLE_INDEX, TIME, CURRENT_CMD, "current", "torque", "position", "counts")
#: the channels a host-clocked drive adds to :data:`DEVICE_CHANNELS`
HOST_CLOCKED_CHANNELS = ("velocity", TORQUE_CMD, HOST_TIME, CYCLE, DRIVE_STATUS)
REQUIRED_CHANNELS = (SAMPLE_INDEX, TIME)
# On a linear axis analysis may ask for the honest names; they are the same datasets.
LINEAR_ALIASES = {"force": "torque", "force_cmd": TORQUE_CMD}

EVENT_DTYPE = np.dtype(
    [
        (SAMPLE_INDEX, "i8"),
        (TIME, "f8"),  # device time, s
        ("wall_time", "f8"),  # host UNIX time, s
        ("kind", "S16"),
        ("message", f"S{EVENT_MESSAGE_BYTES}"),
    ]
)


class RunFileError(InputError):
    """A run file cannot be created, read or repaired, or breaks the schema (the message names the file and the
    reason, in one line). An :class:`~hilbench.common.errors.InputError`, so an analysis catches it as its own
    ``AnalysisError``."""


#: How sample k of the torque channel relates to the plant's input convention (torque held over
#: [t_k, t_k+1)), by the file's ``source``; see hilbench.analysis.identification.regressors.held_torque.
TORQUE_TIMING = {"device": "hold_previous", "import:emps": "hold_next"}
TIMINGS = ("auto", "hold_previous", "hold_next", "instant")
#: the timings a file may declare (``auto`` is a request to the loader, never stored)
TORQUE_TIMINGS = ("hold_next", "hold_previous", "instant")  # docs/science.md §6
#: The largest channel (or protocol array) a run file may hold, values: 2**28 = 268 435 456, i.e. 2 GiB as
#: float64 and 3.7 h at 20 kHz (a protocol lasts at most 1 h). A file claiming more is refused before
#: anything is allocated: a 13 KB file may claim 2**33 samples that HDF5 would read back as 64 GiB of fill.
MAX_SAMPLES = 1 << 28


def check_size(path: Any, name: str, shape: tuple[int, ...]) -> None:
    """Raise :class:`RunFileError` if a dataset of ``shape`` holds more than :data:`MAX_SAMPLES` values."""
    size = 1
    for n in shape:
        size *= int(n)
    if size > MAX_SAMPLES:
        raise RunFileError(f"{path}: {name} claims {size} values, above the bound of {MAX_SAMPLES} "
                            f"(MAX_SAMPLES); refusing to read it")


def record_kind(value: object, path: object = "") -> str:
    """The record kind from a ``record`` attribute value (None: torque-driven); RunFileError if unknown."""
    if value is None:
        return RECORDS[0]
    text = _text(value)
    if text not in RECORDS:
        raise RunFileError(f"{path}: unknown record kind {text!r} (expected {' or '.join(RECORDS)})")
    return text


def torque_timing_for(source: str, timing: str = "auto", channel: str = "torque") -> str:
    """The torque timing for ``channel`` of a run whose file says ``source``: ``timing`` unless it is
    ``auto``. A commanded channel (``*_cmd``) is held over the next interval wherever it comes from."""
    if timing not in TIMINGS:
        raise RunFileError(f"torque timing must be one of {', '.join(TIMINGS)}, got {timing!r}")
    if timing != "auto":
        return timing
    if channel.endswith("_cmd"):
        return "hold_next"
    return TORQUE_TIMING.get(source, "instant")


def run_torque_timing(attrs: Any, timing: str = "auto", channel: str = "torque") -> tuple[str, str]:
    """(timing, where it comes from) for ``channel`` of a run whose root attributes are ``attrs`` (a mapping:
    ``h5py`` attrs or ``Run.meta``). In order: ``timing`` when it is not ``auto`` ("given"); for the torque
    channel, the ``torque_timing`` the file declares ("declared in the run file", written by ``hilbench
    import --torque-timing``); else :func:`torque_timing_for` the file's ``source`` ("default for <source>")."""
    source = _text(attrs.get("source", "device"))
    resolved = torque_timing_for(source, timing, channel)
    if timing != "auto":
        return resolved, "given"
    declared = attrs.get("torque_timing")
    if declared is not None and not channel.endswith("_cmd"):
        declared = _text(declared)
        if declared not in TIMINGS or declared == "auto":
            raise RunFileError(f"run file declares an unknown torque timing {declared!r}")
        return declared, "declared in the run file"
    return resolved, f"default for {source} runs"


#: ``/device/identity`` key saying when a device's samples were taken (:data:`SAMPLE_TIMES`)
SAMPLE_TIMES_KEY = "sample_times"
#: its values: ``device`` (the device owns the sample clock: the hilbench protocol), ``host_time`` (a host-clocked
#: drive samples at each trigger the host sends: CiA 402 SYNC; the analysis resamples on the host_time channel),
#: ``drive`` (a host-clocked drive samples on its own timer: ODrive cyclic messages)
DEVICE_CLOCK, DRIVE_CLOCK = "device", "drive"
SAMPLE_TIMES = (DEVICE_CLOCK, HOST_TIME, DRIVE_CLOCK)
#: resampled channels keep the timing of their record; these are the conventions (see ``TIMINGS``)
SAMPLE_KINDS = ("instant", "hold_next", "hold_previous")


@dataclass(frozen=True)
class DeviceIdentity(Mapping[str, Any]):
    """Who recorded a run: the ``/device/identity`` of a run file, written as one flat JSON object.

    The named fields are the keys every device kind may fill (text; "" when unknown); ``sample_times`` says whose
    clock timed the samples (:data:`SAMPLE_TIMES`); ``details`` holds what one device kind adds (a drive's device
    type, an amplifier's buffer size...), JSON-able values under keys that are not field names. It reads as a
    mapping of its stored keys (``identity["serial"]``, ``dict(identity)``). Construction validates it: a bad
    identity is a :class:`RunFileError` in one line, before any file is touched.
    """

    name: str = ""
    model: str = ""
    serial: str = ""
    firmware: str = ""
    protocol: str = ""
    url: str = ""
    description: str = ""
    source: str = ""
    sample_times: str = DEVICE_CLOCK
    details: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for f in _text_fields():
            value = getattr(self, f.name)
            if not isinstance(value, str):
                raise RunFileError(f"device identity: {f.name} must be text, got {type(value).__name__}")
        if self.sample_times not in SAMPLE_TIMES:
            raise RunFileError(f"device identity: {SAMPLE_TIMES_KEY} must be one of {', '.join(SAMPLE_TIMES)}, "
                               f"got {self.sample_times!r}")
        if not isinstance(self.details, Mapping):
            raise RunFileError(f"device identity: details must be a mapping, got {type(self.details).__name__}")
        named = {f.name for f in fields(self)}
        for key, value in self.details.items():
            if not isinstance(key, str) or key in named:
                raise RunFileError(f"device identity: detail key {key!r} must be text and not a field name")
            try:
                json.dumps(value, allow_nan=True, default=_json_scalar)
            except (TypeError, ValueError) as exc:
                raise RunFileError(f"device identity: {key} is not JSON-serialisable ({exc})") from None
        object.__setattr__(self, "details", dict(self.details))

    @classmethod
    def from_mapping(cls, value: Mapping[str, Any] | None) -> DeviceIdentity:
        """The identity a flat mapping (a file's JSON, a device's report) describes; None: an empty one."""
        if isinstance(value, DeviceIdentity):
            return value
        if value is None:
            return cls()
        if not isinstance(value, Mapping):
            raise RunFileError(f"device identity must be a mapping, got {type(value).__name__}")
        named = {f.name for f in _text_fields()}
        known = {k: v for k, v in value.items() if k in named}
        return cls(**known, details={k: v for k, v in value.items() if k not in named})

    def as_json(self) -> dict[str, Any]:
        """The flat JSON object stored in the file: the fields that say something (not empty; ``sample_times``
        when it is not the default ``device``: a file without it was timed by its device), then the details."""
        out = {f.name: getattr(self, f.name) for f in _text_fields()
               if getattr(self, f.name) != ("" if f.name != SAMPLE_TIMES_KEY else DEVICE_CLOCK)}
        return {**out, **self.details}

    def __getitem__(self, key: str) -> Any:
        return self.as_json()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.as_json())

    def __len__(self) -> int:
        return len(self.as_json())


def _text_fields() -> list[Any]:
    """The named text fields of :class:`DeviceIdentity` (all but ``details``)."""
    return [f for f in fields(DeviceIdentity) if f.name != "details"]


def _json_scalar(value: Any) -> Any:
    """JSON for the numpy values a device or a protocol reports (``json.dumps`` ``default``)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def host_sampled(identity: Any, channels: Any) -> bool:
    """Whether a run's samples were taken at its ``host_time`` (a CiA 402 drive samples at each SYNC), so
    that the analysis must resample them (``identity``: the run's ``/device/identity``; ``channels``: names)."""
    return (isinstance(identity, Mapping) and identity.get(SAMPLE_TIMES_KEY) == HOST_TIME
            and HOST_TIME in channels)


def _text(value: Any) -> str:
    if isinstance(value, bytes | np.bytes_):
        return value.decode()
    return str(value)
