"""Import measured data from other benches into run files (schema v1).

Loaders read a source file into an :class:`ImportedRun` (arrays + metadata, nothing written);
:func:`write_run` writes it with :class:`bench.runfile.RunWriter`. Formats:

- ``emps``: EMPS benchmark (Janot, Gautier, Brunot 2019), MAT v5, 1 kHz. A **linear** axis:
  position ``qm`` (m), reference ``qg`` (m), force = ``gtau``·``vir`` (N) in the ``torque`` channel, the raw
  drive input ``vir`` (V) in ``drive_voltage``; the PULSES file adds ``pulses_N`` as ``pulses`` (V).
- ``hsm150``: HSM150 DC-servo identification runs (``data`` 20000 × 7, 1 kHz). **Rotary**: position (rad),
  velocity (rad/s), commanded torque (N*m), measured torque = Cu·current (N*m), current (A), encoder counts
  (position / (2π/10000)).
- ``csv``: a header row naming ``t`` (s), ``position`` (rad, or m with ``linear``), ``torque`` (N*m or N) or
  ``current`` (A, with a torque constant), optional ``velocity``; other columns mapped by name.
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hilbench.bench.errors import BenchError
from hilbench.bench.runfile import CHANNELS, RunWriter

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
        custom_units: units of channels outside :data:`bench.runfile.CHANNELS`.
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


def _loadmat(path: str) -> dict[str, Any]:
    from scipy.io import loadmat

    if not os.path.isfile(path):
        raise ImportDataError(f"{path}: no such file")
    try:
        return loadmat(path)
    except Exception as exc:  # scipy raises ValueError, TypeError, OSError, MatReadError... for bad files
        raise ImportDataError(f"{path}: not a readable MAT v5 file ({' '.join(str(exc).split())})") from None


def _column(mat: Mapping[str, Any], name: str, path: str, n: int | None = None) -> np.ndarray:
    if name not in mat:
        raise ImportDataError(f"{path}: variable {name!r} is missing")
    a = np.asarray(mat[name])
    if a.ndim != 2 or 1 not in a.shape:
        raise ImportDataError(f"{path}: variable {name!r} should be a column vector, has shape {a.shape}")
    a = a.ravel().astype(float)
    if n is not None and a.size != n:
        raise ImportDataError(f"{path}: variable {name!r} has {a.size} samples, expected {n}")
    return a


def _scalar(mat: Mapping[str, Any], name: str, path: str) -> float:
    if name not in mat or np.asarray(mat[name]).size != 1:
        raise ImportDataError(f"{path}: scalar {name!r} is missing")
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
    mat = _loadmat(path)
    t = _column(mat, "t", path)
    n = t.size
    qm, qg, vir = (_column(mat, v, path, n) for v in ("qm", "qg", "vir"))
    gtau, kp, kv = (_scalar(mat, v, path) for v in ("gtau", "kp", "kv"))
    samples = {
        "sample_index": np.arange(n, dtype=np.int64),
        "t": t,
        "position": qm,
        "position_cmd": qg,
        "torque": gtau * vir,
        "drive_voltage": vir,
    }
    custom = {"drive_voltage": "V"}
    variables = {
        "t": "t",
        "position": "qm",
        "position_cmd": "qg",
        "torque": "gtau*vir",
        "drive_voltage": "vir",
    }
    if "pulses_N" in mat:
        samples["pulses"] = _column(mat, "pulses_N", path, n)
        custom["pulses"] = "V"
        variables["pulses"] = "pulses_N"
    _check_finite(samples, path, variables)
    fs = _sample_rate(t, path)
    return ImportedRun(
        axis="linear",
        sample_rate=fs,
        samples=samples,
        custom_units=custom,
        protocol_name="import:emps",
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
    mat = _loadmat(path)
    if "data" not in mat:
        raise ImportDataError(f"{path}: variable 'data' is missing")
    data = np.asarray(mat["data"], dtype=float)
    if data.ndim != 2 or data.shape[1] != 7:
        raise ImportDataError(f"{path}: 'data' should have 7 columns, has shape {data.shape}")
    n = data.shape[0]
    cols = {
        "t": 0,
        "position_cmd": 1,
        "position": 2,
        "velocity": 3,
        "torque_cmd": 4,
        "torque": 5,
        "current": 6,
    }
    samples: dict[str, np.ndarray] = {"sample_index": np.arange(n, dtype=np.int64)}
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
        "J": "kg*m^2",
        "B": "N*m*s/rad",
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


def _sniff_delimiter(header: str) -> str:
    for candidate in (",", ";", "\t"):
        if candidate in header:
            return candidate
    return ","


def load_csv(
    path: str | os.PathLike,
    *,
    torque_constant: float | None = None,
    mapping: Mapping[str, str] | None = None,
    linear: bool = False,
    delimiter: str | None = None,
    record: str = "torque-driven",
) -> ImportedRun:
    """Load a CSV file with a header row.

    Args:
        path: the CSV file.
        torque_constant: N*m/A (N/A when ``linear``); turns a ``current`` column into ``torque`` when the
            file has no torque column.
        mapping: run-file channel -> CSV column name, for columns not already named after a channel.
        linear: the axis is linear: position in m, torque column in N, velocity in m/s.
        delimiter: field separator (default: guessed from the header among ``,``, ``;`` and tab).
        record: ``torque-driven`` (the torque drives the motion) or ``displacement-driven`` (force measured
            against an imposed displacement, e.g. a tribometer), stored as the run file's ``record``.

    Required: ``t`` (s, strictly increasing), ``position`` and ``torque`` (or ``current`` with
    ``torque_constant``). Any other column named after a run-file channel is kept; the rest are ignored and
    listed in ``protocol_params["ignored_columns"]``.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ImportDataError(f"{path}: no such file")
    try:
        with open(path, encoding="utf-8-sig") as fh:
            header = fh.readline()
    except (OSError, UnicodeDecodeError) as exc:
        raise ImportDataError(f"{path}: cannot read ({' '.join(str(exc).split())})") from None
    if not header.strip():
        raise ImportDataError(f"{path}: empty file (a header row is required)")
    sep = delimiter or _sniff_delimiter(header)
    names = [h.strip().strip('"').strip("'") for h in header.rstrip("\r\n").split(sep)]
    if len(set(names)) != len(names):
        raise ImportDataError(f"{path}: duplicate column names in the header: {names}")
    mapping = dict(mapping or {})
    for channel, column in mapping.items():
        if channel not in CHANNELS or channel in ("sample_index",):
            raise ImportDataError(f"--map {channel}={column}: {channel!r} is not a run-file channel")
        if column not in names:
            raise ImportDataError(f"{path}: --map {channel}={column}: no column {column!r} (header: {names})")
    column_of = {name: name for name in names if name in CHANNELS and name != "sample_index"}
    for channel, column in mapping.items():
        column_of = {k: v for k, v in column_of.items() if v != column}
        column_of[channel] = column
    missing = [c for c in ("t", "position") if c not in column_of]
    if "torque" not in column_of and not ("current" in column_of and torque_constant is not None):
        missing.append("torque (or current with --torque-constant)")
    if missing:
        raise ImportDataError(f"{path}: missing column(s): {', '.join(missing)} (header: {', '.join(names)})")
    if torque_constant is not None and not (math.isfinite(torque_constant) and torque_constant != 0):
        raise ImportDataError(f"torque constant must be finite and non-zero, got {torque_constant}")

    used = list(column_of.values())
    try:
        table = np.loadtxt(
            path,
            delimiter=sep,
            skiprows=1,
            usecols=[names.index(c) for c in used],
            ndmin=2,
            encoding="utf-8-sig",
            comments=None,
        )
    except ValueError as exc:
        raise ImportDataError(f"{path}: {' '.join(str(exc).split())}") from None
    samples = {channel: table[:, i].astype(float) for i, channel in enumerate(column_of)}
    _check_finite(samples, path, {ch: col for ch, col in column_of.items()})
    n = samples["t"].size
    fs = _sample_rate(samples["t"], path)
    calibration: dict[str, Any] = {}
    torque_unit = "N" if linear else "N*m"
    if torque_constant is not None:
        calibration = {"torque_constant": torque_constant, "torque_constant_unit": f"{torque_unit}/A"}
        if "torque" not in samples:
            samples["torque"] = torque_constant * samples["current"]
    if "counts" in samples:
        if np.any(samples["counts"] != np.round(samples["counts"])):
            raise ImportDataError(f"{path}: column {column_of['counts']!r} (counts) must hold whole numbers")
        samples["counts"] = samples["counts"].astype(np.int64)
    samples["sample_index"] = np.arange(n, dtype=np.int64)
    ignored = [c for c in names if c not in used]
    return ImportedRun(
        axis="linear" if linear else "rotary",
        sample_rate=fs,
        samples=samples,
        protocol_name="import:csv",
        protocol_params={
            "format": "csv",
            "source_file": os.path.basename(path),
            "source_sha256": _sha256(path),
            "variables": {ch: col for ch, col in column_of.items()}
            | ({"torque": f"{torque_constant}*{column_of['current']}"} if "torque" not in column_of else {}),
            "ignored_columns": ignored,
            "sample_rate_note": "nominal: (n-1)/(t[-1]-t[0])",
        },
        device={"name": os.path.splitext(os.path.basename(path))[0], "source": "csv"},
        calibration=calibration,
        record=record,
    )


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
        raise ImportDataError(f"{out}: file exists (use --force to overwrite)")
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
        record=imported.record,
    ) as writer:
        writer.append(imported.samples)
    return out
