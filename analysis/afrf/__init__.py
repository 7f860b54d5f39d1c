"""AFRF of a measured stepped-sine record: :func:`analyse` (a :class:`hilbench.analysis.record.Record` read whole),
:func:`analyse_stream` (the run file read one step window at a time, the same result bit for bit) and
:func:`report` (JSON and figure). ``hilbench afrf RUN.h5``, the GUI and scripts call these, so one run gives one
answer. Simulated AFRFs are in :mod:`hilbench.analysis.afrf.frf`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hilbench.analysis.afrf.frf import AfrfResult
    from hilbench.analysis.channel_windows import Progress
    from hilbench.analysis.record import Record

#: bytes per sample of the whole path: the loader's t, position and torque (float64) and their checks' copies
ARRAY_BYTES_PER_SAMPLE = 48
ARRAY_BYTES_FIXED = 120 << 20
#: the window path holds one measure window (position, torque, the FFT and detrend copies)
WINDOW_BYTES_PER_SAMPLE = 96


@dataclass(frozen=True)
class AfrfSettings:
    """How a measured AFRF is taken: harmonics 1..``n_harmonics`` of each step's drive frequency."""

    n_harmonics: int = 3


def array_cost(samples: int) -> int:
    """Estimated peak bytes of :func:`analyse` on a record of ``samples`` read whole."""
    return ARRAY_BYTES_FIXED + ARRAY_BYTES_PER_SAMPLE * int(samples)


def stream_cost(window: int) -> int:
    """Estimated peak bytes of :func:`analyse_stream` whose longest measure window is ``window`` samples."""
    return ARRAY_BYTES_FIXED + WINDOW_BYTES_PER_SAMPLE * int(window)


def load(path: str | Path, **options) -> Record:
    """The record as :func:`analyse` needs it: position, the measured torque when the file has it (the drive
    phasor), the step windows; ``options`` go to :func:`hilbench.analysis.record.load_record`."""
    from hilbench.analysis.record import load_record

    return load_record(path, need_torque=False, channels=("torque",), protocol_arrays=("step_windows",), **options)


def _mode(params: dict) -> str:
    return str(params.get("mode") or params.get("params", {}).get("mode") or "current")


def _finish(result: AfrfResult, record: Record) -> AfrfResult:
    from hilbench.analysis.afrf.steps import breakaway_warning

    result.label = record.name
    result.settings = {"source": str(record.path), "mode": _mode(record.protocol_params),
                       "sample_rate": record.sample_rate, "incomplete": record.incomplete}
    line = breakaway_warning(result)
    result.warnings = [line] if line else []
    return result


def analyse(record: Record, settings: AfrfSettings | None = None, *, progress: Progress | None = None
            ) -> AfrfResult:
    """AFRF of a stepped-sine record read whole (:func:`load`): harmonics of ``position`` over each step's
    measure window (:mod:`hilbench.analysis.afrf.steps`), with the warnings of the input."""
    from hilbench.analysis.afrf.steps import afrf_of_steps, checked_windows

    settings = settings or AfrfSettings()
    windows = checked_windows(record.protocol_arrays.get("step_windows"), str(record.path), record.protocol_name)
    x = record.position
    torque = record.channels.get("torque")
    result = afrf_of_steps(str(record.path), record.sample_rate, windows, int(x.size),
                           lambda a, b: (x[a:b], torque[a:b] if torque is not None else None),
                           mode=_mode(record.protocol_params), axis=record.axis, n_harmonics=settings.n_harmonics,
                           progress=progress)
    return _finish(result, record)


def stream_header(path: str | Path, allow_incomplete: bool = False):
    """(record without arrays, step windows) of a run, checked as :func:`load` checks it, without reading the
    samples: what :func:`analyse_stream` and a memory estimate need. A host-clocked run (resampled whole) gives
    the whole record."""
    from hilbench.analysis.afrf.steps import checked_windows
    from hilbench.analysis.channel_windows import ChannelReader
    from hilbench.analysis.record import stream_record

    record, source = stream_record(path, allow_incomplete=allow_incomplete)
    if source is None:
        record = load(path, allow_incomplete=allow_incomplete)
        windows = record.protocol_arrays.get("step_windows")
    else:
        with ChannelReader(path) as reader:
            windows = reader.protocol_array("step_windows")
    return record, checked_windows(windows, str(path), record.protocol_name)


def analyse_stream(path: str | Path, settings: AfrfSettings | None = None, *, allow_incomplete: bool = False,
                   progress: Progress | None = None) -> AfrfResult:
    """:func:`analyse` reading the run file one measure window at a time (docs/long-runs.md): the same result bit
    for bit, in memory bounded by the longest window whatever the record's length."""
    from hilbench.analysis.afrf.steps import afrf_of_steps
    from hilbench.analysis.channel_windows import ChannelReader

    settings = settings or AfrfSettings()
    record, windows = stream_header(path, allow_incomplete)
    if record.position is not None:  # a host-clocked run was read whole
        return analyse(record, settings, progress=progress)
    with ChannelReader(path) as reader:
        has_torque = reader.has("torque")

        def read(a: int, b: int):
            return reader.read("position", a, b), reader.read("torque", a, b) if has_torque else None

        result = afrf_of_steps(str(record.path), record.sample_rate, windows, reader.n_samples, read,
                               mode=_mode(record.protocol_params), axis=record.axis,
                               n_harmonics=settings.n_harmonics, progress=progress)
    return _finish(result, record)


def report(result: AfrfResult, out_dir: str | Path, title: str | None = None) -> list[Path]:
    """``afrf.json`` (:meth:`AfrfResult.to_dict`, with ``warnings``) and ``afrf.png`` (the paper-style figure) in
    ``out_dir`` (created); returns the paths written."""
    from hilbench.analysis.afrf.frf import plot_afrf
    from hilbench.analysis.output_files import atomic_path, dumps, save_figure

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    js = out / "afrf.json"
    with atomic_path(js) as tmp:
        tmp.write_text(dumps(result.to_dict()))
    fig = plot_afrf(result, title=title or f"AFRF {result.label}", measured=True)
    return [js, save_figure(fig, out / "afrf.png", dpi=120)]
