"""Skeleton curves of chirp records: :func:`analyse` (records read whole), :func:`analyse_stream` (run files read
chunk by chunk into a decimated copy, :mod:`hilbench.analysis.skeleton.streaming`) and :func:`report` (JSON and
figure). ``hilbench skeleton``, the GUI and scripts call these, so one set of runs gives one answer.

Each run goes through ForceVib (:func:`hilbench.analysis.skeleton.forcevib.forcevib`, x = position, force = the
torque channel centred on the sample instants), then the runs are composed (:func:`~.forcevib.compose`). The
result carries the warnings of its input: a run that is no chirp, a composed amplitude range under
:data:`MIN_AMPLITUDE_RATIO`, a negative k_eq.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.common.units import AXIS_UNITS

if TYPE_CHECKING:
    from hilbench.analysis.channel_windows import Progress
    from hilbench.analysis.record import Record
    from hilbench.analysis.skeleton.forcevib import ForceVibResult, SkeletonCurves

#: a composed amplitude range (largest / smallest bin) under this is too narrow for a skeleton curve
MIN_AMPLITUDE_RATIO = 2.0
#: protocols whose runs the skeleton method applies to
CHIRP_PROTOCOLS = ("chirp",)
#: bytes per sample of ForceVib on whole arrays (the loader's copies, the analytic signal and its ratios, the
#: per-sample estimates; measured 740 B per added sample at 10 kHz, 0.1 to 0.3 M samples), and the fixed part
ARRAY_BYTES_PER_SAMPLE = 800
ARRAY_BYTES_FIXED = 160 << 20
#: the streamed path: one chunk and one spectrum segment (fixed), then ForceVib on the decimated copy: per sample
#: of the copy (the analytic signal, its ratios and the per-sample estimates), and per cell of the wavelet map:
#: the ridge's int8 back-pointer (the map itself is computed and consumed block by block, ``streamed_ridge``)
STREAM_BYTES_FIXED = 200 << 20
DECIMATED_BYTES_PER_SAMPLE = 400
MAP_BYTES_PER_CELL = 1
CURVE_NAMES = ("amplitude", "stiffness", "restoring_force", "energy", "amplitude_count", "velocity", "damping",
               "damping_force", "velocity_count")


@dataclass(frozen=True)
class SkeletonSettings:
    """How the skeleton is taken. ``mass``: J (kg*m^2) or m (kg), None = the runs' calibration ``inertia``;
    ``spring``: linear spring subtracted, N*m/rad (N/m); ``method``: ``cwt`` or ``hilbert``; ``fb``, ``fc``: the
    Morlet wavelet; ``band``: (f_min, f_max) Hz, None = from each run's spectrum; ``bins``: log-spaced bins per
    curve; ``compose``: ``rate``, ``updown`` or ``median`` (:func:`~.forcevib.compose`)."""

    mass: float | None = None
    spring: float = 0.0
    method: str = "cwt"
    fb: float = 0.5
    fc: float = 0.8
    band: tuple[float, float] | None = None
    bins: int = 30
    compose: str = "rate"

    def options(self) -> dict:
        """Keyword options of :func:`~.forcevib.forcevib` (the band is added per run)."""
        return {"fb": self.fb, "fc": self.fc} if self.method == "cwt" else {}


@dataclass
class SkeletonResult:
    """The composed curves of the runs and how they were read. ``per_run``: per run, its valid samples, amplitude
    range and how it was read (whole, or decimated by q); ``warnings``: one line each."""

    curves: SkeletonCurves
    runs: list[str]
    names: list[str]
    axis: str
    mass: float
    settings: SkeletonSettings
    incomplete: dict[str, str] = field(default_factory=dict)
    per_run: list[dict] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    @property
    def units(self) -> dict[str, str]:
        pos, trq = ("rad", "N*m") if self.axis == "rotary" else ("m", "N")
        return {"amplitude": pos, "stiffness": f"{trq}/{pos}", "restoring_force": trq, "energy": f"{trq}*{pos}",
                "velocity": f"{pos}/s", "damping": f"{trq}*s/{pos}", "damping_force": trq}

    def to_dict(self) -> dict:
        """The JSON document of ``hilbench skeleton --json``."""
        c = self.curves
        return {"runs": list(self.runs), "incomplete": dict(self.incomplete), "mass": self.mass,
                "spring": self.settings.spring, "method": self.settings.method, "compose": self.settings.compose,
                "units": self.units, **{k: getattr(c, k).tolist() for k in CURVE_NAMES},
                "per_run": self.per_run, "warnings": list(self.warnings)}


def centred_force(torque, timing: str):
    """Torque at the sample instants t_k from a logged channel: a value averaged over [t_k-1, t_k)
    (``hold_previous``) or held over [t_k, t_k+1) (``hold_next``) is centred half a sample off, which biases
    ForceVib's damping by ~5 %; the mean of two neighbours is centred on t_k (ends repeated)."""
    f = np.asarray(torque, float)
    if timing == "hold_previous":
        return 0.5 * (f + np.append(f[1:], f[-1]))
    if timing == "hold_next":
        return 0.5 * (f + np.insert(f[:-1], 0, f[0]))
    return f


def run_mass(settings: SkeletonSettings, records: Sequence[Record]) -> float:
    """J or m: the settings', else the first run's declared calibration ``inertia`` (every run must declare one)."""
    if settings.mass is not None:
        mass = settings.mass
    else:
        declared = [r.calibration.get("inertia") for r in records]
        if any(m is None for m in declared):
            raise AnalysisError("no mass given and a run declares no inertia in its calibration: give --mass J "
                                "(kg*m^2) or --mass MODEL.json (the model of hilbench identify on this axis) to "
                                "hilbench skeleton, --skeleton-mass to hilbench analyse, or [plant] inertia in the "
                                "campaign file (hilbench plan writes it)")
        mass = float(declared[0])
    if not (math.isfinite(mass) and mass > 0):
        raise AnalysisError(f"--mass must be positive, got {mass}")
    return mass


def _check(records: Sequence[Record], settings: SkeletonSettings) -> float:
    if not records:
        raise AnalysisError("a skeleton needs at least one run")
    if len({r.axis for r in records}) > 1:
        raise AnalysisError("runs mix rotary and linear axes")
    if not (math.isfinite(settings.spring) and settings.spring >= 0):
        raise AnalysisError(f"--spring must be >= 0, got {settings.spring}")
    return run_mass(settings, records)


def not_chirp_warning(run: str, protocol: str) -> str | None:
    """One line when the ``protocol`` of the run named ``run`` is known and is no chirp (an identification run gives
    F_k of -2e4 N*m)."""
    if not protocol or protocol in CHIRP_PROTOCOLS:
        return None
    return (f"{run} is a {protocol!r} run, not a chirp: ForceVib reads a response swept through one frequency "
            "at a time, so its k_eq and c_eq here are no skeleton; record one with hilbench run chirp")


def range_warning(curves: SkeletonCurves, unit: str) -> str | None:
    """One line when the composed amplitude range is under :data:`MIN_AMPLITUDE_RATIO` (largest/smallest bin)."""
    a = np.asarray(curves.amplitude, float)
    if a.size == 0:
        return None
    ratio = float(a.max() / a.min())
    if ratio >= MIN_AMPLITUDE_RATIO:
        return None
    return (f"the runs cover amplitudes {a.min():.4g} .. {a.max():.4g} {unit} only ({ratio:.2f}x, under "
            f"{MIN_AMPLITUDE_RATIO:g}x): too narrow a range for a skeleton curve; `hilbench plan` sizes a chirp "
            "from the motor (a log sweep above break-away), or compose chirps at several --gain values (hilbench "
            "skeleton RUN1.h5 RUN2.h5 ...), or sweep through the resonance")


def stiffness_warnings(curves: SkeletonCurves, units: dict, spring: float, mass: float) -> list[str]:
    """A negative k_eq is no stiffness: say so, and refuse (AnalysisError) when no bin is positive."""
    k = np.asarray(curves.stiffness, float)
    neg = np.isfinite(k) & (k < 0)
    if not neg.any():
        return []
    a = np.asarray(curves.amplitude, float)[neg]
    pos, trq = units["amplitude"], units["restoring_force"]
    mass_unit = AXIS_UNITS["rotary" if pos == AXIS_UNITS["rotary"]["position"] else "linear"]["inertia"]
    # quantities, not option names: the same text reaches hilbench skeleton (--spring, --mass) and the campaign
    # step of hilbench analyse (--skeleton-mass, or the campaign's [plant] inertia)
    why = (f"the restoring force is negative: the spring subtracted ({spring:g} {trq}/{pos}) is larger than the "
           f"system's, the mass used ({mass:g} {mass_unit}) is too large, or the system has no restoring force at "
           "these amplitudes (no spring, free sliding), where the skeleton method does not apply")
    if neg.all():
        raise AnalysisError(f"k_eq < 0 in every amplitude bin: {why}")
    return [f"k_eq < 0 in {int(neg.sum())} of {k.size} amplitude bins (A {a.min():.3g} .. {a.max():.3g} {pos}): "
            f"{why}"]


def _compose(results: list[ForceVibResult], records: Sequence[Record], paths: Sequence[str], mass: float,
             settings: SkeletonSettings, reads: list[str]) -> SkeletonResult:
    from hilbench.analysis.skeleton.forcevib import compose

    curves = compose(results, n_bins=settings.bins, method=settings.compose)
    result = SkeletonResult(curves, [str(p) for p in paths], [r.name for r in records], records[0].axis, mass,
                            settings, {str(r.path): r.incomplete for r in records if r.incomplete is not None})
    for r, res, read in zip(records, results, reads, strict=True):
        v = res.valid
        result.per_run.append({"run": r.name, "valid_samples": int(v.sum()), "amplitude_min":
                               float(res.amplitude[v].min()), "amplitude_max": float(res.amplitude[v].max()),
                               "read": read})
    result.warnings = [w for w in (not_chirp_warning(r.name, r.protocol_name) for r in records) if w]
    line = range_warning(curves, result.units["amplitude"])
    result.warnings += [line] if line else []
    result.warnings += stiffness_warnings(curves, result.units, settings.spring, mass)
    return result


def analyse(records: Sequence[Record], settings: SkeletonSettings | None = None, *,
            progress: Progress | None = None) -> SkeletonResult:
    """ForceVib on each record read whole (position, torque), composed into skeleton curves (module docstring)."""
    from hilbench.analysis.skeleton.forcevib import forcevib

    settings = settings or SkeletonSettings()
    mass = _check(records, settings)
    options = settings.options()
    if settings.band:
        options["freq_range"] = tuple(settings.band)
    results = []
    total, done = sum(r.n_samples for r in records), 0
    for r in records:
        results.append(forcevib(r.position, centred_force(r.torque, r.timing), r.sample_rate, mass,
                                settings.method, spring=settings.spring, **options))
        done += r.n_samples
        if progress is not None:
            progress(done, total)
    return _compose(results, records, [str(r.path) for r in records], mass, settings, ["whole"] * len(records))


def stream_band(reader, record: Record, settings: SkeletonSettings, chunk: int) -> tuple[float, float]:
    """Pass 1 of :mod:`~.streaming`: the analysis band of a run read chunk by chunk (the settings' band if set)."""
    from hilbench.analysis.skeleton.instantaneous import band_of_extent
    from hilbench.analysis.skeleton.streaming import streamed_extent

    if settings.band:
        return float(settings.band[0]), float(settings.band[1])
    extent = streamed_extent((c[0] for _, c in reader.chunks(["position"], chunk)), reader.n_samples,
                             record.sample_rate)
    if settings.method == "hilbert":
        return 0.0, extent[1]
    return band_of_extent(reader.n_samples, record.sample_rate, extent, settings.fb, settings.fc, 4.0)


def analyse_stream(paths: Sequence[str | Path], settings: SkeletonSettings | None = None, *,
                   torque_channel: str | None = None, timing: str = "auto", allow_incomplete: bool = False,
                   chunk: int | None = None, budget: int | None = None,
                   progress: Progress | None = None) -> SkeletonResult:
    """:func:`analyse` on run files read chunk by chunk (:mod:`~.streaming`): per run, its band from a streamed
    spectrum, then ForceVib on a copy decimated to :data:`~.streaming.OVERSAMPLE` x the band's top frequency.
    ``budget`` (bytes): a one-line AnalysisError, before the samples are read, when a decimated copy would not
    fit. The curves agree with :func:`analyse`'s within the tolerances of docs/long-runs.md."""
    from hilbench.analysis.channel_windows import CHUNK, ChannelReader
    from hilbench.analysis.record import stream_record
    from hilbench.analysis.skeleton.forcevib import forcevib
    from hilbench.analysis.skeleton.streaming import centred_chunks, decimated_copy, decimation_factor

    settings = settings or SkeletonSettings()
    chunk = chunk or CHUNK
    records = [stream_record(p, torque_channel=torque_channel, timing=timing,
                             allow_incomplete=allow_incomplete)[0] for p in paths]
    mass = _check(records, settings)
    total = 2 * sum(r.n_samples for r in records)
    done = 0
    results, reads = [], []
    for path, r in zip(paths, records, strict=True):
        if r.position is not None:  # a host-clocked run, resampled whole by the loader
            results.append(forcevib(r.position, centred_force(r.torque, r.timing), r.sample_rate, mass,
                                    settings.method, spring=settings.spring, **settings.options(),
                                    **({"freq_range": tuple(settings.band)} if settings.band else {})))
            reads.append("whole (a host-clocked run is resampled whole)")
            done += 2 * r.n_samples
            continue
        with ChannelReader(path) as reader:
            band = stream_band(reader, r, settings, chunk)
            done += r.n_samples
            q = decimation_factor(r.sample_rate, band[1])
            need = stream_cost(r.n_samples, q, r.sample_rate, band, settings)
            if budget is not None and need > budget:
                raise AnalysisError(f"{path}: its band reaches {band[1]:.4g} Hz, so it decimates by {q} only and "
                                    f"needs about {need >> 20} MiB, over --memory {budget >> 20} MiB: raise "
                                    "--memory or narrow --band")
            base = done

            def tick(d: int, t: int, base: int = base) -> None:
                if progress is not None:
                    progress(base + d, total)

            pairs = ((c[0], c[1]) for _, c in reader.chunks(["position", r.torque_channel], chunk, progress=tick))
            x, force = decimated_copy(centred_chunks(pairs, r.timing), r.sample_rate, q)
            done += r.n_samples
        options = {**settings.options(), "freq_range": band}
        results.append(forcevib(x, force, r.sample_rate / q, mass, settings.method, spring=settings.spring,
                                **options))
        reads.append("whole" if q == 1 else f"chunk by chunk, decimated by {q} to {r.sample_rate / q:g} Hz")
    return _compose(results, records, [str(p) for p in paths], mass, settings, reads)


def array_cost(samples: int) -> int:
    """Estimated peak bytes of :func:`analyse` on records of ``samples`` in all."""
    return ARRAY_BYTES_FIXED + ARRAY_BYTES_PER_SAMPLE * int(samples)


def stream_cost(samples: int, q: int, fs: float, band: tuple[float, float],
                settings: SkeletonSettings | None = None) -> int:
    """Estimated peak bytes of :func:`analyse_stream` on a run of ``samples`` at ``fs`` decimated by ``q``,
    analysed in ``band`` (Hz)."""
    from hilbench.analysis.skeleton.instantaneous import map_cells
    from hilbench.analysis.skeleton.streaming import SEGMENT

    settings = settings or SkeletonSettings()
    kept = -(-int(samples) // max(1, q))
    cells = map_cells(kept, fs / q, band, settings.fb, settings.fc) if settings.method == "cwt" and band[0] > 0 else 0
    return STREAM_BYTES_FIXED + 16 * SEGMENT + DECIMATED_BYTES_PER_SAMPLE * kept + MAP_BYTES_PER_CELL * cells


def report(result: SkeletonResult, out_dir: str | Path,
           figure: Callable[[SkeletonCurves, list[str], str, str], object] | None = None) -> list[Path]:
    """``skeleton.json`` (:meth:`SkeletonResult.to_dict`) and, given a ``figure`` function (curves, run names,
    position unit, force unit) -> matplotlib Figure, ``skeleton.png`` in ``out_dir`` (created)."""
    from hilbench.analysis.output_files import atomic_path, dumps, save_figure

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "skeleton.json"]
    with atomic_path(paths[0]) as tmp:
        tmp.write_text(dumps(result.to_dict()))
    if figure is not None:
        u = result.units
        fig = figure(result.curves, result.names, u["amplitude"], u["restoring_force"])
        paths.append(save_figure(fig, out / "skeleton.png", dpi=110, bbox_inches="tight"))
    return paths
