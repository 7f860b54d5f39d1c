"""The AFRF of a measured stepped-sine record, step by step (docs/long-runs.md, "afrf").

Each step's harmonics are those of its measure window alone (:func:`hilbench.analysis.afrf.frf.harmonic_phasors`),
so the analysis needs one window of the record at a time: read whole or window by window from the file, the
computation and the result are the same, bit for bit. The grid is the run's amplitudes x requested frequencies;
the reported frequency is the played one (snapped to whole periods by the bench). Steps the file does not hold
completely (an aborted or crashed run) are NaN. Amplitudes are the setpoint's (A in current mode, rad/s in velocity
mode); the torque channel's first harmonic is in ``drive`` (N*m).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from hilbench.analysis.afrf.frf import AfrfResult, harmonic_phasors, period_convergence
from hilbench.analysis.errors import AnalysisError

#: windows table columns an AFRF needs
WINDOW_COLUMNS = ("frequency", "amplitude", "measure_start", "measure_stop")
#: log-log slope of |X(f)| between the two lowest frequencies above which a step is rate-independent: presliding
#: (Maxwell-slip hysteresis does not depend on the rate, and the inertia is negligible far below the presliding
#: resonance) gives ~0; sliding makes the inertia or the viscous term carry the drive: -2 or -1
SLIDING_SLOPE = -0.5

#: reads samples [start, stop) of a step: (position, torque or None)
WindowReader = Callable[[int, int], tuple[np.ndarray | None, np.ndarray | None]]


def checked_windows(windows: np.ndarray | None, where: str, protocol: str) -> np.ndarray:
    """The ``step_windows`` table, or a one-line AnalysisError saying the record is no stepped-sine run."""
    if windows is None or windows.dtype.names is None or not all(n in windows.dtype.names for n in WINDOW_COLUMNS):
        raise AnalysisError(f"{where}: no step windows (/protocol/step_windows); an AFRF needs a stepped-sine "
                            f"run (protocol {protocol or 'unknown'!r})")
    if windows.size == 0:
        raise AnalysisError(f"{where}: the step_windows table is empty")
    return windows


def largest_window(windows: np.ndarray) -> int:
    """Samples of the longest measure window (what a window-by-window analysis holds at once)."""
    return int(np.max(windows["measure_stop"] - windows["measure_start"]))


def afrf_of_steps(where: str, fs: float, windows: np.ndarray, n_samples: int, read: WindowReader, *, mode: str,
                  axis: str, n_harmonics: int = 3, progress: Callable[[int, int], None] | None = None
                  ) -> AfrfResult:
    """AFRF from each step's measure window, read by ``read(start, stop)`` (module docstring).

    Raises:
        AnalysisError: no complete step, an empty window, a window with fewer than one whole period or not whole
            periods.
    """
    w = windows
    amps = np.unique(w["amplitude"])
    req = w["frequency_requested"] if "frequency_requested" in w.dtype.names else w["frequency"]
    freqs_req = np.unique(req)
    shape = (amps.size, freqs_req.size)
    response = np.full(shape + (n_harmonics,), np.nan + 0j)
    drive = np.full(shape, np.nan + 0j)
    conv = np.full(shape, np.nan)
    played = np.full(shape, np.nan)
    complete = 0
    total = int(np.sum(np.clip(w["measure_stop"], None, n_samples) - w["measure_start"]).clip(0))
    done = 0
    for row, f_req in zip(w, req, strict=True):
        i = int(np.searchsorted(amps, row["amplitude"]))
        j = int(np.searchsorted(freqs_req, f_req))
        a, b, f = int(row["measure_start"]), int(row["measure_stop"]), float(row["frequency"])
        played[i, j] = f
        if b <= a:
            raise AnalysisError(f"{where}: step at {f:g} Hz, amplitude {row['amplitude']:g} has an empty "
                                "measure window")
        if b > n_samples:
            continue
        x, torque = read(a, b)
        try:
            response[i, j] = harmonic_phasors(x, fs, f, n_harmonics)
            conv[i, j] = period_convergence(x, fs, f, n_harmonics)
        except AnalysisError as exc:
            raise AnalysisError(f"{where}: step at {f:g} Hz, amplitude {row['amplitude']:g}: {exc}") from None
        if torque is not None:
            drive[i, j] = harmonic_phasors(torque, fs, f, 1, detrend=False)[0]
        complete += 1
        done += b - a
        if progress is not None:
            progress(done, total)
    if complete == 0:
        raise AnalysisError(f"{where}: no step's measure window is complete in the file ({n_samples} samples)")
    linear = axis == "linear"
    return AfrfResult(
        amplitudes=amps, frequencies=np.nanmean(played, axis=0), response=response, drive=drive,
        convergence=conv, amplitude_unit="A" if mode == "current" else ("m/s" if linear else "rad/s"),
        displacement_unit="m" if linear else "rad", drive_unit="N" if linear else "N*m",
    )


def sliding_slopes(result: AfrfResult) -> np.ndarray:
    """Per amplitude, the log-log slope of |X(f)| between the two lowest frequencies with a complete step
    (NaN where fewer than two)."""
    out = np.full(result.amplitudes.size, np.nan)
    f = np.asarray(result.frequencies, float)
    for i in range(result.amplitudes.size):
        h = result.magnitudes[i, :, 0]
        ok = np.flatnonzero(np.isfinite(h) & (h > 0) & np.isfinite(f))
        if ok.size < 2:
            continue
        j0, j1 = ok[np.argsort(f[ok])[:2]]
        if f[j1] > f[j0]:
            out[i] = math.log(h[j1] / h[j0]) / math.log(f[j1] / f[j0])
    return out


def breakaway_warning(result: AfrfResult) -> str | None:
    """One line when no amplitude of the run reaches break-away, judged from the data (:data:`SLIDING_SLOPE`):
    every amplitude's response is rate-independent, i.e. presliding only. None when one slides, or when no
    amplitude has two frequencies to judge by."""
    slopes = sliding_slopes(result)
    ok = np.isfinite(slopes)
    if not ok.any() or np.any(slopes[ok] < SLIDING_SLOPE):
        return None
    top = float(np.max(result.amplitudes[ok]))
    return (f"no drive amplitude reaches break-away: |X(f)| is rate-independent at every amplitude (log-log slope "
            f"{np.min(slopes[ok]):.2f} to {np.max(slopes[ok]):.2f} over the two lowest frequencies, where sliding "
            f"gives -1 to -2), so the AFRF shows presliding only; add amplitudes above {top:g} "
            f"{result.amplitude_unit} (hilbench run stepped_sine --amplitudes ...)")
