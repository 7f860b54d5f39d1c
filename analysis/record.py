"""One front door for every analysis: :func:`load_record` reads a run file into a :class:`Record`.

It does, once and the same way for the CLI, the GUI, campaigns and scripts (docs/record.md):

- the channel choice: the measured ``torque`` when the file has it, else the commanded ``torque_cmd``
  (``force``/``force_cmd`` on a linear axis name the same datasets), or the channel the caller asks for;
- the torque timing (what sample k of that channel means), from the caller, the file's declaration or its source;
- host-clock resampling: a drive that samples at each SYNC (CiA 402) is put on a uniform grid;
- the numeric checks (finite numbers within :data:`MAX_ABS_VALUE`), with one line naming the channel;
- the record kind (torque- or displacement-driven);
- the completeness checks: a run that is ``aborted``, ``crashed``, ``failed`` or still ``running``, that holds
  fewer samples than its plan, or that its device marked unfit is refused in one line naming the reason, unless
  the caller passes ``allow_incomplete`` (CLI ``--allow-incomplete``); then :attr:`Record.incomplete` says why
  and every report carries it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.common.runfile import (
    HOST_TIME,
    LINEAR_ALIASES,
    SAMPLE_KINDS,
    TORQUE_CMD,
    Run,
    RunFileError,
    host_sampled,
    open_run,
    record_kind,
    run_torque_timing,
)

#: the default torque channels, in order of preference
TORQUE_CHANNELS = ("torque", TORQUE_CMD)
#: Largest magnitude accepted in a channel. The analyses square and sum samples: 1e100 squared is 1e200, far from
#: float64's 1.8e308 even summed over 1e9 samples; real torques, forces and positions are many decades below.
MAX_ABS_VALUE = 1e100
#: the CLI option that lets an incomplete record through
ALLOW_OPTION = "--allow-incomplete"


def _open(path: Path) -> Run:
    """The run at ``path`` through the one reader; a file it refuses is an :class:`AnalysisError` here (one line)."""
    try:
        return open_run(path)
    except RunFileError as exc:
        raise AnalysisError(str(exc)) from None
    except OSError as exc:
        raise AnalysisError(f"{path}: cannot open: {' '.join(str(exc).split())}") from None


class IncompleteRecordError(AnalysisError):
    """The record is aborted, crashed, short of its plan or marked unfit by its device."""


@dataclass
class Record:
    """One run as every analysis reads it.

    Attributes:
        path: the run file. ``name``: its file name.
        axis: ``rotary`` (rad, N*m) or ``linear`` (m, N).
        sample_rate: Hz (the uniform grid of ``t``; a host-clocked run is resampled onto it).
        t: s, shape (n,), uniform. ``position``: rad or m, shape (n,). ``torque``: N*m or N, shape (n,), the
            channel ``torque_channel`` with sample timing ``timing`` (None when the caller did not need it).
        timing_origin: where ``timing`` comes from (given, declared in the file, default for its source).
        kind: ``torque-driven`` or ``displacement-driven``. ``source``: ``device`` or ``import:<format>``.
        status: as stored (``completed``, ``aborted``, ...); a ``running`` file without a writer reads ``crashed``.
        incomplete: None for a complete record, else why it is not (only when ``allow_incomplete`` let it through).
        channels: further channels the caller asked for, name -> array (same grid as ``t``).
        units: unit of every channel in the file.
        protocol_name, protocol_params, protocol_arrays: what the run played (only the arrays asked for).
        calibration, device: the file's device calibration and identity (dicts).
        events: (kind, message) of every event, in order.
        notes: what the loader did that a report should mention (resampling, the device's timing figures).
        lead: for a held-out tail, the run's samples before it (position, torque); see analysis.scoring.
    """

    path: Path
    axis: str
    sample_rate: float
    t: np.ndarray
    position: np.ndarray | None
    torque: np.ndarray | None
    torque_channel: str | None
    timing: str
    timing_origin: str
    kind: str
    source: str
    status: str
    incomplete: str | None = None
    channels: dict[str, np.ndarray] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    protocol_name: str = ""
    protocol_params: dict[str, Any] = field(default_factory=dict)
    protocol_arrays: dict[str, np.ndarray] = field(default_factory=dict)
    calibration: dict[str, Any] = field(default_factory=dict)
    device: dict[str, Any] = field(default_factory=dict)
    events: list[tuple[str, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    n_samples: int = 0  # samples of the record (set also when the arrays are not loaded: stream_record)
    #: (position, torque) of the same run before ``t[0]`` when the record is a held-out tail of it
    #: (analysis.record_split): the measured path the model's friction state runs along before the scored span
    #: (analysis.scoring); None for a record that starts its run
    lead: tuple[np.ndarray, np.ndarray] | None = None

    def __post_init__(self) -> None:
        if not self.n_samples and self.t is not None:
            self.n_samples = int(np.asarray(self.t).size)

    @property
    def name(self) -> str:
        return self.path.name

    @property
    def fs(self) -> float:
        return self.sample_rate

    def channel(self, name: str) -> np.ndarray:
        """A loaded channel by name (``position``, the torque channel, or one asked for in ``channels``)."""
        key = LINEAR_ALIASES.get(name, name) if self.axis == "linear" else name
        if key == "position" and self.position is not None:
            return self.position
        if key == self.torque_channel and self.torque is not None:
            return self.torque
        if key in self.channels:
            return self.channels[key]
        raise AnalysisError(f"{self.path}: channel {name!r} was not loaded (loaded: "
                            f"{', '.join(['position', str(self.torque_channel), *self.channels])})")

    def unit(self, name: str) -> str:
        """Unit of a channel of the file (``force`` names ``torque`` on a linear axis)."""
        key = LINEAR_ALIASES.get(name, name) if self.axis == "linear" else name
        if key not in self.units:
            raise AnalysisError(f"{self.path}: no channel {name!r} (has: {', '.join(sorted(self.units))})")
        return self.units[key]

    def arrays(self):
        """The record as :class:`hilbench.analysis.identification.identify.RunArrays`."""
        from hilbench.analysis.identification.identify import RunArrays

        if self.position is None:
            raise AnalysisError(f"{self.path}: no position channel loaded")
        return RunArrays(self.t, self.torque, self.position, self.axis, self.name, self.lead)

    def incomplete_line(self) -> str | None:
        """One line for a report when the record is incomplete, else None."""
        if self.incomplete is None:
            return None
        return f"INCOMPLETE RECORD {self.name}: {self.incomplete} (analysed with {ALLOW_OPTION})"


def choose_torque_channel(channels: Sequence[str], requested: str | None, path: object, axis: str = "rotary") -> str:
    """The torque channel to analyse: ``requested`` if given (must exist), else ``torque``, else ``torque_cmd``."""
    names = set(channels)
    aliases = LINEAR_ALIASES if axis == "linear" else {}
    if requested is not None:
        name = aliases.get(requested, requested)
        if name not in names:
            raise AnalysisError(f"{path}: no channel {requested!r} (has: {', '.join(sorted(names))})")
        return name
    for name in TORQUE_CHANNELS:
        if name in names:
            return name
    raise AnalysisError(f"{path}: no torque channel (torque or torque_cmd; has: {', '.join(sorted(names))})")


#: channels of sensor readings where NaN is the protocol's "no reading" (a missing value, not a damaged record)
READINGS = ("temperature",)


def numeric(values: Any, name: str, path: object, missing_ok: bool = False) -> np.ndarray:
    """``values`` as a float64 array, or a one-line :class:`AnalysisError` saying what is wrong with it.
    ``missing_ok``: NaN (no reading) passes; an infinity does not."""
    raw = np.asarray(values)
    if raw.dtype.kind not in "biuf":
        what = "strings" if raw.dtype.kind in "SUO" else raw.dtype.name
        raise AnalysisError(f"{path}: channel {name!r} holds {what}, not numbers")
    arr = raw.astype(float)
    bad = np.isinf(arr) if missing_ok else ~np.isfinite(arr)
    if bad.any():
        i = int(np.argmax(bad))
        raise AnalysisError(f"{path}: channel {name!r} has {int(bad.sum())} non-finite value(s), first at sample {i}")
    if arr.size and float(np.nanmax(np.abs(arr), initial=0.0)) > MAX_ABS_VALUE:
        i = int(np.nanargmax(np.abs(arr)))
        raise AnalysisError(f"{path}: channel {name!r} sample {i} is {arr[i]:.3g}, beyond the analysis bound "
                            f"+-{MAX_ABS_VALUE:g}")
    return arr


def completeness(run) -> str | None:
    """Why an open :class:`hilbench.common.runfile.Run` is not a complete record, or None.

    Incomplete: a status other than ``completed`` (with the abort or fault event's message when there is one);
    fewer samples than the protocol's ``setpoints`` (the plan; only its shape is read); an ``info`` event of the
    device that says the record is UNFIT (a host-clocked drive whose cycle timing broke its limits)."""
    status = run.status
    events = run.events
    if status != "completed":
        why = [str(e["message"]) for e in events if e["kind"] in ("abort", "fault", "error", "crash")]
        return f"the run is {status}" + (f" ({why[-1]})" if why else "")
    if "setpoints" in run.protocol_array_names:
        planned = int(run._file["protocol"]["setpoints"].shape[0])
        if run.n_samples < planned:
            return f"it holds {run.n_samples} of the {planned} planned samples"
    for e in events:
        if e["kind"] == "info" and "UNFIT" in str(e["message"]):
            return f"its device marked it unfit: {e['message']}"
    return None


def _checked_completeness(run, path: Path, allow_incomplete: bool) -> str | None:
    """:func:`completeness`, refused in one line unless ``allow_incomplete``."""
    reason = completeness(run)
    if reason is not None and not allow_incomplete:
        raise IncompleteRecordError(f"{path}: refusing an incomplete record: {reason}; pass {ALLOW_OPTION} to "
                                    "analyse it anyway (every report then says so)")
    return reason


def load_record(path: str | Path, *, torque_channel: str | None = None, timing: str = "auto",
                need_torque: bool = True, need_position: bool = True, channels: Sequence[str] = (),
                protocol_arrays: Sequence[str] = (), allow_incomplete: bool = False) -> Record:
    """Read a run file into a :class:`Record` (module docstring). Raises :class:`AnalysisError` in one line for a
    missing, damaged or foreign file, a missing or non-numeric channel, and (:class:`IncompleteRecordError`) an
    incomplete record unless ``allow_incomplete``."""
    path = Path(path)
    if not path.exists():
        raise AnalysisError(f"{path}: no such run file")
    with _open(path) as run:
        reason = _checked_completeness(run, path, allow_incomplete)
        if need_position and "position" not in run.channels:
            raise AnalysisError(f"{path}: no position channel (has: {', '.join(run.channels)})")
        name = choose_torque_channel(run.channels, torque_channel, path, run.axis) if need_torque else None
        t = numeric(run.channel("t"), "t", path)
        position = numeric(run.channel("position"), "position", path) if need_position else None
        torque = numeric(run.channel(name), name, path) if name is not None else None
        resolved, origin = run_torque_timing(run.meta, timing, name or "torque")
        extra = {}
        for c in channels:
            key = LINEAR_ALIASES.get(c, c) if run.axis == "linear" else c
            if key in run.channels and key not in ("position", name):
                extra[key] = numeric(run.channel(key), key, path, missing_ok=key in READINGS)
        notes: list[str] = []
        if host_sampled(run.device, run.channels):  # a drive sampled at each SYNC: on its real times
            host_time = numeric(run.channel(HOST_TIME), HOST_TIME, path)
            group: dict[str, tuple[np.ndarray, str]] = {}
            if position is not None:
                group["position"] = (position, "instant")
            if torque is not None:
                group["torque"] = (torque, resolved)
            for k, v in extra.items():
                group[k] = (v, "instant")
            t, out = resample_host_clocked(host_time, run.sample_rate, group)
            period = np.diff(host_time)
            line = (f"resampled on host_time: {period.size + 1} samples taken at {1e3 * period.min():.3f} to "
                    f"{1e3 * period.max():.3f} ms intervals -> {t.size} at {run.sample_rate:g} Hz")
            origin = f"{origin}; {line}"
            notes.append(line)
            position = out.get("position")
            torque = out.get("torque")
            extra = {k: out[k] for k in extra}
        events = [(str(e["kind"]), str(e["message"])) for e in run.events]
        notes += [m for k, m in events if k == "info" and m.startswith("host-clocked timing")]
        arrays = {}
        for a in protocol_arrays:
            if a in run.protocol_array_names:
                arrays[a] = run.protocol_array(a)
        return Record(
            path=path, axis=run.axis, sample_rate=run.sample_rate, t=t, position=position, torque=torque,
            torque_channel=name, timing=resolved, timing_origin=origin,
            kind=record_kind(run.meta.get("record"), path), source=str(run.meta.get("source", "device")),
            status=run.status, incomplete=reason, channels=extra, units=run.units,
            protocol_name=run.protocol_name, protocol_params=run.protocol_params, protocol_arrays=arrays,
            calibration=run.calibration, device=run.device, events=events, notes=notes)


#: samples per chunk of :meth:`ChannelReader.chunks` when the caller does not choose (a few MiB per channel set)
READER_CHUNK = 1 << 18


class ChannelReader:
    """A run file held open to read samples ``[start, stop)`` of its channels (context manager)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._run = _open(self.path)

    def __enter__(self) -> ChannelReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._run.close()

    @property
    def n_samples(self) -> int:
        return int(self._run.n_samples)

    def has(self, name: str) -> bool:
        key = LINEAR_ALIASES.get(name, name) if self._run.axis == "linear" else name
        return key in self._run.channels

    def protocol_array(self, name: str) -> np.ndarray | None:
        return self._run.protocol_array(name) if name in self._run.protocol_array_names else None

    def read(self, name: str, start: int, stop: int) -> np.ndarray:
        """Samples ``[start, stop)`` of channel ``name`` as float64, checked (one-line AnalysisError)."""
        return numeric(self._run.channel(name, start, stop), name, f"{self.path} (samples from {start})")

    def chunks(self, names: Sequence[str], chunk: int = READER_CHUNK, start: int = 0, stop: int | None = None,
               progress: Callable[[int, int], None] | None = None) -> Iterator[tuple[int, list[np.ndarray]]]:
        """``(first sample, [channel arrays])`` of at most ``chunk`` samples each, in order, from ``start`` to
        ``stop`` (default the end); ``progress(done, total)`` after each chunk."""
        stop = self.n_samples if stop is None else min(stop, self.n_samples)
        total = max(0, stop - start)
        for a in range(start, stop, max(1, int(chunk))):
            b = min(a + chunk, stop)
            yield a, [self.read(n, a, b) for n in names]
            if progress is not None:
                progress(b - start, total)


#: samples per chunk read from a file by :func:`stream_record` (two float64 channels: 2 MiB)
STREAM_CHUNK = 1 << 17


def stream_record(path: str | Path, *, torque_channel: str | None = None, timing: str = "auto",
                  allow_incomplete: bool = False, chunk: int = STREAM_CHUNK):
    """A record read chunk by chunk (docs/long-runs.md): ``(record, source)`` where ``record`` is the
    :class:`Record` of :func:`load_record` without its arrays (``t``, ``position``, ``torque`` empty;
    ``n_samples`` set) and ``source`` is a chunk source, a callable that returns a fresh iterator of
    ``(position, torque)`` pairs of at most ``chunk`` samples read from the file, each checked as
    :func:`numeric` does (the sample index in a message is the record's). The same checks as
    :func:`load_record` run first (completeness, channels, torque timing). A host-clocked run (resampled onto a
    uniform grid by a spline over the whole record) cannot stream: ``source`` is None and ``record`` is the
    whole :func:`load_record`."""
    path = Path(path)
    if not path.exists():
        raise AnalysisError(f"{path}: no such run file")
    if chunk < 1:
        raise AnalysisError(f"chunk size must be >= 1, got {chunk}")
    with _open(path) as run:
        if host_sampled(run.device, run.channels):
            return load_record(path, torque_channel=torque_channel, timing=timing,
                               allow_incomplete=allow_incomplete), None
        reason = _checked_completeness(run, path, allow_incomplete)
        if "position" not in run.channels:
            raise AnalysisError(f"{path}: no position channel (has: {', '.join(run.channels)})")
        name = choose_torque_channel(run.channels, torque_channel, path, run.axis)
        resolved, origin = run_torque_timing(run.meta, timing, name)
        n = run.n_samples
        empty = np.empty(0)
        record = Record(
            path=path, axis=run.axis, sample_rate=run.sample_rate, t=empty, position=None, torque=None,
            torque_channel=name, timing=resolved, timing_origin=origin,
            kind=record_kind(run.meta.get("record"), path), source=str(run.meta.get("source", "device")),
            status=run.status, incomplete=reason, units=run.units, protocol_name=run.protocol_name,
            protocol_params=run.protocol_params, calibration=run.calibration, device=run.device,
            events=[(str(e["kind"]), str(e["message"])) for e in run.events], n_samples=n)

    def chunks():
        with ChannelReader(path) as r:
            for _, (x, tau) in r.chunks(("position", name), chunk, stop=n):
                yield x, tau

    return record, chunks


def on_host_time(host_time: np.ndarray, rate: float, position: np.ndarray, torque: np.ndarray, timing: str
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """Position (sampled at ``host_time``) and torque (of sample timing ``timing``) of a host-clocked run on
    a uniform grid at ``rate``: (t, position, torque, one line saying so). See :func:`resample_host_clocked`."""
    t, r = resample_host_clocked(host_time, rate, {"position": (position, "instant"), "torque": (torque, timing)})
    period = np.diff(np.asarray(host_time, dtype=np.float64))
    line = (f"resampled on host_time: {period.size + 1} samples taken at {1e3 * period.min():.3f} to "
            f"{1e3 * period.max():.3f} ms intervals -> {t.size} at {rate:g} Hz")
    return t, r["position"], r["torque"], line


def resample_host_clocked(host_time: np.ndarray, rate: float, channels: dict[str, tuple[np.ndarray, str]]
                          ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Channels of a host-clocked record, sampled at the irregular times ``host_time``, on the uniform grid
    ``t_j = j/rate`` (s, from the first sample to the last), each in its own sample timing.

    Args:
        host_time: s, shape (n,), strictly increasing: when the drive sampled (the SYNC went out).
        rate: nominal rate, Hz.
        channels: name -> (values of shape (n,), kind). ``instant`` (a value at s_k: position, velocity) is
            interpolated by a cubic spline through (s_k, x_k) (not-a-knot; the motion is smooth between
            samples, and a straight line would bend the second difference the identification reads);
            ``hold_next`` (held over [s_k, s_k+1): a command) and ``hold_previous`` (the mean over
            [s_k-1, s_k): a current measured at s_k) are averaged over each grid interval, which keeps the
            integral (the impulse) of the held signal exact: out_j = (F(t_j+1) - F(t_j)) * rate with F the
            running integral, piecewise linear between the s_k.
    Returns:
        (t, resampled): t of shape (m,), m = floor((s_n-1 - s_0) * rate) + 1; each channel of shape (m,).
    """
    from scipy.interpolate import CubicSpline

    s = np.asarray(host_time, dtype=np.float64)
    s = s - s[0]
    if s.size < 4 or not np.all(np.diff(s) > 0):
        raise AnalysisError("host_time must hold 4 or more strictly increasing times to resample on it")
    period = 1.0 / rate
    m = int(np.floor(s[-1] * rate + 1e-9)) + 1
    t = np.arange(m) * period
    out = {}
    for name, (values, kind) in channels.items():
        v = np.asarray(values, dtype=np.float64)
        if kind == "instant":
            out[name] = CubicSpline(s, v)(t)
            continue
        if kind not in SAMPLE_KINDS:
            raise AnalysisError(f"{name}: unknown sample kind {kind!r} (expected {', '.join(SAMPLE_KINDS)})")
        # held values h_i over [s_i, s_i+1); the last one has no end: hold it over one nominal period
        held = v if kind == "hold_next" else np.append(v[1:], v[-1])
        edges = np.append(s, s[-1] + period)
        integral = np.concatenate([[0.0], np.cumsum(held * np.diff(edges))])
        means = np.diff(np.interp(np.append(t, t[-1] + period), edges, integral)) * rate
        out[name] = means if kind == "hold_next" else np.concatenate([[v[0]], means[:-1]])
    return t, out


# --- decimation read chunk by chunk (docs/long-runs.md, "A decimated copy") ---------------------------------------

#: bytes per kept sample of a decimated record: t, position and torque as float64
DECIMATED_BYTES_PER_SAMPLE = 24
#: how the note of a record cut to a bounded span starts (:func:`decimated_record` with ``max_samples``)
SPAN_NOTE = "analysed the first"


def bounded_span(budget: int, fixed: int, per_sample: int, runs: int) -> int:
    """The most samples each of ``runs`` runs may hold for an analysis whose peak is ``fixed + per_sample * samples``
    bytes (all runs together) to stay within ``budget`` bytes; 0 when not even ``fixed`` fits."""
    return max(0, (int(budget) - int(fixed)) // (int(per_sample) * max(1, int(runs))))


def span_note(record: Record) -> str | None:
    """The note of a record cut to a bounded span (:func:`decimated_record` with ``max_samples``), else None."""
    return next((n for n in record.notes if n.startswith(SPAN_NOTE)), None)


def decimation_factor(sample_rate: float, max_rate: float) -> int:
    """The smallest whole factor q that brings ``sample_rate`` (Hz) to at most ``max_rate`` (Hz); 1 when it is
    already there."""
    if not (np.isfinite(max_rate) and max_rate > 0):
        raise AnalysisError(f"decimated rate must be > 0 Hz, got {max_rate}")
    return max(1, int(np.ceil(sample_rate / max_rate - 1e-9)))


def block_average(position: np.ndarray, torque: np.ndarray, fs: float, q: int,
                  timing: str) -> tuple[np.ndarray, np.ndarray, float]:
    """Reduce a run by a whole factor q: the torque is averaged over blocks of q samples and the position is
    sampled at the matching block edge, so a torque held sample by sample stays exactly a held torque at fs/q
    (the block mean is its impulse over the block divided by the block's length). ``hold_next`` (torque held over
    [t_k, t_k+1)): block [k, k+q) with the position at t_k; ``hold_previous`` (mean over [t_k-1, t_k)): block
    (k-q, k] with the position at t_k; ``instant``: block centred on t_k (approximate). Returns (position, torque,
    fs/q); shapes (n // q,): a last partial block is dropped."""
    n = (position.size // q) * q
    blocks = torque[:n].reshape(-1, q).mean(axis=1)
    if timing == "hold_previous":
        x = position[q - 1:n:q]
    elif timing == "instant":
        x = position[q // 2:n:q]
    else:
        x = position[:n:q]
    return x, blocks, fs / q


def decimated_record(path: str | Path, max_rate: float, *, torque_channel: str | None = None, timing: str = "auto",
                     allow_incomplete: bool = False, chunk: int = STREAM_CHUNK,
                     progress: Callable[[int], None] | None = None, max_samples: int | None = None) -> Record:
    """The record of :func:`load_record` reduced to at most ``max_rate`` Hz by :func:`block_average`, read chunk by
    chunk: memory is the decimated copy (:data:`DECIMATED_BYTES_PER_SAMPLE` per kept sample) plus one chunk,
    whatever the record's length. The result equals ``block_average`` of the whole arrays bit for bit (each block's
    samples are summed in the same order; tests/analysis/test_record.py). A record already at or below
    ``max_rate`` is returned as read (q = 1). ``progress(samples)`` is called after each chunk with the samples
    read so far (for a progress bar). A host-clocked run is resampled whole first (:func:`stream_record`).
    ``max_samples`` (None: all) keeps only the first ``max_samples`` reduced samples and stops reading there, so
    the copy is bounded whatever the record's length (docs/long-runs.md, "A bounded span"); the result is then
    the reduction of the record cut at ``max_samples * q`` input samples, bit for bit.
    The record's ``notes`` say what was done (a cut span: a note starting with :data:`SPAN_NOTE`); ``n_samples``
    is the kept count."""
    rec, source = stream_record(path, torque_channel=torque_channel, timing=timing,
                                allow_incomplete=allow_incomplete, chunk=chunk)
    q = decimation_factor(rec.sample_rate, max_rate)
    n_in = rec.n_samples
    if max_samples is not None and max_samples < 1:
        raise AnalysisError(f"max_samples must be >= 1, got {max_samples}")
    limit = n_in // q if max_samples is None else min(n_in // q, int(max_samples))
    if source is None:  # host-clocked: already whole in memory
        x, tau, fs = block_average(rec.position[:limit * q], rec.torque[:limit * q], rec.sample_rate, q, rec.timing)
        if progress is not None:
            progress(n_in)
    else:
        xs: list[np.ndarray] = []
        taus: list[np.ndarray] = []
        carry_x, carry_tau = np.empty(0), np.empty(0)
        done = kept = 0
        for x_c, tau_c in source():
            done += x_c.size
            x_c, tau_c = np.concatenate([carry_x, x_c]), np.concatenate([carry_tau, tau_c])
            whole = min(x_c.size // q, limit - kept) * q
            if whole:
                bx, bt, _ = block_average(x_c[:whole], tau_c[:whole], rec.sample_rate, q, rec.timing)
                xs.append(bx.copy())  # a strided view would keep the whole chunk alive: memory of the full record
                taus.append(bt)
                kept += bx.size
            carry_x, carry_tau = x_c[whole:], tau_c[whole:]
            if progress is not None:
                progress(done)
            if kept >= limit and limit < n_in // q:  # a bounded span is full: read no further
                break
        x = np.concatenate(xs) if xs else np.empty(0)
        tau = np.concatenate(taus) if taus else np.empty(0)
        fs = rec.sample_rate / q
    notes = list(rec.notes)
    if q > 1:
        notes.append(f"decimated by {q} ({rec.sample_rate:g} -> {fs:g} Hz): torque averaged over blocks of {q} "
                     f"samples ({rec.timing}), position at the block edge; {n_in} -> {x.size} samples")
    if limit < n_in // q:
        notes.append(f"{SPAN_NOTE} {x.size / fs:.6g} s of {n_in / rec.sample_rate:.6g} s ({x.size} of "
                     f"{n_in // q} samples at {fs:g} Hz): a bounded span, docs/long-runs.md")
    return replace(rec, sample_rate=fs, t=np.arange(x.size) / fs, position=x, torque=tau, notes=notes,
                   n_samples=int(x.size))
