"""Reading hilbench run files (HDF5 schema v1, docs/run-file.md) for the analysis, with plain h5py.

analysis never imports bench; this is the one place it reads the file layout. A file still being
written (SWMR) or left by a crash reads as far as it was flushed.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hilbench.analysis.errors import AnalysisError

SCHEMA = "hilbench-run"
#: How sample k of the torque channel relates to the plant's input convention (torque held over
#: [t_k, t_k+1)), by the file's ``source``; see hilbench.analysis.identification.regressors.held_torque.
TORQUE_TIMING = {"device": "hold_previous", "import:emps": "hold_next"}
TIMINGS = ("auto", "hold_previous", "hold_next", "instant")
#: The largest channel (or protocol array) a run file may hold, values: 2**28 = 268 435 456, i.e. 2 GiB as
#: float64 and 3.7 h at 20 kHz (a protocol lasts at most 1 h). A file claiming more is refused before
#: anything is allocated: a 13 KB file may claim 2**33 samples that HDF5 would read back as 64 GiB of fill.
MAX_SAMPLES = 1 << 28


def check_size(path: Any, name: str, shape: tuple[int, ...]) -> None:
    """Raise :class:`AnalysisError` if a dataset of ``shape`` holds more than :data:`MAX_SAMPLES` values."""
    size = 1
    for n in shape:
        size *= int(n)
    if size > MAX_SAMPLES:
        raise AnalysisError(f"{path}: {name} claims {size} values, above the bound of {MAX_SAMPLES} "
                            f"(MAX_SAMPLES); refusing to read it")
#: the root attribute ``record``: ``torque-driven`` (absent means this) or ``displacement-driven`` (force
#: measured against an imposed displacement); the analysis picks its mode from it
RECORDS = ("torque-driven", "displacement-driven")


def record_kind(value: object, path: object = "") -> str:
    """The record kind from a ``record`` attribute value (None: torque-driven); AnalysisError if unknown."""
    if value is None:
        return RECORDS[0]
    text = _text(value)
    if text not in RECORDS:
        raise AnalysisError(f"{path}: unknown record kind {text!r} (expected {' or '.join(RECORDS)})")
    return text


def torque_timing_for(source: str, timing: str = "auto", channel: str = "torque") -> str:
    """The torque timing for ``channel`` of a run whose file says ``source``: ``timing`` unless it is
    ``auto``. A commanded channel (``*_cmd``) is held over the next interval wherever it comes from."""
    if timing not in TIMINGS:
        raise AnalysisError(f"torque timing must be one of {', '.join(TIMINGS)}, got {timing!r}")
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
            raise AnalysisError(f"run file declares an unknown torque timing {declared!r}")
        return declared, "declared in the run file"
    return resolved, f"default for {source} runs"


@dataclass
class RunFile:
    """One run file's samples and metadata.

    Attributes:
        path: the file.
        axis: ``"rotary"`` (rad, N*m) or ``"linear"`` (m, N).
        sample_rate: Hz.
        status: ``completed``, ``aborted``, ``crashed`` or ``running`` as stored.
        source: ``device`` or ``import:<format>``.
        channels: name -> 1-D array (the flushed samples).
        units: name -> unit string.
        protocol_name, protocol_params: what the run played.
        protocol_arrays: e.g. ``setpoints``, ``step_windows``.
        record: ``torque-driven`` or ``displacement-driven`` (root attribute ``record``; absent: torque-driven).
        torque_timing: ``hold_previous`` (torque from the current sampled at t_k), ``hold_next`` (a command
            held over the next interval) or ``instant``: as declared in the file, else from its source.
        declared_timing: the file's ``torque_timing`` attribute, None when it declares none.
    """

    path: Path
    axis: str
    sample_rate: float
    status: str
    source: str
    channels: dict[str, np.ndarray]
    units: dict[str, str]
    protocol_name: str = ""
    protocol_params: dict[str, Any] = field(default_factory=dict)
    protocol_arrays: dict[str, np.ndarray] = field(default_factory=dict)
    calibration: dict[str, Any] = field(default_factory=dict)
    declared_timing: str | None = None
    record: str = "torque-driven"

    @property
    def name(self) -> str:
        return self.path.stem

    @property
    def torque_timing(self) -> str:
        attrs = {"source": self.source, "torque_timing": self.declared_timing}
        return run_torque_timing({k: v for k, v in attrs.items() if v is not None})[0]

    @property
    def t(self) -> np.ndarray:
        return self.channels["t"]

    def channel(self, name: str) -> np.ndarray:
        """A channel by name (``force`` reads ``torque`` on a linear axis); AnalysisError if missing."""
        key = "torque" if name == "force" else name
        if key not in self.channels:
            raise AnalysisError(f"{self.path}: no {name!r} channel (has: {', '.join(sorted(self.channels))})")
        return self.channels[key]

    def arrays(self):
        """The run as :class:`hilbench.analysis.identification.identify.RunArrays` (t, torque, position, axis, name)."""
        from hilbench.analysis.identification.identify import RunArrays

        torque = self.channels.get("torque")
        return RunArrays(self.t, torque, self.channel("position"), self.axis, self.name)


def _text(value: Any) -> str:
    if isinstance(value, bytes | np.bytes_):
        return value.decode()
    return str(value)


def read_run_file(path: str | Path) -> RunFile:
    """Read a run file. Raises :class:`AnalysisError` for a missing, damaged or foreign file."""
    import h5py

    path = Path(path)
    if not path.exists():
        raise AnalysisError(f"{path}: no such run file")
    try:
        f = h5py.File(path, "r", locking=False)
    except OSError as exc:
        # A file being written (or left by a crash) is flagged open-for-write: read it as an SWMR reader.
        # Only then: SWMR on a truncated file makes HDF5 retry for a long time.
        text = str(exc)
        if "already open for write" not in text and "locking flag values" not in text:
            raise AnalysisError(f"{path}: not readable as HDF5 (truncated or damaged?): "
                                f"{' '.join(text.split())}") from None
        try:  # default locking: a writer in this very process needs the flags matched
            f = h5py.File(path, "r", libver="latest", swmr=True)
        except OSError as exc2:
            raise AnalysisError(f"{path}: not readable: {' '.join(str(exc2).split())}") from None
    try:
        with f:
            attrs = {k: f.attrs[k] for k in f.attrs}
            if _text(attrs.get("schema", "")) != SCHEMA:
                raise AnalysisError(f"{path}: not a hilbench run file (no schema={SCHEMA!r} attribute)")
            if int(attrs.get("schema_version", 0)) not in (1, 2):  # 2: position-mode channels added
                raise AnalysisError(f"{path}: unsupported run-file schema version {attrs.get('schema_version')}")
            samples = f["samples"]
            for name in samples:
                check_size(path, f"channel {name!r}", samples[name].shape)
            channels = {name: samples[name][()] for name in samples}
            units = {name: _text(samples[name].attrs.get("unit", "")) for name in samples}
            n = min((a.size for a in channels.values()), default=0)
            channels = {k: v[:n] for k, v in channels.items()}
            proto = f["protocol"] if "protocol" in f else None
            params, arrays = {}, {}
            if proto is not None:
                if "parameters" in proto:
                    params = json.loads(_text(proto["parameters"][()]))
                for k in proto:
                    check_size(path, f"protocol array {k!r}", proto[k].shape)
                arrays = {k: proto[k][()] for k in proto if k != "parameters"}
            calibration = json.loads(_text(f["device/calibration"][()])) if "device/calibration" in f else {}
            return RunFile(
                path=path, axis=_text(attrs.get("axis", "rotary")), sample_rate=float(attrs["sample_rate"]),
                status=_text(attrs.get("status", "")), source=_text(attrs.get("source", "device")),
                channels=channels, units=units,
                protocol_name=_text(proto.attrs.get("name", "")) if proto is not None else "",
                protocol_params=params, protocol_arrays=arrays, calibration=calibration,
                declared_timing=_text(attrs["torque_timing"]) if "torque_timing" in attrs else None,
                record=record_kind(attrs.get("record"), path),
            )
    except (KeyError, ValueError, TypeError, AttributeError, OSError, RuntimeError) as exc:
        raise AnalysisError(f"{path}: damaged or incomplete run file ({' '.join(str(exc).split())})") from None
