"""Import measured data from other benches into run files (schema v1).

Loaders read a source file into an :class:`ImportedRun` (arrays + metadata, nothing written);
:func:`write_run` writes it with :class:`hilbench.common.runfile.RunWriter`. Formats:

- ``emps``: EMPS benchmark (Janot, Gautier, Brunot 2019), MAT v5, 1 kHz. A **linear** axis:
  position ``qm`` (m), reference ``qg`` (m), force = ``gtau``·``vir`` (N) in the ``torque`` channel, the raw
  drive input ``vir`` (V) in ``drive_voltage``; the PULSES file adds ``pulses_N`` as ``pulses`` (V).
- ``hsm150``: HSM150 DC-servo identification runs (``data`` 20000 × 7, 1 kHz). **Rotary**: position (rad),
  velocity (rad/s), commanded torque (N*m), measured torque = Cu·current (N*m), current (A), encoder counts
  (position / (2π/10000)).
- ``csv`` and ``mat``: a lab's own table (:func:`load_csv`, :func:`load_mat`, :func:`table_run`): columns found
  by their usual names (``t``, ``time``, ``Time [ms]``, ``theta``, ``torque``...) or mapped, converted to SI from
  stated units (``--unit t=ms``, encoder counts with counts per rev), refused or resampled when the time stamps
  have gaps, with a declared torque timing stored in the run file. docs/data.md is the user's guide.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.analysis.reproductions.emps import EMPS_VARIABLES, parse_emps
from hilbench.bench.errors import BenchError
from hilbench.bench.storage.import_units import COUNTS, factor_to_si
from hilbench.common.runfile import CHANNELS, POSITION_CMD, SAMPLE_INDEX, TORQUE_CMD, TORQUE_TIMINGS, RunWriter
from hilbench.common.units import AXIS_UNITS

EMPS_CITATION = (
    "A. Janot, M. Gautier, M. Brunot, 'Data Set and Reference Models of EMPS', 2019 Workshop on Nonlinear "
    "System Identification Benchmarks, Eindhoven"
)
HSM150_COUNTS_PER_REV = 10_000  # 2500-line encoder, x4 decoding: quantum 2*pi/10000 rad


class ImportDataError(BenchError):
    """A source file cannot be imported (missing, unreadable, wrong variables, non-finite values...)."""


@dataclass
class ImportedRun:
    """Everything an import writes: sample arrays (run-file channel names) and metadata.

    Attributes:
        axis: ``rotary`` or ``linear``.
        sample_rate: Hz.
        samples: channel name -> 1-D array, equal lengths; includes ``sample_index`` and ``t`` (s).
        custom_units: units of channels outside :data:`hilbench.common.runfile.CHANNELS`.
        torque_timing: the declared timing of the torque channel (docs/science.md §6), stored in the run file;
            None when the source does not say.
        device, calibration, protocol_params: JSON-able dicts; protocol_name is ``import:<format>``.
    """

    axis: str
    sample_rate: float
    samples: dict[str, np.ndarray]
    protocol_name: str
    protocol_params: dict[str, Any]
    device: dict[str, Any] = field(default_factory=dict)
    calibration: dict[str, Any] = field(default_factory=dict)
    custom_units: dict[str, str] = field(default_factory=dict)
    torque_timing: str | None = None
    record: str = "torque-driven"  # or "displacement-driven": force measured against an imposed displacement

    @property
    def n_samples(self) -> int:
        return int(self.samples["t"].size)


def _sha256(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _loadmat(path: str, **kwargs: Any) -> dict[str, Any]:
    from scipy.io import loadmat

    from hilbench.bench.storage.mat5_bound import MatBoundError, check_inflation

    if not os.path.isfile(path):
        raise ImportDataError(f"{path}: no such file")
    try:
        check_inflation(path, set(kwargs.get("variable_names") or ()))  # before scipy inflates any of them
    except (OSError, MatBoundError) as exc:
        raise ImportDataError(f"{path}: {' '.join(str(exc).split())}") from None
    try:
        return loadmat(path, **kwargs)
    except Exception as exc:  # scipy raises ValueError, TypeError, OSError, MatReadError... for bad files
        raise ImportDataError(f"{path}: not a readable MAT v5 file ({' '.join(str(exc).split())})") from None


def _load_named(path: str, names: tuple[str, ...]) -> dict[str, Any]:
    """The variables ``names`` of a MAT v5 file that has them, read after their sizes (each and together) were
    checked against the import bound; the file's other variables are never read."""
    v73, listing = _mat_listing(path)
    if v73:
        raise ImportDataError(f"{path}: a MAT v7.3 file; this format's files are MAT v5 (or use `import mat`)")
    present = [n for n in names if n in listing]
    bound = MAX_MAT_ELEMENTS_FACTOR * MAX_IMPORT_SAMPLES
    sizes = {n: math.prod(listing[n][0]) for n in present}
    for name, size in sizes.items():
        if size > bound:
            raise ImportDataError(f"{path}: variable {name!r} has {size} elements, above the import bound of "
                                  f"{bound} ({MAX_MAT_ELEMENTS_FACTOR} x MAX_IMPORT_SAMPLES)")
    if sum(sizes.values()) > bound:
        raise ImportDataError(f"{path}: the variables used hold {sum(sizes.values())} elements together, above the "
                              f"import bound of {bound} ({MAX_MAT_ELEMENTS_FACTOR} x MAX_IMPORT_SAMPLES)")
    return _loadmat(path, variable_names=present) if present else {}


def _column(mat: Mapping[str, Any], name: str, path: str, n: int | None = None) -> np.ndarray:
    if name not in mat:
        raise ImportDataError(f"{path}: variable {name!r} is missing")
    a = np.asarray(mat[name])
    _refuse_complex(a, name, path)
    if a.ndim != 2 or 1 not in a.shape:
        raise ImportDataError(f"{path}: variable {name!r} should be a column vector, has shape {a.shape}")
    a = a.ravel().astype(float)
    if n is not None and a.size != n:
        raise ImportDataError(f"{path}: variable {name!r} has {a.size} samples, expected {n}")
    return a


def _refuse_complex(a: np.ndarray, name: str, path: str) -> None:
    if np.iscomplexobj(a) or (a.dtype.names is not None and {"real", "imag"} <= set(a.dtype.names)):
        raise ImportDataError(f"{path}: variable {name!r} is complex; hilbench imports real signals only "
                              "(store its real and imaginary parts as two variables)")


def _scalar(mat: Mapping[str, Any], name: str, path: str) -> float:
    if name not in mat or np.asarray(mat[name]).size != 1:
        raise ImportDataError(f"{path}: scalar {name!r} is missing")
    _refuse_complex(np.asarray(mat[name]), name, path)
    return float(np.asarray(mat[name]).ravel()[0])


def _check_finite(
    samples: Mapping[str, np.ndarray], path: str, labels: Mapping[str, str] | None = None
) -> None:
    for name, a in samples.items():
        bad = ~np.isfinite(a)
        if bad.any():
            label = (labels or {}).get(name, name)
            first = int(np.argmax(bad))
            raise ImportDataError(
                f"{path}: {label!r} has {int(bad.sum())} non-finite value(s) (first at sample {first})"
            )


def _sample_rate(t: np.ndarray, path: str) -> float:
    """Nominal rate (n-1)/(t[-1]-t[0]) in Hz, 9 significant digits; t must increase strictly."""
    if t.size < 2:
        raise ImportDataError(f"{path}: need at least 2 samples, got {t.size}")
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise ImportDataError(
            f"{path}: time must increase strictly (first problem at sample {int(np.argmax(dt <= 0)) + 1})"
        )
    return float(f"{(t.size - 1) / (t[-1] - t[0]):.9g}")


def load_emps(path: str | os.PathLike) -> ImportedRun:
    """Load ``DATA_EMPS.mat`` or ``DATA_EMPS_PULSES.mat`` (linear axis, m and N). See the module docstring."""
    path = os.fspath(path)
    try:  # the one EMPS parser (analysis.reproductions.emps), on the variables read within the import bounds
        rec = parse_emps(_load_named(path, EMPS_VARIABLES), path)
    except AnalysisError as exc:
        raise ImportDataError(str(exc)) from None
    t, gtau, kp, kv = rec.t, rec.gtau, rec.kp, rec.kv
    samples = {
        SAMPLE_INDEX: np.arange(t.size, dtype=np.int64),
        "t": t,
        "position": rec.qm,
        POSITION_CMD: rec.qg,
        "torque": rec.force,
        "drive_voltage": rec.vir,
    }
    custom = {"drive_voltage": "V"}
    variables = {
        "t": "t",
        "position": "qm",
        POSITION_CMD: "qg",
        "torque": "gtau*vir",
        "drive_voltage": "vir",
    }
    if rec.pulses is not None:
        samples["pulses"] = rec.pulses
        custom["pulses"] = "V"
        variables["pulses"] = "pulses_N"
    fs = _sample_rate(t, path)
    return ImportedRun(
        axis="linear",
        sample_rate=fs,
        samples=samples,
        custom_units=custom,
        protocol_name="import:emps",
        torque_timing="hold_next",  # vir is the controller output, held by the drive over the next period
        protocol_params={
            "format": "emps",
            "source_file": os.path.basename(path),
            "source_sha256": _sha256(path),
            "variables": variables,
            "citation": EMPS_CITATION,
            "notes": (
                "closed-loop data (PD cascade); vir is the controller output in V, force = gtau*vir in N. "
                "pulses_N is stored as 'pulses' in V: treated as volts added to the controller output "
                "(already included in vir), which the bundled README found to reproduce vir."
            ),
        },
        device={
            "name": "EMPS",
            "description": "electro-mechanical positioning system (prismatic joint)",
            "source": "nonlinearbenchmark.org EMPS",
        },
        calibration={
            "gtau": gtau,
            "gtau_unit": "N/V",
            "kp": kp,
            "kp_unit": "1/s",
            "kv": kv,
            "kv_unit": "V/(m/s)",
        },
    )


def load_hsm150(path: str | os.PathLike) -> ImportedRun:
    """Load an HSM150 ``idf_*.mat`` identification run (rotary axis, rad and N*m)."""
    path = os.fspath(path)
    mat = _load_named(path, ("data", "Iz1", "Iz", "Im1", "Im", "J", "B", "Cu", "Mn", "Mmax", "N", "KFI", "Tvz", "Tgm",
                             "Tn", "Tsim"))
    if "data" not in mat:
        raise ImportDataError(f"{path}: variable 'data' is missing")
    _refuse_complex(np.asarray(mat["data"]), "data", path)
    data = np.asarray(mat["data"], dtype=float)
    if data.ndim != 2 or data.shape[1] != 7:
        raise ImportDataError(f"{path}: 'data' should have 7 columns, has shape {data.shape}")
    n = data.shape[0]
    cols = {
        "t": 0,
        POSITION_CMD: 1,
        "position": 2,
        "velocity": 3,
        TORQUE_CMD: 4,
        "torque": 5,
        "current": 6,
    }
    samples: dict[str, np.ndarray] = {SAMPLE_INDEX: np.arange(n, dtype=np.int64)}
    samples.update({name: np.ascontiguousarray(data[:, c]) for name, c in cols.items()})
    _check_finite(samples, path, {k: f"data[:, {c}]" for k, c in cols.items()})
    quantum = 2 * math.pi / HSM150_COUNTS_PER_REV
    counts = np.round(samples["position"] / quantum)
    if np.max(np.abs(samples["position"] - counts * quantum)) < 1e-6 * quantum:
        samples["counts"] = counts.astype(np.int64)  # the position is exactly on the encoder grid
    custom = {}
    for name in ("Iz1", "Iz", "Im1", "Im"):  # undocumented current-like vectors; kept, unit unknown
        if name in mat and np.asarray(mat[name]).size == n:
            samples[name.lower()] = _column(mat, name, path, n)
            custom[name.lower()] = "unknown"
    calibration: dict[str, Any] = {}
    units = {
        "J": AXIS_UNITS["rotary"]["inertia"],
        "B": AXIS_UNITS["rotary"]["viscous"],
        "Cu": "N*m/A",
        "N": "lines/rev",
        "Tvz": "s",
        "Tgm": "s",
        "Tn": "s",
        "Tsim": "s",
    }
    for name in ("J", "B", "Cu", "Mn", "Mmax", "N", "KFI", "Tvz", "Tgm", "Tn", "Tsim"):
        if name in mat and np.asarray(mat[name]).size == 1:
            calibration[name] = _scalar(mat, name, path)
            if name in units:
                calibration[f"{name}_unit"] = units[name]
    calibration["counts_per_rev"] = HSM150_COUNTS_PER_REV
    return ImportedRun(
        axis="rotary",
        sample_rate=_sample_rate(samples["t"], path),
        samples=samples,
        custom_units=custom,
        protocol_name="import:hsm150",
        protocol_params={
            "format": "hsm150",
            "source_file": os.path.basename(path),
            "source_sha256": _sha256(path),
            "variables": {name: f"data[:, {c}]" for name, c in cols.items()},
            "notes": (
                "open-loop torque step at t = 10 s; torque = Cu*current as stored by the authors; counts "
                "derived from position (quantum 2*pi/10000 rad); iz1, iz, im1, im are undocumented."
            ),
        },
        device={
            "name": "HSM150",
            "description": "DC servo with incremental encoder (two-motor HSM150 system)",
            "source": "github.com/malik-robert/HSM150-data",
        },
        calibration=calibration,
    )


#: Largest number of samples an import creates (each channel: 8 bytes a sample, so 400 MB a channel).
MAX_IMPORT_SAMPLES = 50_000_000
#: Highest sample rate an import accepts, Hz: well above any friction bench; a faster "rate" is a time unit
#: mistake (a 1 ns step in a file of seconds), and the run file's chunks scale with it.
MAX_IMPORT_RATE_HZ = 10e6
#: Lowest sample rate accepted when the time column has no stated unit: a slower file is far more often in ms.
MIN_UNSTATED_RATE_HZ = 10.0
#: Time stamps are uniform when every one lies within this fraction of a period of the nominal grid
#: (the criterion hilbench.analysis.identification.identify applies; float32 time stamps pass).
GRID_TOLERANCE = 0.01
RESAMPLE_METHODS = ("linear",)


@dataclass(frozen=True)
class TableOptions:
    """How to read a table of columns (CSV or MAT) into a run.

    Attributes:
        mapping: run-file channel -> column (CSV header or MAT variable, ``VAR(:,k)`` for column k of a matrix),
            for columns whose names are not among the aliases of :mod:`hilbench.bench.storage.import_units`.
        units: channel (or column) -> unit of the source values, e.g. ``{"t": "ms", "position": "deg"}``; a unit in
            the header (``Time [ms]``) counts as stated. Unstated units are taken as the run file's SI unit.
        torque_constant: N*m/A (N/A when linear): makes ``torque`` from ``current`` when there is no torque column.
        counts_per_rev: encoder counts per revolution, for a position given in counts (rotary axis).
        linear: linear axis (m, N, m/s) instead of rotary (rad, N*m, rad/s).
        torque_timing: what torque sample k means (docs/science.md §6): ``hold_next``, ``hold_previous``,
            ``instant``; stored in the run file. None: not declared (analyses then assume ``instant``).
        resample: None refuses non-uniform time stamps (naming the first gap); ``"linear"`` interpolates every
            channel linearly onto the uniform grid of the median step (counts rounded to whole counts).
        sample_rate: Hz, for a file without a time column (t = k/sample_rate).
        record: ``torque-driven`` (the torque drives the motion) or ``displacement-driven`` (force measured
            against an imposed displacement, e.g. a tribometer), stored as the run file's ``record``.
    """

    mapping: Mapping[str, str] = field(default_factory=dict)
    units: Mapping[str, str] = field(default_factory=dict)
    torque_constant: float | None = None
    counts_per_rev: float | None = None
    linear: bool = False
    torque_timing: str | None = None
    resample: str | None = None
    sample_rate: float | None = None
    record: str = "torque-driven"


def _assign_channels(names: list[str], mapping: Mapping[str, str], path: str) -> tuple[dict[str, str], dict]:
    """channel -> column, and column -> unit stated in its header; aliases first, then ``mapping`` overrides."""
    from hilbench.bench.storage.import_units import channel_of

    header_unit: dict[str, str] = {}
    found: dict[str, list[str]] = {}
    for name in names:
        channel, unit = channel_of(name)
        if unit:
            header_unit[name] = unit
        if channel is not None:
            found.setdefault(channel, []).append(name)
    for channel, column in mapping.items():
        if channel not in CHANNELS or channel == SAMPLE_INDEX:
            raise ImportDataError(f"--map {channel}={column}: {channel!r} is not a run-file channel")
        if column not in names:
            raise ImportDataError(f"{path}: --map {channel}={column}: no column {column!r} (has: {', '.join(names)})")
    twice = sorted({c for c in mapping.values() if list(mapping.values()).count(c) > 1})
    if twice:  # --map torque=x --map position=x stored torque == position
        channels = [ch for ch, c in mapping.items() if c == twice[0]]
        raise ImportDataError(f"--map: column {twice[0]!r} is mapped to {' and '.join(channels)}; a column is one "
                              "channel")
    mapped = set(mapping.values())
    column_of: dict[str, str] = {}
    for channel, columns in found.items():
        columns = [c for c in columns if c not in mapped]
        if channel in mapping or not columns:
            continue
        if len(columns) > 1:
            raise ImportDataError(f"{path}: columns {', '.join(map(repr, columns))} all look like {channel}; "
                                  f"choose one with --map {channel}=COLUMN")
        column_of[channel] = columns[0]
    column_of.update(mapping)
    return column_of, header_unit


def _units(column_of: Mapping[str, str], header_unit: Mapping[str, str], given: Mapping[str, str], axis: str,
           path: str) -> dict[str, str]:
    """channel -> unit of the source values, from --unit (by channel or column) or the header; refuses a conflict."""
    by_column = {column: channel for channel, column in column_of.items()}
    stated: dict[str, str] = {}
    for key, unit in given.items():
        channel = key if key in column_of else by_column.get(key)
        if channel is None:
            raise ImportDataError(f"--unit {key}={unit}: no channel or column {key!r} in {path} "
                                  f"(channels: {', '.join(column_of)})")
        if channel in stated:  # --unit x=deg --unit position=rad name one column: the last won, a 57x scale
            raise ImportDataError(f"--unit: two units for channel {channel} (column {column_of[channel]!r}): "
                                  f"{stated[channel]} and {unit}; give one")
        stated[channel] = unit
    for channel, column in column_of.items():
        head = header_unit.get(column)
        if head is None:
            continue
        if channel in stated and _same_unit(stated[channel], head) is False:
            raise ImportDataError(f"{path}: column {column!r} says {head}, --unit {channel}={stated[channel]}; "
                                  "drop one")
        stated.setdefault(channel, head)
    for channel, unit in stated.items():
        factor_to_si(channel, unit, axis)  # refuses a unit of the wrong quantity, listing the accepted ones
    return stated


def _same_unit(a: str, b: str) -> bool:
    from hilbench.bench.storage.import_units import normalise_unit

    return normalise_unit(a) == normalise_unit(b)


def _first_gap(t: np.ndarray) -> tuple[int, float, float] | None:
    """None when every time stamp lies within GRID_TOLERANCE of a period of the nominal uniform grid; else
    (k, dt[k], typical step): the sample after which the step differs most from the median step."""
    period = (t[-1] - t[0]) / (t.size - 1)
    off_grid = np.abs(t - (t[0] + period * np.arange(t.size)))
    if off_grid.max() <= GRID_TOLERANCE * period:
        return None
    dt = np.diff(t)
    step = float(np.median(dt))
    k = int(np.argmax(np.abs(dt - step)))
    return k, float(dt[k]), step


def _resample_linear(samples: dict[str, np.ndarray], step: float, path: str) -> dict[str, np.ndarray]:
    t = samples["t"]
    n = int(math.floor((t[-1] - t[0]) / step * (1 + 1e-12))) + 1
    if n > MAX_IMPORT_SAMPLES:
        raise ImportDataError(f"{path}: resampling onto a {step:.6g} s grid would make {n} samples, above the "
                              f"import bound of {MAX_IMPORT_SAMPLES} samples (MAX_IMPORT_SAMPLES)")
    grid = t[0] + step * np.arange(n)
    out = {"t": grid}
    for name, values in samples.items():
        if name != "t":
            out[name] = np.interp(grid, t, values)
    if "counts" in out:
        out["counts"] = np.round(out["counts"])
    return out


def _check_rate(t: np.ndarray, time_stated: bool, path: str) -> float:
    fs = _sample_rate(t, path)
    if fs > MAX_IMPORT_RATE_HZ:
        raise ImportDataError(f"{path}: sample rate {fs:.6g} Hz (step {1 / fs:.3g} s) is above the import bound of "
                              f"{MAX_IMPORT_RATE_HZ:.6g} Hz (MAX_IMPORT_RATE_HZ); is t in another unit? (--unit t=ms)")
    if not time_stated and fs < MIN_UNSTATED_RATE_HZ:
        raise ImportDataError(f"{path}: t has no unit and read as seconds gives {fs:.6g} Hz; state it: "
                              "--unit t=s, or --unit t=ms if the column is in milliseconds")
    return fs


def _require(column_of: Mapping[str, str], o: TableOptions, names: list[str], path: str) -> None:
    if "t" in column_of and o.sample_rate is not None:
        raise ImportDataError(f"{path}: column {column_of['t']!r} is the time already; --sample-rate is for a "
                              "file without one")
    from_counts = "counts" in column_of and o.counts_per_rev is not None and not o.linear
    missing = [c for c in ("t", "position") if c not in column_of and not (c == "t" and o.sample_rate is not None)
               and not (c == "position" and from_counts)]
    if "torque" not in column_of and not ("current" in column_of and o.torque_constant is not None):
        missing.append("torque (or current with --torque-constant)")
    if missing:
        raise ImportDataError(f"{path}: missing column(s): {', '.join(missing)} (columns: {', '.join(names)}); "
                              "map them with --map CHANNEL=COLUMN")


def _convert_to_si(samples: dict[str, np.ndarray], units: dict[str, str], labels: Mapping[str, str], axis: str,
                   counts_per_rev: float | None, path: str) -> dict[str, str]:
    """Scale every channel in place to its run-file SI unit; a position in counts also fills ``counts``.
    Returns channel -> the unit the source used."""
    if "counts" in samples:
        units.setdefault("counts", COUNTS)
    source_units = {}
    for channel in list(samples):
        factor = factor_to_si(channel, units[channel], axis) if channel in units else 1.0
        source_units[channel] = units.get(channel, CHANNELS[channel].unit(axis))
        if factor == COUNTS:
            if np.any(samples[channel] != np.round(samples[channel])):
                raise ImportDataError(f"{path}: column {labels.get(channel, channel)!r} (counts) must hold whole "
                                      "numbers")
            if channel != "counts":
                samples.setdefault("counts", samples[channel].copy())
                samples[channel] = samples[channel] * (2 * math.pi / float(counts_per_rev))
        elif factor != 1.0:
            samples[channel] = samples[channel] * factor
    return source_units


def _make_uniform(samples: dict[str, np.ndarray], resample: str | None, row: Any,
                  path: str) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """(samples, {}) when the time stamps are uniform; refuses a gap naming its place, or resamples it when
    ``resample`` says how (then returns what was done, for ``protocol_params["resampled"]``)."""
    gap = _first_gap(samples["t"])
    if gap is None:
        return samples, {}
    k, dt_k, step = gap
    where = f"sample {k} ({row(k) + ', ' if row else ''}t = {samples['t'][k]:.9g} s)"
    if resample is None:
        raise ImportDataError(f"{path}: time stamps are not uniform: a step of {dt_k:.6g} s after {where}, against a "
                              f"typical {step:.6g} s; fix the file or give --resample linear")
    t_source = samples["t"]
    out = _resample_linear(samples, step, path)
    return out, {"method": "linear interpolation of every channel onto t0 + k*step (counts rounded)",
                 "step_s": step, "samples_before": int(t_source.size), "samples_after": int(out["t"].size),
                 "largest_step_s": float(np.max(np.diff(t_source))), "first_gap_after": where}


def table_run(columns: Mapping[str, np.ndarray], path: str, fmt: str, options: TableOptions,
              row: Any = None) -> ImportedRun:
    """Turn named 1-D columns (a CSV's or a MAT file's) into an :class:`ImportedRun` in SI units.

    Channels come from the column names (aliases, see :mod:`hilbench.bench.storage.import_units`) and
    ``options.mapping``; units from ``options.units`` and the header; every size is checked against
    :data:`MAX_IMPORT_SAMPLES` and the rate against :data:`MAX_IMPORT_RATE_HZ` before anything is allocated
    from it. ``row(k)`` names where sample k is in the source, for error messages (e.g. ``line 12``).
    """
    o = options
    axis = "linear" if o.linear else "rotary"
    names = list(columns)
    column_of, header_unit = _assign_channels(names, o.mapping, path)
    units = _units(column_of, header_unit, o.units, axis, path)
    if o.torque_timing is not None and o.torque_timing not in TORQUE_TIMINGS:
        raise ImportDataError(f"torque timing must be one of {', '.join(TORQUE_TIMINGS)}, got {o.torque_timing!r}")
    if o.resample is not None and o.resample not in RESAMPLE_METHODS:
        raise ImportDataError(f"--resample must be one of {', '.join(RESAMPLE_METHODS)}, got {o.resample!r}")
    if o.torque_constant is not None and not (math.isfinite(o.torque_constant) and o.torque_constant != 0):
        raise ImportDataError(f"torque constant must be finite and non-zero, got {o.torque_constant}")
    if o.counts_per_rev is not None and not (math.isfinite(o.counts_per_rev) and o.counts_per_rev > 0):
        raise ImportDataError(f"counts per rev must be finite and > 0, got {o.counts_per_rev}")
    counts_unit = [ch for ch, u in units.items() if factor_to_si(ch, u, axis) == COUNTS and ch != "counts"]
    if counts_unit and o.counts_per_rev is None:
        raise ImportDataError(f"{', '.join(counts_unit)} in counts: give --counts-per-rev N")
    _require(column_of, o, names, path)

    samples = {ch: np.asarray(columns[col], dtype=float) for ch, col in column_of.items()}
    if "position" not in samples:  # from the encoder counts (_require checked counts_per_rev)
        samples["position"] = samples["counts"].copy()
        units["position"] = COUNTS
    n = next(iter(samples.values())).size
    if n > MAX_IMPORT_SAMPLES:
        raise ImportDataError(f"{path}: {n} samples, above the import bound of {MAX_IMPORT_SAMPLES} samples "
                              "(MAX_IMPORT_SAMPLES)")
    labels = dict(column_of)
    if "t" not in samples:
        if not (o.sample_rate is not None and math.isfinite(o.sample_rate) and 0 < o.sample_rate):
            raise ImportDataError(f"--sample-rate must be finite and > 0 Hz, got {o.sample_rate}")
        samples["t"] = np.arange(n) / float(o.sample_rate)
        labels["t"] = f"k/{o.sample_rate:g} Hz"
        units["t"] = "s"
    _check_finite(samples, path, labels)
    source_units = _convert_to_si(samples, units, labels, axis, o.counts_per_rev, path)
    fs = _check_rate(samples["t"], "t" in units, path)
    samples, resampled = _make_uniform(samples, o.resample, row, path)
    if resampled:
        fs = _check_rate(samples["t"], True, path)
    calibration: dict[str, Any] = {}
    torque_unit = "N" if o.linear else "N*m"
    if o.torque_constant is not None:
        calibration = {"torque_constant": o.torque_constant, "torque_constant_unit": f"{torque_unit}/A"}
        if "torque" not in samples:
            samples["torque"] = o.torque_constant * samples["current"]
    if o.counts_per_rev is not None:
        calibration["counts_per_rev"] = o.counts_per_rev
    if "counts" in samples:
        samples["counts"] = samples["counts"].astype(np.int64)
    samples[SAMPLE_INDEX] = np.arange(samples["t"].size, dtype=np.int64)
    variables = dict(labels)
    if "torque" not in column_of:
        variables["torque"] = f"{o.torque_constant}*{column_of['current']}"
    used = set(column_of.values())
    params: dict[str, Any] = {
        "format": fmt,
        "source_file": os.path.basename(path),
        "source_sha256": _sha256(path),
        "variables": variables,
        "source_units": source_units,
        "units_assumed": sorted(ch for ch in source_units if ch not in units and ch in column_of and ch != "counts"),
        "ignored_columns": [c for c in names if c not in used],
        "sample_rate_note": "nominal: (n-1)/(t[-1]-t[0])",
    }
    if resampled:
        params["resampled"] = resampled
    return ImportedRun(
        axis=axis,
        sample_rate=fs,
        samples=samples,
        protocol_name=f"import:{fmt}",
        protocol_params=params,
        device={"name": os.path.splitext(os.path.basename(path))[0], "source": fmt},
        calibration=calibration,
        torque_timing=o.torque_timing,
        record=o.record,
    )


def _sniff_delimiter(header: str) -> str:
    for candidate in (",", ";", "\t"):
        if candidate in header:
            return candidate
    return ","


#: Longest line a CSV import reads, bytes: a lab's row of 200 columns is a few KB; a longer line (a file with no
#: line breaks) would be read into memory whole by the header or row parser.
MAX_LINE_BYTES = 1 << 20


def _count_lines(path: str) -> int:
    """Lines in a text file, counted in 1 MiB blocks (nothing the size of the file is allocated); refuses a
    line longer than :data:`MAX_LINE_BYTES` before any row is parsed."""
    lines, last, run = 0, b"\n", 0  # run: bytes of the current line so far
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            ends = np.flatnonzero(np.frombuffer(block, np.uint8) == 10)
            first = run + (int(ends[0]) + 1 if ends.size else len(block))  # the line begun in an earlier block
            lengths = np.diff(ends) if ends.size > 1 else np.zeros(1, np.int64)
            if max(first, int(np.max(lengths))) > MAX_LINE_BYTES + 1:  # (+1: its line break)
                line = lines + 1 if first > MAX_LINE_BYTES + 1 else lines + 2 + int(np.argmax(lengths))
                raise ImportDataError(f"{path}: line {line} is longer than {MAX_LINE_BYTES} bytes (MAX_LINE_BYTES); "
                                      "is this a CSV file?")
            run = len(block) - 1 - ends[-1] if ends.size else run + len(block)
            lines += ends.size
            last = block[-1:]
    return lines + (last != b"\n")


def load_csv(path: str | os.PathLike, options: TableOptions | None = None, *, delimiter: str | None = None,
             **kwargs: Any) -> ImportedRun:
    """Load a CSV file with a header row (see :class:`TableOptions`; keyword arguments are its fields).

    Required: time (``t``, ``time``, ``Time [ms]``...; or ``sample_rate``), position (or counts with
    ``counts_per_rev``) and torque (or current with ``torque_constant``). Columns named after no channel are
    kept out and listed in ``protocol_params["ignored_columns"]``. ``delimiter``: default guessed from the
    header among ``,``, ``;`` and tab.
    """
    options = options or TableOptions(**kwargs)
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ImportDataError(f"{path}: no such file")
    try:
        with open(path, encoding="utf-8-sig") as fh:
            header = fh.readline(MAX_LINE_BYTES + 1)  # a file without line breaks is not read whole
    except (OSError, UnicodeDecodeError) as exc:
        raise ImportDataError(f"{path}: cannot read ({' '.join(str(exc).split())})") from None
    if not header.strip():
        raise ImportDataError(f"{path}: empty file (a header row is required)")
    if len(header) > MAX_LINE_BYTES:
        raise ImportDataError(f"{path}: the header is longer than {MAX_LINE_BYTES} characters (MAX_LINE_BYTES); "
                              "is this a CSV file?")
    sep = delimiter or _sniff_delimiter(header)
    names = [h.strip().strip('"').strip("'") for h in header.rstrip("\r\n").split(sep)]
    if len(set(names)) != len(names):
        raise ImportDataError(f"{path}: duplicate column names in the header: {names}")
    column_of, _ = _assign_channels(names, options.mapping, path)
    _require(column_of, options, names, path)
    rows = _count_lines(path) - 1
    if rows > MAX_IMPORT_SAMPLES:
        raise ImportDataError(f"{path}: {rows} rows, above the import bound of {MAX_IMPORT_SAMPLES} samples "
                              "(MAX_IMPORT_SAMPLES)")
    used = list(dict.fromkeys(column_of.values()))
    try:
        table = np.loadtxt(path, delimiter=sep, skiprows=1, usecols=[names.index(c) for c in used], ndmin=2,
                           encoding="utf-8-sig", comments=None)
    except ValueError as exc:
        raise ImportDataError(f"{path}: {' '.join(str(exc).split())}") from None
    columns = {name: table[:, used.index(name)] if name in used else np.empty(0) for name in names}
    return table_run(columns, path, "csv", options, row=lambda k: f"line {k + 2}")


_MATRIX_COLUMN = re.compile(r"^(?P<var>[A-Za-z]\w*)\(\s*:\s*,\s*(?P<col>\d+)\s*\)$")


#: Most elements an import reads from a MAT file, over all the variables it uses together (a matrix counts
#: whole in a v5 file, where scipy reads a variable at once; one column in a v7.3 file, read alone).
MAX_MAT_ELEMENTS_FACTOR = 16
_SKIPPED_CLASSES = ("struct", "cell", "char", "object", "function_handle", "opaque")
#: Most variables a MAT file's listing may have (a lab file has tens): the listing itself is bounded too.
MAX_MAT_VARIABLES = 10_000


def _mat_listing(path: str) -> tuple[bool, dict[str, tuple[tuple[int, ...], str]]]:
    """(is v7.3, name -> (shape as MATLAB shows it, class)) of a MAT file's numeric variables, from its headers
    only: no variable's data is read here."""
    from scipy.io import matlab

    if not os.path.isfile(path):
        raise ImportDataError(f"{path}: no such file")
    try:
        with open(path, "rb") as fh:
            major, _ = matlab.matfile_version(fh)
    except Exception as exc:  # scipy raises ValueError / MatReadError for what is not a MAT file
        raise ImportDataError(f"{path}: not a MAT file ({' '.join(str(exc).split())})") from None
    if major == 2:
        return True, _mat73_listing(path)
    from hilbench.bench.storage.mat5_bound import MatBoundError, list_variables

    try:
        listing = list_variables(path)  # headers only: whosmat inflated every compressed variable whole
    except MatBoundError as exc:
        raise ImportDataError(f"{path}: not a readable MAT file ({' '.join(str(exc).split())})") from None
    except Exception as exc:
        raise ImportDataError(f"{path}: not a readable MAT file ({' '.join(str(exc).split())})") from None
    if len(listing) > MAX_MAT_VARIABLES:
        raise ImportDataError(f"{path}: {len(listing)} variables, above the {MAX_MAT_VARIABLES} an import lists "
                              "(MAX_MAT_VARIABLES)")
    return False, {name: (tuple(shape), cls) for name, shape, cls in listing if cls not in _SKIPPED_CLASSES}


def _mat73_listing(path: str) -> dict[str, tuple[tuple[int, ...], str]]:
    import h5py

    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise ImportDataError(f"{path}: not a readable MAT v7.3 (HDF5) file ({' '.join(str(exc).split())})") from None
    out = {}
    with f:
        if len(f) > MAX_MAT_VARIABLES:
            raise ImportDataError(f"{path}: {len(f)} variables, above the {MAX_MAT_VARIABLES} an import lists "
                                  "(MAX_MAT_VARIABLES)")
        for name, obj in f.items():
            if not isinstance(obj, h5py.Dataset) or name.startswith("#"):
                continue
            cls = obj.attrs.get("MATLAB_class", b"")
            cls = cls.decode() if isinstance(cls, bytes) else str(cls)
            if cls in _SKIPPED_CLASSES or obj.attrs.get("MATLAB_empty", 0):
                continue
            complex_ = obj.dtype.names is not None and {"real", "imag"} <= set(obj.dtype.names)
            if obj.dtype.kind not in "biuf" and not complex_:
                continue
            out[name] = (tuple(reversed(obj.shape)), "complex" if complex_ else cls)  # HDF5 holds MATLAB's transpose
    return out


def _read_mat(path: str, v73: bool, wanted: set[tuple[str, int | None]]) -> dict[tuple[str, int | None], np.ndarray]:
    """Read only ``wanted``: (variable, None) a whole variable, (variable, k) its 0-based column k, as MATLAB shows
    them. scipy reads a v5 variable whole (the column is cut after); a v7.3 column is read alone. Complex
    variables are refused."""
    out = {}
    if not v73:
        mat = _loadmat(path, variable_names=sorted({var for var, _ in wanted}))
        for var, col in wanted:
            a = np.asarray(mat[var])
            _refuse_complex(a, var, path)
            out[var, col] = a if col is None else np.ascontiguousarray(a[:, col])
        return out
    import h5py

    with h5py.File(path, "r") as f:
        for var, col in wanted:
            obj = f[var]
            _refuse_complex(np.empty(0, obj.dtype), var, path)
            out[var, col] = np.asarray(obj[()]).T if col is None else np.asarray(obj[col, :])
    return out


def load_mat(path: str | os.PathLike, options: TableOptions | None = None, **kwargs: Any) -> ImportedRun:
    """Load a MAT file (v5/v7 or v7.3) of vectors into a run (see :class:`TableOptions`; keyword arguments are
    its fields).

    Every numeric vector whose name is a channel alias (``t``, ``time``, ``position``, ``theta``, ``torque``...)
    becomes that channel; ``options.mapping`` names other variables, and ``VAR(:,k)`` column k (1-based, as in
    MATLAB) of a matrix. All vectors used must have the same length. MAT files carry no units: give them with
    ``options.units``; unstated ones are taken as SI.

    The channels are chosen from the file's headers; only the variables they use are read, after their sizes,
    each and together, were checked against ``MAX_MAT_ELEMENTS_FACTOR * MAX_IMPORT_SAMPLES`` elements.
    """
    options = options or TableOptions(**kwargs)
    path = os.fspath(path)
    v73, listing = _mat_listing(path)
    # column name -> (variable, 0-based column or None for a vector, samples)
    columns: dict[str, tuple[str, int | None, int]] = {}
    for name, (shape, _) in listing.items():
        if len(shape) == 2 and 1 in shape and math.prod(shape) > 1:
            columns[name] = (name, None, math.prod(shape))
    for channel, ref in options.mapping.items():
        m = _MATRIX_COLUMN.match(ref)
        if ref in columns or not m:
            continue
        var, col = m.group("var"), int(m.group("col"))
        if var not in listing:
            raise ImportDataError(f"{path}: --map {channel}={ref}: no variable {var!r} (has: {', '.join(listing)})")
        shape = listing[var][0]
        if len(shape) != 2 or not 1 <= col <= shape[1]:
            raise ImportDataError(f"{path}: --map {channel}={ref}: {var!r} has shape {shape}, no column {col}")
        columns[ref] = (var, col - 1, shape[0])
    column_of, _ = _assign_channels(list(columns), options.mapping, path)
    used = set(column_of.values())
    lengths: dict[int, list[str]] = {}
    for name in column_of.values():
        lengths.setdefault(columns[name][2], []).append(name)
    if len(lengths) > 1:
        detail = "; ".join(f"{', '.join(names)}: {n}" for n, names in sorted(lengths.items()))
        raise ImportDataError(f"{path}: the variables used have different lengths ({detail})")
    bound = MAX_MAT_ELEMENTS_FACTOR * MAX_IMPORT_SAMPLES
    wanted = {columns[name][:2] for name in used}
    # what is read: a v5 variable whole, once; a v7.3 vector whole or a matrix column alone
    sizes = ({var: math.prod(listing[var][0]) for var, _ in wanted} if not v73 else
             {f"{var}(:,{col + 1})" if col is not None else var:
              listing[var][0][0] if col is not None else math.prod(listing[var][0]) for var, col in wanted})
    for var, size in sizes.items():
        if size > bound:
            raise ImportDataError(f"{path}: variable {var!r} has {size} elements, above the import bound of "
                                  f"{bound} ({MAX_MAT_ELEMENTS_FACTOR} x MAX_IMPORT_SAMPLES)")
    if sum(sizes.values()) > bound:
        raise ImportDataError(f"{path}: the variables used hold {sum(sizes.values())} elements together, above the "
                              f"import bound of {bound} ({MAX_MAT_ELEMENTS_FACTOR} x MAX_IMPORT_SAMPLES)")
    read = _read_mat(path, v73, wanted)
    arrays = {name: read[columns[name][:2]].ravel() if name in used else np.empty(0)  # unused: never read
              for name in columns}
    return table_run(arrays, path, "mat", options)


LOADERS = {"emps": load_emps, "hsm150": load_hsm150}


def write_run(
    imported: ImportedRun,
    out: str | os.PathLike,
    *,
    overwrite: bool = False,
    operator: str = "",
    notes: str = "",
) -> str:
    """Write an :class:`ImportedRun` as a completed run file; returns the path written."""
    out = os.fspath(out)
    if os.path.exists(out) and not overwrite:
        raise ImportDataError(f"{out}: file exists (use --overwrite to replace it)")
    n = imported.n_samples
    if n > MAX_IMPORT_SAMPLES:
        raise ImportDataError(f"{out}: {n} samples, above the import bound of {MAX_IMPORT_SAMPLES} samples "
                              "(MAX_IMPORT_SAMPLES)")
    custom = dict(imported.custom_units)
    channels = [name for name in imported.samples if name not in custom]
    with RunWriter(
        out,
        sample_rate=imported.sample_rate,
        axis=imported.axis,
        channels=channels,
        custom_channels=custom,
        device=imported.device,
        calibration=imported.calibration,
        protocol_name=imported.protocol_name,
        protocol_params=imported.protocol_params,
        operator=operator,
        notes=notes,
        source=imported.protocol_name,
        overwrite=overwrite,
        # chunks hold flush_interval*sample_rate samples: never more than the file has (a 1 MHz file of four
        # samples would otherwise allocate half a million per channel)
        flush_interval=min(0.5, max(n, 1) / imported.sample_rate),
        torque_timing=imported.torque_timing,
        record=imported.record,
    ) as writer:
        writer.append(imported.samples)
    return out
