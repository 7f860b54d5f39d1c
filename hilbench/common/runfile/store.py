"""HDF5 run files (schema in :mod:`hilbench.common.runfile.schema`): the crash-safe incremental writer, the one
reader (:class:`Run`, live refresh included) and repair.

The layout is documented in ``docs/run-file.md``; plain h5py can read every part of it. In short::

    /                 attrs: schema, schema_version, uid, status, start_time, end_time, axis, sample_rate, ...
    /device/          identity, config, calibration      (JSON text datasets)
    /protocol/        attrs name; parameters (JSON text); any protocol arrays (e.g. step_windows)
    /samples/<name>   1-D, chunked, compressed, resizable; attr ``unit``
    /events           resizable compound table: sample_index, t, wall_time, kind, message

Writing: :class:`RunWriter` creates every group and dataset first, then switches the file to SWMR mode
(``libver="latest"``) so the GUI and analysis can read it live. Samples are buffered and written in whole
chunks of ``flush_interval·sample_rate`` samples followed by a flush, so less than ``flush_interval``
(0.5 s by default) of device time is ever at risk. ``status`` is ``running`` until :meth:`RunWriter.finish`
sets ``completed`` or ``aborted``. A writer holds an exclusive ``flock`` on ``<file>.lock`` for its whole
life; the kernel drops it when the process dies, even on SIGKILL, so a file that still says ``running``
while nobody holds the lock is a crashed run. :func:`repair` marks it ``crashed`` (no external tools).
"""

from __future__ import annotations

import glob
import json
import math
import os
import re
import shutil
import socket
import stat
import sys
import time
import uuid
from collections.abc import Iterable, Mapping, Sequence
from datetime import UTC, datetime
from typing import Any

import h5py
import numpy as np

from hilbench.common.runfile.schema import (
    AXES,
    CHANNELS,
    DEVICE_CHANNELS,
    EVENT_DTYPE,
    EVENT_KINDS,
    EVENT_MESSAGE_BYTES,
    FINAL_STATUSES,
    LINEAR_ALIASES,
    MAX_CHUNK,
    MAX_SAMPLES,
    RECORDS,
    REQUIRED_CHANNELS,
    RESERVE_BYTES,
    SCHEMA,
    SCHEMA_VERSION,
    SCHEMA_VERSIONS,
    TORQUE_TIMINGS,
    DeviceIdentity,
    RunFileError,
    _json_scalar,
    _text,
    check_size,
)

_NAME_RE = re.compile(r"^[a-z][a-z0-9_]{0,63}$")



def software_versions() -> dict[str, str]:
    """Versions recorded in every run file: hilbench, python, numpy, h5py and the HDF5 library."""
    import hilbench

    return {
        "hilbench": hilbench.__version__,
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "h5py": h5py.__version__,
        "hdf5": h5py.version.hdf5_version,
    }


def utc_now() -> str:
    """Current time as ISO 8601 UTC with microseconds, e.g. ``2024-05-01T12:00:00.000000+00:00``."""
    return datetime.now(UTC).isoformat(timespec="microseconds")


def lock_path(path: str | os.PathLike) -> str:
    """The writer's lock file beside the run file: ``<path>.lock``."""
    return os.fspath(path) + ".lock"


def writer_alive(path: str | os.PathLike) -> bool:
    """True when a live process holds the writer lock of the run file at ``path``."""
    import fcntl

    try:
        fd = os.open(lock_path(path), os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except (FileNotFoundError, OSError):
        return False  # missing, or a planted symlink or fifo: no writer of ours holds it
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)  # closing drops the lock if we took it
    return False


def _json_text(value: Any, what: str = "metadata") -> str:
    try:
        return json.dumps({} if value is None else value, sort_keys=True, default=_json_scalar)
    except (TypeError, ValueError) as exc:
        raise RunFileError(f"{what} is not JSON-serialisable ({exc})") from None


def _header_field(path: str, check: Any, value: Any, *args: Any) -> Any:
    """``check(value, *args)``, its refusal named with the file: ``path: <reason>``, one line."""
    try:
        return check(value, *args)
    except RunFileError as exc:
        raise RunFileError(f"{path}: {exc}") from None


def _json_dataset(group: h5py.Group, name: str, value: Any) -> None:
    text = _json_text(value, f"{group.name}/{name}")
    group.create_dataset(name, data=text, dtype=h5py.string_dtype("utf-8"))


def _check_text(path: str, name: str, text: Any) -> None:
    """Text stored as an HDF5 string attribute: valid UTF-8 (no lone surrogates) and no NUL character."""
    try:
        str(text).encode("utf-8")
    except UnicodeEncodeError:
        raise RunFileError(f"{path}: {name} is not valid UTF-8 text") from None
    if "\0" in str(text):
        raise RunFileError(f"{path}: {name} contains a NUL character")


def _encode_message(message: str) -> bytes:
    raw = message.encode("utf-8")[:EVENT_MESSAGE_BYTES]
    return raw.decode("utf-8", errors="ignore").encode("utf-8")  # never cut a character in half


class RunWriter:
    """Write one run file incrementally; readable live (SWMR) and crash-safe.

    Use as a context manager: a normal exit finishes ``completed``; Ctrl-C finishes ``aborted`` with an
    ``abort`` event; any other exception finishes ``aborted`` with an ``error`` event (and propagates)::

        with RunWriter("run.h5", sample_rate=10_000.0, protocol_name="chirp", protocol_params={...}) as w:
            for block in device_blocks:          # mapping channel name -> 1-D array, equal lengths
                w.append(block)
            w.add_event("pause", "operator pause")

    Args:
        path: file to create (refused if it exists unless ``overwrite``).
        sample_rate: nominal device sample rate in Hz (sets the chunk and flush size).
        axis: ``"rotary"`` (rad, N*m) or ``"linear"`` (m, N); channel units follow it.
        channels: names from :data:`CHANNELS` to record; must include ``sample_index`` and ``t``.
        custom_channels: extra float64 channels not in the catalogue, ``{name: unit}``, e.g. ``{"vir": "V"}``.
        device: who records the run (:class:`DeviceIdentity`, or a flat mapping it is built from).
        config, calibration: device configuration / calibration (JSON-able dicts).
        protocol_name, protocol_params: the protocol and its parameters (JSON-able).
        protocol_arrays: arrays stored under ``/protocol`` (e.g. a stepped sine's ``step_windows``).
        operator, notes: free text.
        source: ``"device"`` for a measured run, ``"import:<format>"`` for imported data.
        flush_interval: largest span of device time (s) kept only in memory; chunks hold this many seconds
            (at most :data:`MAX_CHUNK` samples).
        compression: ``"lzf"`` (fast; h5py's built-in filter), ``"gzip"`` (level 1; readable by every HDF5
            tool, about 2x slower) or ``None``; always with the shuffle filter.
        start_time: ISO 8601 UTC start time (default: now).
        torque_timing: what torque sample k means (``hold_next``, ``hold_previous``, ``instant``; docs/science.md
            §6), stored as the root attribute ``torque_timing``; None (default) stores nothing.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        sample_rate: float,
        axis: str = "rotary",
        channels: Sequence[str] = DEVICE_CHANNELS,
        custom_channels: Mapping[str, str] | None = None,
        device: DeviceIdentity | Mapping[str, Any] | None = None,
        config: Mapping[str, Any] | None = None,
        calibration: Mapping[str, Any] | None = None,
        protocol_name: str = "",
        protocol_params: Mapping[str, Any] | None = None,
        protocol_arrays: Mapping[str, np.ndarray] | None = None,
        operator: str = "",
        notes: str = "",
        source: str = "device",
        flush_interval: float = 0.5,
        compression: str | None = "lzf",
        overwrite: bool = False,
        start_time: str | None = None,
        torque_timing: str | None = None,
        record: str = "torque-driven",
    ) -> None:
        self.path = os.fspath(path)
        if torque_timing not in (None, *TORQUE_TIMINGS):
            raise RunFileError(f"{self.path}: torque_timing must be one of {TORQUE_TIMINGS}, got {torque_timing!r}")
        self.torque_timing = torque_timing
        if record not in RECORDS:
            raise RunFileError(f"{self.path}: record must be one of {', '.join(RECORDS)}, got {record!r}")
        self.record = record
        if not (isinstance(sample_rate, int | float) and math.isfinite(sample_rate) and sample_rate > 0):
            raise RunFileError(f"{self.path}: sample_rate must be finite and > 0 Hz, got {sample_rate!r}")
        if axis not in AXES:
            raise RunFileError(f"{self.path}: axis must be one of {AXES}, got {axis!r}")
        if not (math.isfinite(flush_interval) and flush_interval > 0):
            raise RunFileError(f"{self.path}: flush_interval must be > 0 s, got {flush_interval!r}")
        if compression not in ("lzf", "gzip", None):
            raise RunFileError(f"{self.path}: compression must be 'lzf', 'gzip' or None, got {compression!r}")
        self.axis = axis
        self.sample_rate = float(sample_rate)
        self.units: dict[str, str] = {}
        self._dtypes: dict[str, np.dtype] = {}
        for name in channels:
            if name not in CHANNELS:
                raise RunFileError(f"{self.path}: unknown channel {name!r}; known: {', '.join(CHANNELS)}")
            self.units[name] = CHANNELS[name].unit(axis)
            self._dtypes[name] = np.dtype(CHANNELS[name].dtype)
        for name, unit in (custom_channels or {}).items():
            if not _NAME_RE.match(name) or name in CHANNELS or name in LINEAR_ALIASES:
                raise RunFileError(f"{self.path}: bad custom channel name {name!r}")
            if not isinstance(unit, str) or not unit:
                raise RunFileError(f"{self.path}: custom channel {name!r} needs a unit string")
            self.units[name] = unit
            self._dtypes[name] = np.dtype("f8")
        missing = [c for c in REQUIRED_CHANNELS if c not in self.units]
        if missing:
            raise RunFileError(f"{self.path}: channels must include {', '.join(missing)}")
        self.channels = tuple(self.units)
        # at most MAX_CHUNK samples (8 MiB of float64 per channel) held in memory, whatever the rate
        self.chunk = max(1, min(MAX_CHUNK, int(flush_interval * self.sample_rate)))
        self.flush_interval = float(flush_interval)
        self._pending: dict[str, list[np.ndarray]] = {c: [] for c in self.channels}
        self._n_pending = 0
        self._n_written = 0
        self._n_events = 0
        self._last_t = math.nan
        self._last_index = -1
        self._status = "running"
        self._lock_fd: int | None = None

        for name, text in (("operator", operator), ("notes", notes), ("source", source),
                           ("protocol_name", protocol_name), *((f"unit of {k!r}", u) for k, u in
                                                               (custom_channels or {}).items())):
            _check_text(self.path, name, text)
        # the whole header is validated before anything is touched: a bad one is refused in one line
        self.identity = _header_field(self.path, DeviceIdentity.from_mapping, device)
        for what, value in (("device config", config), ("device calibration", calibration),
                            ("protocol parameters", protocol_params)):
            _header_field(self.path, _json_text, value, what)
        if os.path.lexists(self.path) and not overwrite:
            raise RunFileError(f"{self.path}: file exists (choose another name, or pass --overwrite to replace it)")
        try:  # never renamed over /dev/null, a FIFO or a folder (issue 30 item 17)
            mode = os.stat(self.path).st_mode
        except FileNotFoundError:
            mode = stat.S_IFREG
        except OSError as exc:
            raise RunFileError(f"{self.path}: cannot use as a run file ({exc.strerror})") from None
        if not stat.S_ISREG(mode):
            raise RunFileError(f"{self.path} is not a regular file; a run file is written as a file and would "
                               "replace it: choose a file name")
        self._take_lock()
        # The file is built under a temporary name and appears at its path only once its layout is complete
        # and it is in SWMR mode, by an atomic rename (overwrite) or link (no overwrite): an old file is never
        # destroyed before a readable new one replaces it, and a kill at any moment leaves either nothing
        # new at the path or a repairable run. The protocol arrays (possibly long) are written after that.
        head, tail = os.path.split(self.path)
        for stale in glob.glob(os.path.join(glob.escape(head or "."), f".{glob.escape(tail)}.*.partial")):
            os.unlink(stale)  # left by a writer of this path killed while creating it (we hold its lock)
        self._tmp_path = os.path.join(head, f".{tail}.{uuid.uuid4().hex[:12]}.partial")
        self._file = None
        try:
            # no raw-data chunk cache: every chunk goes to the disk when written, so a full disk shows at
            # that write and nothing dirty is left that a later flush (marking the run failed) would need
            self._file = h5py.File(self._tmp_path, "x", libver="latest", rdcc_nbytes=0)
            later = self._create_layout(
                config, calibration, protocol_name, protocol_params, protocol_arrays, operator, notes,
                source, compression, start_time,
            )
            self._file.flush()
            self._file.swmr_mode = True  # no new objects from here on
            self._place(overwrite)
        except BaseException as exc:
            if self._file is not None:
                try:
                    self._file.close()
                except (OSError, RuntimeError):
                    pass
            if os.path.lexists(self._tmp_path):
                os.unlink(self._tmp_path)
            self._release_lock()
            if isinstance(exc, OSError):
                raise RunFileError(f"{self.path}: cannot create the run file: {_one_line(exc)}") from None
            raise
        try:  # the file is at its path now: a failure from here on ends it 'failed', never half-made
            for ds, array in later:
                ds[...] = array
            self._file.flush()
        except (OSError, RuntimeError, ValueError, TypeError) as exc:
            self._fail(f"cannot write the protocol arrays: {_one_line(exc)}")

    def _place(self, overwrite: bool) -> None:
        try:
            if overwrite:
                os.replace(self._tmp_path, self.path)
            else:
                os.link(self._tmp_path, self.path)  # fails if a file appeared meanwhile: never clobbers
                os.unlink(self._tmp_path)
        except FileExistsError:
            raise RunFileError(f"{self.path}: file exists (choose another name, or pass --overwrite to replace "
                               "it)") from None

    # -- setup ---------------------------------------------------------------------------------------------

    def _take_lock(self) -> None:
        import fcntl

        lock = lock_path(self.path)
        try:  # never follow a planted symlink, never block on a planted fifo
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
        except OSError as exc:
            raise RunFileError(f"{self.path}: cannot use the lock file {lock} ({_one_line(exc)}; a symlink "
                               f"there is refused)") from None
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode) or st.st_nlink != 1:
            os.close(fd)
            raise RunFileError(f"{self.path}: the lock file {lock} is not a plain file of its own "
                               f"(a link or a device); remove it")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise RunFileError(f"{self.path}: another process is writing this run") from None
        try:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()} {socket.gethostname()}\n".encode())
            os.posix_fallocate(fd, 0, RESERVE_BYTES)
        except OSError as exc:
            os.close(fd)
            os.unlink(lock)
            raise RunFileError(f"{self.path}: cannot reserve {RESERVE_BYTES} bytes beside the run "
                               f"({_one_line(exc)}); is the disk full?") from None
        self._lock_fd = fd

    def _release_lock(self) -> None:
        if self._lock_fd is None:
            return
        try:
            os.unlink(lock_path(self.path))
        except FileNotFoundError:
            pass
        os.close(self._lock_fd)
        self._lock_fd = None

    def _create_layout(
        self, config, calibration, protocol_name, protocol_params, protocol_arrays, operator, notes,
        source, compression, start_time,
    ) -> None:
        f = self._file
        self.uid = uuid.uuid4().hex
        attrs = {
            "schema": SCHEMA,
            "schema_version": SCHEMA_VERSION,
            "uid": self.uid,
            "status": "running",
            "start_time": start_time or utc_now(),
            "end_time": "",
            "axis": self.axis,
            "sample_rate": self.sample_rate,
            "flush_interval": self.flush_interval,
            "operator": str(operator),
            "notes": str(notes),
            "source": str(source),
            "record": self.record,
            "writer_pid": os.getpid(),
            "writer_host": socket.gethostname(),
        }
        for key, value in software_versions().items():
            attrs[f"software_{key}"] = value
        if self.torque_timing is not None:
            attrs["torque_timing"] = self.torque_timing
        for key, value in attrs.items():
            f.attrs[key] = value

        dev = f.create_group("device")
        _json_dataset(dev, "identity", self.identity.as_json())
        _json_dataset(dev, "config", config)
        _json_dataset(dev, "calibration", calibration)

        later: list[tuple[h5py.Dataset, np.ndarray]] = []
        proto = f.create_group("protocol")
        proto.attrs["name"] = str(protocol_name)
        _json_dataset(proto, "parameters", protocol_params)
        for name, array in (protocol_arrays or {}).items():
            if not _NAME_RE.match(name) or name == "parameters":
                raise RunFileError(f"{self.path}: bad protocol array name {name!r}")
            array = np.asarray(array)
            numeric = array.dtype.kind in "biuf" or (array.dtype.names and not array.dtype.hasobject)
            if not numeric or array.ndim > 2 or array.size > MAX_SAMPLES:
                raise RunFileError(f"{self.path}: protocol array {name!r} must be numeric, at most 2-D and at "
                                   f"most {MAX_SAMPLES} values, got {array.dtype} {array.shape}")
            big = array.size > 4096  # e.g. a whole setpoint array: compress it like the samples
            ds = proto.create_dataset(
                name, shape=array.shape, dtype=array.dtype, compression=compression if big else None,
                compression_opts=1 if big and compression == "gzip" else None,
                shuffle=big and compression is not None, chunks=True if big else None,
            )
            later.append((ds, array))  # written once the file is in SWMR mode and at its path

        samples = f.create_group("samples")
        samples.attrs["chunk"] = self.chunk
        samples.attrs["channels"] = list(self.channels)  # recording order (HDF5 lists names alphabetically)
        self._datasets: dict[str, h5py.Dataset] = {}
        for name in self.channels:
            ds = samples.create_dataset(
                name, shape=(0,), maxshape=(None,), chunks=(self.chunk,), dtype=self._dtypes[name],
                compression=compression, compression_opts=1 if compression == "gzip" else None,
                shuffle=compression is not None,
            )
            ds.attrs["unit"] = self.units[name]
            ds.attrs["description"] = CHANNELS[name].description if name in CHANNELS else "custom channel"
            self._datasets[name] = ds
        self._events = f.create_dataset(
            "events", shape=(0,), maxshape=(None,), chunks=(64,), dtype=EVENT_DTYPE
        )
        return later

    # -- recording -----------------------------------------------------------------------------------------

    @property
    def n_samples(self) -> int:
        """Samples appended so far (written or still buffered)."""
        return self._n_written + self._n_pending

    @property
    def status(self) -> str:
        """``running`` until finished; then ``completed``, ``aborted`` or ``failed``."""
        return self._status

    @property
    def n_flushed(self) -> int:
        """Samples written and flushed to the file (safe from a crash)."""
        return self._n_written

    def _check_open(self) -> None:
        if self._status != "running":
            raise RunFileError(f"{self.path}: run already finished ({self._status})")

    def append(self, block: Mapping[str, Any] | np.ndarray) -> None:
        """Append a block of samples.

        Args:
            block: mapping (or numpy structured array) from every declared channel name to a 1-D array;
                all arrays have the same length. Units are those of the file (see ``self.units``).

        Whole chunks are written and flushed as soon as they are complete, so after this call less than
        one chunk (``flush_interval`` s of device time) is held only in memory.
        """
        self._check_open()
        names = block.dtype.names if isinstance(block, np.ndarray) else tuple(block.keys())
        if names != self.channels and (names is None or set(names) != set(self.channels)):
            got = set(names or ())
            missing, extra = sorted(set(self.channels) - got), sorted(got - set(self.channels))
            raise RunFileError(f"{self.path}: block channels differ (missing {missing}, unexpected {extra})")
        arrays = {}
        n = None
        for name in self.channels:
            a = self._as_channel(name, block[name])
            if a.ndim != 1 or (n is not None and a.size != n):
                raise RunFileError(f"{self.path}: block channel {name!r} must be 1-D, as long as the others")
            n = a.size
            arrays[name] = a
        if not n:
            return
        for name, a in arrays.items():
            self._pending[name].append(a)
        self._n_pending += n
        self._last_t = float(arrays["t"][-1])
        self._last_index = int(arrays["sample_index"][-1])
        if self._n_pending >= self.chunk:
            self._write(whole_chunks_only=True)

    def _as_channel(self, name: str, value: Any) -> np.ndarray:
        """``value`` as the channel's dtype, refusing what the cast would change silently: text, complex
        values (the imaginary part), non-integral or non-finite values in an integer channel, overflow."""
        dtype = self._dtypes[name]
        try:
            raw = np.asarray(value)
            if raw.dtype.kind not in "biuf":
                raise TypeError(f"{raw.dtype} values")
            if dtype.kind == "i" and raw.dtype.kind in "uf":
                info = np.iinfo(dtype)
                exact = np.isfinite(raw) & (raw == np.round(raw)) & (raw >= info.min) & (raw <= info.max) \
                    if raw.dtype.kind == "f" else raw <= info.max
                if not np.all(exact):
                    raise ValueError("values that are not whole numbers within int64")
            return np.array(raw, dtype=dtype, copy=True, ndmin=1)
        except (TypeError, ValueError, OverflowError) as exc:
            raise RunFileError(f"{self.path}: block channel {name!r} must hold real numbers "
                               f"({dtype.name}); got {_one_line(exc)}") from None

    def _write(self, whole_chunks_only: bool) -> None:
        n_write = self._n_pending - self._n_pending % self.chunk if whole_chunks_only else self._n_pending
        if n_write == 0:
            return
        start, stop = self._n_written, self._n_written + n_write
        if stop > MAX_SAMPLES:
            self._fail(f"the run reached {MAX_SAMPLES} samples, the bound of a run file channel")
        memory_space = h5py.h5s.create_simple((n_write,))
        try:
            for name, ds in self._datasets.items():
                pieces = self._pending[name]
                data = np.concatenate(pieces) if len(pieces) > 1 else pieces[0]
                self._pending[name] = [data]
                ds.id.set_extent((stop,))
                file_space = ds.id.get_space()
                file_space.select_hyperslab((start,), (n_write,))
                # low level: 3x less overhead than ds[start:stop] = ...
                ds.id.write(memory_space, file_space, np.ascontiguousarray(data[:n_write]))
            self._file.flush()
        except (OSError, RuntimeError, ValueError) as exc:
            self._fail(f"write failed: {_one_line(exc)}")
        for name in self._datasets:  # only samples that reached the disk leave the buffer
            data = self._pending[name][0]
            self._pending[name] = [data[n_write:]] if n_write < data.size else []
        self._n_written = stop
        self._n_pending -= n_write

    def _fail(self, reason: str) -> None:
        """The file cannot take more (disk full, I/O error): give back the reserve, cut every channel back to
        the samples flushed before, record the reason, mark the run ``failed`` and close. Raises
        :class:`RunFileError`; samples still in memory are reported lost, never written half."""
        if self._lock_fd is not None:
            os.ftruncate(self._lock_fd, 0)  # the reserve: room for the metadata below on a full disk
        n = self._n_written
        marked = True
        try:
            for ds in self._datasets.values():
                ds.id.set_extent((n,))
            self._add_event_row("error", reason, self._last_index, self._last_t)
            self._file.attrs.modify("end_time", utc_now())
            self._file.attrs.modify("status", "failed")
            self._file.flush()
        except (OSError, RuntimeError, ValueError):
            marked = False
        finally:
            self._status = "failed"
            try:
                self._file.close()
            except (OSError, RuntimeError, ValueError):
                marked = False
            self._release_lock()
        lost = self._n_pending
        end = "the file says 'failed'" if marked else "the file could not be marked and reads as 'crashed'"
        raise RunFileError(f"{self.path}: {reason}; the run stopped: {n} flushed samples kept, {lost} not "
                           f"yet flushed lost, {end}")
    def flush(self) -> None:
        """Write every buffered sample (including a partial chunk) and flush the file."""
        self._check_open()
        self._write(whole_chunks_only=False)
        self._file.flush()

    def add_event(
        self, kind: str, message: str = "", *, t: float | None = None, sample_index: int | None = None
    ) -> None:
        """Record an event (fault, pause, resume, abort, error, info) and flush it at once.

        Args:
            kind: one of :data:`EVENT_KINDS`.
            message: free text, cut to 256 UTF-8 bytes.
            t: device time in s (default: the last appended sample's t, NaN before any sample).
            sample_index: device sample index (default: the last appended one, -1 before any sample).
        """
        self._check_open()
        if kind not in EVENT_KINDS:
            raise RunFileError(f"{self.path}: event kind must be one of {EVENT_KINDS}, got {kind!r}")
        try:
            self._add_event_row(kind, message, self._last_index if sample_index is None else sample_index,
                                self._last_t if t is None else t)
            self._file.flush()
        except (OSError, RuntimeError) as exc:
            self._fail(f"write failed: {_one_line(exc)}")

    def _add_event_row(self, kind: str, message: str, sample_index: int, t: float) -> None:
        row = np.array([(sample_index, t, time.time(), kind.encode(), _encode_message(str(message)))],
                       dtype=EVENT_DTYPE)
        self._events.resize((self._n_events + 1,))
        self._events[self._n_events] = row[0]
        self._n_events += 1

    def finish(self, status: str = "completed") -> None:
        """Write what is buffered, set ``end_time`` and ``status`` (``completed`` or ``aborted``), close.

        Calling it again is a no-op.
        """
        if self._status != "running":
            return
        if status not in FINAL_STATUSES:
            raise RunFileError(f"{self.path}: finish status must be one of {FINAL_STATUSES}, got {status!r}")
        self._write(whole_chunks_only=False)  # a failure here ends the run 'failed' (and raises)
        try:
            self._file.attrs.modify("end_time", utc_now())
            self._file.attrs.modify("status", status)
            self._file.flush()
        except (OSError, RuntimeError) as exc:
            self._fail(f"cannot mark the run {status}: {_one_line(exc)}")
        self._status = status
        self._file.close()
        self._release_lock()

    def abort(self, message: str = "aborted by operator") -> None:
        """Record an ``abort`` event and finish with status ``aborted``."""
        self.add_event("abort", message)
        self.finish("aborted")

    def __enter__(self) -> RunWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if self._status != "running":
            return False
        if exc_type is None:
            self.finish("completed")
        else:
            try:
                if issubclass(exc_type, KeyboardInterrupt):
                    self.add_event("abort", "interrupted by the operator (Ctrl-C)")
                else:
                    self.add_event("error", f"{exc_type.__name__}: {exc}")
            finally:
                self.finish("aborted")
        return False


# ---- reading ---------------------------------------------------------------------------------------------




def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    m = re.search(r"errno = (\d+), error message = '([^']*)'", text)  # HDF5's long I/O failure report
    return f"{m.group(2)} (errno {m.group(1)})" if m else text


def _open_h5(path: str, mode: str = "r") -> h5py.File:
    """Open for reading: finished files plainly; files still flagged "open for write" (live or crashed) in
    SWMR-read mode, which HDF5 allows for them."""
    if not os.path.exists(path):
        raise RunFileError(f"{path}: no such file")
    try:
        try:
            return h5py.File(path, mode)
        except OSError as exc:
            if mode != "r" or "already open for write" not in str(exc):
                raise
        if not writer_alive(path):
            check_not_truncated(path)
        return h5py.File(path, "r", libver="latest", swmr=True)
    except OSError as exc:
        reason = _one_line(exc)
        if "signature" in reason:
            reason = "not an HDF5 file"
        raise RunFileError(f"{path}: cannot open run file: {reason}") from None


class Run:
    """A run file opened for reading (live, finished or crashed). Use :func:`open_run`.

    Attributes:
        path, uid, axis (``rotary``/``linear``), sample_rate (Hz), start_time, end_time (ISO 8601 UTC).
        meta: every root attribute as a plain dict (str/int/float).
        stored_status: the ``status`` attribute as written.
        device, config, calibration, protocol_params: dicts decoded from their JSON datasets.
        protocol_name: str.
        channels: names of the sample channels present.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = os.fspath(path)
        self._file = _open_h5(self.path)
        try:
            self._load()
        except RunFileError:
            self._file.close()
            raise
        except (OSError, KeyError, ValueError, RuntimeError, TypeError) as exc:
            self._file.close()
            raise RunFileError(f"{self.path}: damaged or not a run file ({_one_line(exc)})") from None

    def _load(self) -> None:
        f = self._file
        self.meta: dict[str, Any] = {}
        for key, value in f.attrs.items():
            is_text = isinstance(value, str | bytes | np.bytes_)
            self.meta[key] = _text(value) if is_text else np.asarray(value).item()
        if self.meta.get("schema") != SCHEMA:
            raise RunFileError(f"{self.path}: not a hilbench run file (no schema={SCHEMA!r} attribute)")
        version = self.meta.get("schema_version")
        if version not in SCHEMA_VERSIONS:
            raise RunFileError(f"{self.path}: unsupported run-file schema version {version} (bench reads "
                               f"{', '.join(map(str, SCHEMA_VERSIONS))})")
        self.uid = self.meta["uid"]
        self.axis = self.meta["axis"]
        self.sample_rate = float(self.meta["sample_rate"])
        self.start_time = self.meta["start_time"]
        self.stored_status = self.meta["status"]
        self.software = {k[len("software_"):]: v for k, v in self.meta.items() if k.startswith("software_")}
        self.device = self._json("device/identity")  # as stored; :attr:`identity` is the typed reading
        self.config = self._json("device/config")
        self.calibration = self._json("device/calibration")
        self.protocol_name = _text(f["protocol"].attrs.get("name", ""))
        self.protocol_params = self._json("protocol/parameters")
        self._samples = f["samples"]
        order = [_text(n) for n in self._samples.attrs.get("channels", [])]
        present = set(self._samples.keys())
        self.channels = tuple([n for n in order if n in present] + sorted(present - set(order)))
        for required in REQUIRED_CHANNELS:
            if required not in self.channels:
                raise RunFileError(f"{self.path}: sample channel {required!r} is missing")
        self._units = {name: _text(self._samples[name].attrs["unit"]) for name in self.channels}
        for name in self.channels:
            self._check_size(f"channel {name!r}", self._samples[name].shape)
        self._check_size("events", f["events"].shape)
        self.n_samples = min(self._samples[name].shape[0] for name in self.channels)

    @property
    def identity(self) -> DeviceIdentity:
        """The typed ``/device/identity`` (:class:`RunFileError` in one line if the file's breaks the schema)."""
        return _header_field(self.path, DeviceIdentity.from_mapping, self.device)

    def _check_size(self, what: str, shape: tuple[int, ...]) -> None:
        check_size(self.path, what, shape)

    def _json(self, name: str) -> dict[str, Any]:
        raw = self._file[name][()]
        return json.loads(_text(raw))

    @property
    def end_time(self) -> str:
        return _text(self._file.attrs["end_time"])

    @property
    def writer_alive(self) -> bool:
        """True while a live process is still writing this file."""
        return writer_alive(self.path)

    @property
    def status(self) -> str:
        """``completed``, ``aborted``, ``crashed``, or ``running`` while a live writer holds the file.

        A file that says ``running`` with no live writer is reported ``crashed`` (use :func:`repair` to
        write that into the file)."""
        stored = _text(self._file.attrs["status"])
        if stored == "running" and not self.writer_alive:
            return "crashed"
        return stored

    @property
    def meta_json(self) -> dict[str, Any]:
        """Everything but the samples as one JSON-able dict."""
        return {
            "path": self.path, "status": self.status, "attributes": dict(self.meta), "device": self.device,
            "config": self.config, "calibration": self.calibration,
            "protocol": {"name": self.protocol_name, "parameters": self.protocol_params},
        }

    @property
    def duration(self) -> float:
        """Span of device time in s: ``t[-1] - t[0]`` (0 for fewer than 2 samples)."""
        if self.n_samples < 2:
            return 0.0
        ds = self._samples["t"]
        return float(ds[self.n_samples - 1] - ds[0])

    def _resolve(self, name: str) -> str:
        if name in self.channels:
            return name
        if self.axis == "linear" and LINEAR_ALIASES.get(name) in self.channels:
            return LINEAR_ALIASES[name]
        raise RunFileError(f"{self.path}: no channel {name!r} in this run (has: {', '.join(self.channels)})")

    def channel(self, name: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Samples ``[start, stop)`` of a channel (all complete samples by default), in the unit :meth:`unit`.

        ``force``/``force_cmd`` are accepted as names of ``torque``/``torque_cmd`` on a linear axis."""
        name = self._resolve(name)
        stop = self.n_samples if stop is None else min(stop, self.n_samples)
        try:
            return self._samples[name][start:stop]
        except (OSError, RuntimeError) as exc:
            raise RunFileError(f"{self.path}: cannot read channel {name!r}: {_one_line(exc)}") from None

    def unit(self, name: str) -> str:
        """Unit of a channel, e.g. ``N*m`` (rotary torque) or ``N`` (linear force)."""
        return self._units[self._resolve(name)]

    @property
    def t(self) -> np.ndarray:
        """Device time in s, shape (n_samples,)."""
        return self.channel("t")

    @property
    def units(self) -> dict[str, str]:
        return dict(self._units)

    @property
    def events(self) -> np.ndarray:
        """Events: structured array of sample_index, t (s), wall_time (UNIX s), kind and message (str)."""
        ev = self._file["events"]
        if self._file.swmr_mode:
            ev.refresh()
        raw = ev[()]
        out = np.empty(raw.shape, dtype=[("sample_index", "i8"), ("t", "f8"), ("wall_time", "f8"),
                                          ("kind", "U16"), ("message", f"U{EVENT_MESSAGE_BYTES}")])
        for field in ("sample_index", "t", "wall_time"):
            out[field] = raw[field]
        out["kind"] = [_text(k) for k in raw["kind"]]
        out["message"] = [_text(m) for m in raw["message"]]
        return out

    @property
    def protocol_array_names(self) -> tuple[str, ...]:
        return tuple(k for k in self._file["protocol"].keys() if k != "parameters")

    def protocol_array(self, name: str) -> np.ndarray:
        """An array stored under ``/protocol`` (e.g. ``step_windows``)."""
        if name not in self.protocol_array_names:
            have = ", ".join(self.protocol_array_names)
            raise RunFileError(f"{self.path}: no protocol array {name!r} (has: {have})")
        ds = self._file["protocol"][name]
        self._check_size(f"protocol array {name!r}", ds.shape)
        return ds[()]

    def refresh(self) -> int:
        """Pick up samples a live writer has flushed since opening; returns the new ``n_samples``."""
        if not self._file.swmr_mode:
            return self.n_samples  # opened after the writer finished: nothing more will come
        for name in self.channels:
            self._samples[name].refresh()
        self.n_samples = min(self._samples[name].shape[0] for name in self.channels)
        return self.n_samples

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> Run:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_run(path: str | os.PathLike, *, repair: bool = False) -> Run:
    """Open a run file for reading. With ``repair=True`` a crashed file is first marked ``crashed``
    (see :func:`repair`). Raises :class:`RunFileError` for missing, truncated or foreign files."""
    if repair:
        _repair_file(path)
    return Run(path)


# ---- repair ----------------------------------------------------------------------------------------------


def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & 0xFFFFFFFF


def lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 ``hashlittle``: the checksum HDF5 puts on superblocks v2/v3 and object headers."""
    m = 0xFFFFFFFF
    a = b = c = (0xDEADBEEF + len(data) + initval) & m
    k = data
    while len(k) > 12:
        a = (a + int.from_bytes(k[0:4], "little")) & m
        b = (b + int.from_bytes(k[4:8], "little")) & m
        c = (c + int.from_bytes(k[8:12], "little")) & m
        a = (a - c) & m; a ^= _rot(c, 4); c = (c + b) & m  # noqa: E702
        b = (b - a) & m; b ^= _rot(a, 6); a = (a + c) & m  # noqa: E702
        c = (c - b) & m; c ^= _rot(b, 8); b = (b + a) & m  # noqa: E702
        a = (a - c) & m; a ^= _rot(c, 16); c = (c + b) & m  # noqa: E702
        b = (b - a) & m; b ^= _rot(a, 19); a = (a + c) & m  # noqa: E702
        c = (c - b) & m; c ^= _rot(b, 4); b = (b + a) & m  # noqa: E702
        k = k[12:]
    if not k:
        return c
    k = k.ljust(12, b"\0")  # the tail's missing bytes add nothing
    a = (a + int.from_bytes(k[0:4], "little")) & m
    b = (b + int.from_bytes(k[4:8], "little")) & m
    c = (c + int.from_bytes(k[8:12], "little")) & m
    c ^= b; c = (c - _rot(b, 14)) & m  # noqa: E702
    a ^= c; a = (a - _rot(c, 11)) & m  # noqa: E702
    b ^= a; b = (b - _rot(a, 25)) & m  # noqa: E702
    c ^= b; c = (c - _rot(b, 16)) & m  # noqa: E702
    a ^= c; a = (a - _rot(c, 4)) & m  # noqa: E702
    b ^= a; b = (b - _rot(a, 14)) & m  # noqa: E702
    c ^= b; c = (c - _rot(b, 24)) & m  # noqa: E702
    return c


_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _superblock(fh: Any, path: str) -> tuple[int, bytearray]:
    """Offset and bytes (fields + 4-byte checksum) of a v2/v3 superblock; empty bytes for v0/v1."""
    size = os.fstat(fh.fileno()).st_size
    offset = 0
    while True:  # the superblock sits at 0, 512, 1024, 2048, ... (after a user block)
        fh.seek(offset)
        head = fh.read(12)
        if head[:8] == _SIGNATURE and len(head) == 12:
            break
        offset = 512 if offset == 0 else offset * 2
        if offset >= size:
            raise RunFileError(f"{path}: not an HDF5 file")
    if head[8] < 2:
        return offset, bytearray()
    n = 12 + 4 * head[9]
    fh.seek(offset)
    block = bytearray(fh.read(n + 4))
    if len(block) < n + 4 or lookup3(bytes(block[:n])) != int.from_bytes(block[n : n + 4], "little"):
        raise RunFileError(f"{path}: HDF5 superblock damaged (checksum mismatch)")
    return offset, block


def check_not_truncated(path: str | os.PathLike) -> None:
    """Raise :class:`RunFileError` if the file is shorter than the end-of-file address in its superblock.

    Needed before a SWMR open: SWMR readers skip HDF5's own check and retry failed reads for a long time."""
    path = os.fspath(path)
    with open(path, "rb") as fh:
        offset, block = _superblock(fh, path)
        size = os.fstat(fh.fileno()).st_size
    if not block:
        return
    o = block[9]
    base = int.from_bytes(block[12 : 12 + o], "little")
    eof = int.from_bytes(block[12 + 2 * o : 12 + 3 * o], "little")
    if base + eof > size:
        raise RunFileError(f"{path}: truncated file ({size} bytes, the superblock expects {base + eof})")


def clear_write_flags(path: str | os.PathLike) -> bool:
    """Clear the "open for (SWMR) write" flags a dead writer left in a v2/v3 superblock and raise its
    end-of-file address to the file's real size (what ``h5clear -s`` and ``h5clear --increment=0`` do), so
    HDF5 opens the file for writing again. Returns True if flags were set.

    The end-of-file address matters: a writer killed between flushes may leave metadata beyond the address
    stored in the superblock, and new allocations there would collide with it. The superblock checksum is
    verified before and recomputed after the change."""
    path = os.fspath(path)
    with open(path, "r+b") as fh:
        offset, block = _superblock(fh, path)
        if not block or block[11] == 0:
            return False  # v0/v1 superblocks carry no write flags
        n = len(block) - 4
        o = block[9]
        base = int.from_bytes(block[12 : 12 + o], "little")
        eof = int.from_bytes(block[12 + 2 * o : 12 + 3 * o], "little")
        size = os.fstat(fh.fileno()).st_size
        block[12 + 2 * o : 12 + 3 * o] = max(eof, size - base).to_bytes(o, "little")
        block[11] = 0
        block[n:] = lookup3(bytes(block[:n])).to_bytes(4, "little")
        fh.seek(offset)
        fh.write(block)
        fh.flush()
        os.fsync(fh.fileno())
    return True


def repair(path: str | os.PathLike) -> str:
    """Mark a crashed run ``crashed`` and make it an ordinary HDF5 file again; returns the final status.

    A run is crashed when its status says ``running`` and no live process holds its writer lock. Repair
    clears the superblock's write flags, cuts every channel to the length of the shortest (the last flush
    may have reached some channels only), sets ``end_time`` to the file's last modification time, appends a
    ``crash`` event and removes the stale lock file. Finished files are left as they are.
    """
    path = os.fspath(path)
    with Run(path) as run:
        stored = run.stored_status
        n = run.n_samples
        last_t = float(run.channel("t", n - 1, n)[0]) if n else math.nan
        last_index = int(run.channel("sample_index", n - 1, n)[0]) if n else -1
    if writer_alive(path):
        if stored == "running":
            return "running"
        raise RunFileError(f"{path}: a live process holds the writer lock; not repairing")
    mtime = datetime.fromtimestamp(os.path.getmtime(path), UTC).isoformat(timespec="microseconds")
    if stored == "running" or _write_flags_set(path):
        # repaired on a copy that replaces the file by an atomic rename once complete: a failure (a full
        # disk) leaves the file as it was, and HDF5 never writes into a file it cannot finish
        head, tail = os.path.split(path)
        tmp = os.path.join(head, f".{tail}.{uuid.uuid4().hex[:12]}.repair")
        try:
            size = os.path.getsize(path)
            free = os.statvfs(head or ".").f_bavail * os.statvfs(head or ".").f_frsize
            if free < size + RESERVE_BYTES:
                raise RunFileError(f"{path}: cannot repair: it needs {size + RESERVE_BYTES} bytes free beside "
                                   f"the file (a copy plus {RESERVE_BYTES}), {free} are; the file is unchanged")
            shutil.copyfile(path, tmp)
            clear_write_flags(tmp)
            if stored == "running":
                _mark_crashed(tmp, n, last_index, last_t, mtime)
            with open(tmp, "rb") as fh:
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        except (OSError, RuntimeError, KeyError, ValueError) as exc:
            raise RunFileError(f"{path}: cannot repair: {_one_line(exc)}; the file is unchanged") from None
        finally:
            if os.path.lexists(tmp):
                os.unlink(tmp)
        if stored == "running":
            stored = "crashed"
    try:
        os.unlink(lock_path(path))
    except FileNotFoundError:
        pass
    return stored


def _write_flags_set(path: str) -> bool:
    with open(path, "rb") as fh:
        _, block = _superblock(fh, path)
    return bool(block) and block[11] != 0


def _mark_crashed(path: str, n: int, last_index: int, last_t: float, end_time: str) -> None:
    f = _open_h5(path, "r+")
    try:
        for ds in f["samples"].values():
            if ds.shape[0] > n:
                ds.resize((n,))
        message = _encode_message(f"writer died; samples kept up to the last flush ({n} samples)")
        row = np.array([(last_index, last_t, time.time(), b"crash", message)], dtype=EVENT_DTYPE)
        events = f["events"]
        events.resize((events.shape[0] + 1,))
        events[-1] = row[0]
        f.attrs["end_time"] = end_time
        f.attrs["status"] = "crashed"
    finally:
        f.close()


_repair_file = repair


def channel_summary(run: Run, names: Iterable[str] | None = None) -> list[dict[str, Any]]:
    """Per-channel unit, count, min, max, mean (NaN-aware) for display; reads each channel once."""
    out = []
    for name in names or run.channels:
        data = run.channel(name)
        row: dict[str, Any] = {"name": name, "unit": run.unit(name), "n": int(data.size)}
        if data.dtype.kind not in "biuf":  # a foreign file may hold text or compound data: shown, not summed
            row.update(min=None, max=None, mean=None, non_finite=0, not_numeric=str(data.dtype))
            out.append(row)
            continue
        finite = data[np.isfinite(data)] if data.dtype.kind == "f" else data
        if finite.size:
            row.update(min=float(finite.min()), max=float(finite.max()), mean=float(finite.mean()))
        else:
            row.update(min=None, max=None, mean=None)
        row["non_finite"] = int(data.size - finite.size)
        out.append(row)
    return out
