"""The EMPS benchmark's reference model, fitted by IDIM-LS as in its description paper.

Janot, Gautier, Brunot, "Data Set and Reference Models of EMPS", Nonlinear System Identification
Benchmarks workshop, 2019. Data: ``tests/data/emps/`` in the repository (see its README.md).

Model (linear axis, SI units):

    tau = M*q'' + Fv*q' + Fc*sign(q') + offset,      tau = gtau*vir  (N)

IDIM-LS recipe (the paper's Script_IDIM_LS):

1. position q (m) low-passed by a 4th-order Butterworth at 100 Hz, zero phase (filtfilt);
2. q' and q'' by central differences of the filtered position;
3. "parallel decimation" by 10 of the force and of every regressor column with the same
   anti-alias filter (scipy.signal.decimate = MATLAB decimate: Chebyshev I order 8, zero phase);
4. the first and last decimated samples are dropped: their central differences and filter
   stencils straddle the record ends. With this the sample count is 2483, which is what the
   published residual norm and standard deviation imply (108.76 / 2.1843 -> n - 4 = 2479);
5. ordinary least squares; standard errors sigma^2 (W^T W)^-1 with sigma^2 = |r|^2 / (n - p).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hilbench.analysis.errors import AnalysisError
from hilbench.common.metrics import percent, relative_error
from hilbench.common.units import AXIS_UNITS

#: Published IDIM-LS figures of EMPS_Description.pdf (values, standard errors).
PUBLISHED = {
    "mass": (95.1089, 0.1085),  # kg
    "viscous": (203.5034, 1.1460),  # N*s/m
    "coulomb": (20.3935, 0.1012),  # N
    "offset": (-3.1648, 0.0444),  # N
    "relative_error_train": 4.0834,  # %
    "error_norm_train": 108.76,  # N
    "residual_std_train": 2.1843,  # N
    "relative_error_test": 5.9824,  # % (DATA_EMPS_PULSES, same parameters)
    "error_norm_test": 169.49,  # N
    "condition_number": 25.99,
}

PARAMETER_NAMES = ("mass", "viscous", "coulomb", "offset")
PARAMETER_UNITS = tuple(AXIS_UNITS["linear"][q] for q in ("inertia", "viscous", "torque", "torque"))


#: The variables an EMPS file is read for; ``pulses_N`` is in DATA_EMPS_PULSES.mat only.
EMPS_VARIABLES = ("t", "qm", "qg", "vir", "gtau", "kp", "kv", "pulses_N")


@dataclass(frozen=True)
class EmpsRecord:
    """One EMPS .mat file as arrays: t (s), qm and qg (m), vir (V), gtau (N/V), kp (1/s), kv (V/(m/s)),
    pulses (V, the PULSES file only, else None); force = gtau*vir (N)."""

    t: np.ndarray
    qm: np.ndarray
    vir: np.ndarray
    gtau: float
    name: str
    qg: np.ndarray | None = None
    kp: float = float("nan")
    kv: float = float("nan")
    pulses: np.ndarray | None = None

    @property
    def force(self) -> np.ndarray:
        return self.gtau * self.vir


def parse_emps(mat: Mapping[str, Any], source: str) -> EmpsRecord:
    """The one EMPS parser: the variables of an EMPS MAT file (as scipy.io.loadmat returns them) checked and
    converted. Each is a real column vector of one length (scalars for gtau, kp, kv) with finite values; anything
    else raises :class:`AnalysisError` naming ``source`` and the variable. ``bench import emps`` reads the file with
    its size bounds and calls this too, so a run file and this module see the same arrays."""

    def real(name: str) -> np.ndarray:
        a = np.asarray(mat[name])
        if np.iscomplexobj(a) or (a.dtype.names is not None and {"real", "imag"} <= set(a.dtype.names)):
            raise AnalysisError(f"{source}: variable {name!r} is complex; hilbench imports real signals only "
                                "(store its real and imaginary parts as two variables)")
        return a

    def column(name: str, n: int | None = None) -> np.ndarray:
        if name not in mat:
            raise AnalysisError(f"{source}: variable {name!r} is missing")
        a = real(name)
        if a.ndim != 2 or 1 not in a.shape:
            raise AnalysisError(f"{source}: variable {name!r} should be a column vector, has shape {a.shape}")
        a = a.ravel().astype(float)
        if n is not None and a.size != n:
            raise AnalysisError(f"{source}: variable {name!r} has {a.size} samples, expected {n}")
        bad = ~np.isfinite(a)
        if bad.any():
            raise AnalysisError(f"{source}: {name!r} has {int(bad.sum())} non-finite value(s) "
                                f"(first at sample {int(np.argmax(bad))})")
        return a

    def scalar(name: str) -> float:
        if name not in mat or np.asarray(mat[name]).size != 1:
            raise AnalysisError(f"{source}: scalar {name!r} is missing")
        return float(real(name).ravel()[0])

    t = column("t")
    qm, qg, vir = (column(v, t.size) for v in ("qm", "qg", "vir"))
    gtau, kp, kv = (scalar(v) for v in ("gtau", "kp", "kv"))
    if not np.isfinite(gtau):
        raise AnalysisError(f"{source}: 'gtau' is not finite")
    pulses = column("pulses_N", t.size) if "pulses_N" in mat else None
    return EmpsRecord(t=t, qm=qm, vir=vir, gtau=gtau, name=Path(source).stem, qg=qg, kp=kp, kv=kv, pulses=pulses)


def load_emps(path: str | Path) -> EmpsRecord:
    """Read DATA_EMPS.mat or DATA_EMPS_PULSES.mat (MAT v5) with scipy.io.loadmat, then :func:`parse_emps`."""
    from scipy.io import loadmat

    path = Path(path)
    if not path.is_file():
        raise AnalysisError(f"EMPS file not found: {path}")
    try:
        data = loadmat(str(path), variable_names=EMPS_VARIABLES)
    except Exception as exc:  # scipy raises ValueError, TypeError, OSError, MatReadError... for bad files
        raise AnalysisError(f"{path}: not a readable MAT v5 file ({' '.join(str(exc).split())})") from None
    return parse_emps(data, str(path))


def idim_observation(
    t: np.ndarray,
    position: np.ndarray,
    force: np.ndarray,
    *,
    cutoff: float = 100.0,
    order: int = 4,
    decimation: int = 10,
    trim: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """IDIM-LS observation matrix W (n, 4) = [q'', q', sign(q'), 1] and force vector Y (n,).

    Parameters: t (s, uniform), position (m or rad), force (N or N*m), Butterworth ``cutoff`` (Hz)
    and ``order``, ``decimation`` factor, ``trim`` decimated samples dropped at each end.
    """
    from scipy import signal

    t = np.asarray(t, float)
    dt = float(t[1] - t[0])
    sos = signal.butter(order, cutoff, fs=1.0 / dt, output="sos")
    qf = signal.sosfiltfilt(sos, np.asarray(position, float))
    dq = np.gradient(qf, dt)
    ddq = np.gradient(dq, dt)
    w = np.column_stack([ddq, dq, np.sign(dq), np.ones_like(dq)])
    wd = signal.decimate(w, decimation, axis=0, zero_phase=True)
    yd = signal.decimate(np.asarray(force, float), decimation, zero_phase=True)
    sl = slice(trim, len(yd) - trim if trim else None)
    return wd[sl], yd[sl]


@dataclass(frozen=True)
class IdimResult:
    """IDIM-LS estimate: parameters (M kg, Fv N*s/m, Fc N, offset N), standard errors, fit figures."""

    params: np.ndarray
    std_errors: np.ndarray
    relative_error: float  # % = 100*|Y - W p| / |Y|
    error_norm: float  # N
    residual_std: float  # N, sqrt(|r|^2/(n-p))
    condition_number: float
    n_samples: int

    def as_dict(self) -> dict[str, float]:
        return dict(zip(PARAMETER_NAMES, map(float, self.params), strict=True))


def fit_idim(w: np.ndarray, y: np.ndarray) -> IdimResult:
    """Ordinary least squares y ~ w p with the classical covariance sigma^2 (W^T W)^-1."""
    n, p = w.shape
    if n <= p:
        raise AnalysisError(f"IDIM-LS needs more than {p} decimated samples, got {n}")
    params, *_ = np.linalg.lstsq(w, y, rcond=None)
    r = y - w @ params
    s2 = float(r @ r) / (n - p)
    cov = s2 * np.linalg.inv(w.T @ w)
    return IdimResult(
        params=params,
        std_errors=np.sqrt(np.diag(cov)),
        relative_error=percent(relative_error(y, r)),
        error_norm=float(np.linalg.norm(r)),
        residual_std=float(np.sqrt(s2)),
        condition_number=float(np.linalg.cond(w)),
        n_samples=n,
    )


def cross_test(result: IdimResult, w: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Relative error (%) and error norm of fixed parameters on another record's (W, Y)."""
    r = y - w @ result.params
    return 100.0 * float(np.linalg.norm(r) / np.linalg.norm(y)), float(np.linalg.norm(r))
