"""Drift of identified parameters over a campaign's runs: covariates first, then charts on calibrated scores.

The runs are first grouped into **series** by protocol and analysis settings (an identification run and a chirp
run estimate the viscous term differently; mixing them raises alarms on a motor that did not change). For each
series and each monitored parameter y (one value per run, in start-time order):

1. **Baseline.** The first N runs (default :func:`default_baseline`: half the runs, at most 50, and at least two
   more than the coefficients fitted), or the runs named.
2. **Covariates.** The dependence on the covariates (winding temperature, load) is fitted on the baseline runs by
   ordinary least squares, y = c0 + sum_j c_j*(x_j - mean_b(x_j)), over every covariate recorded for all runs that
   varies over the baseline. A dependence is "found" when |c_j| >= ``significance`` standard errors; a weaker one
   stays in the fit.
3. **Scores** (analysis.drift.calibration.standardise): a baseline run's studentised residual, a later run's
   residual over its prediction standard error. The uncertainty of the baseline mean and of the covariate slope
   enters every later score, so a slope fitted over 0.9 K does not extrapolate into alarms at 5 K.
4. **Charts** on the scores clipped to +-``clip`` (3: the estimates of short runs have heavy tails, one wild run
   must not read as a drift): EWMA and CUSUM over the runs after the baseline, change points (binary segmentation)
   over all runs, on the same clipped scores. Their limits are calibrated on simulated stationary campaigns of the
   same design (analysis.drift.calibration) so that a stationary campaign raises any alarm, over all its series and
   charts, with probability at most ``false_alarm``. A run whose unclipped score exceeds the outlier threshold is
   reported as an outlier, not as a drift.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from datetime import datetime
from typing import Any

import numpy as np

from hilbench.analysis.drift.calibration import Limits, calibrate, clipped, cusum_paths, ewma_paths, standardise
from hilbench.analysis.drift.charts import change_points, signals
from hilbench.analysis.errors import AnalysisError
from hilbench.common.units import rows_axis

#: the longest default baseline, runs
MAX_BASELINE = 50
#: charts per series that share the false-alarm budget (EWMA, CUSUM, change points)
CHARTS = 3


def default_baseline(runs: int, coefficients: int = 1) -> int:
    """The default baseline: the first half of the runs, at most :data:`MAX_BASELINE`, at least ``coefficients``
    + 2 runs (a fit and a spread), never more than ``runs``. The CLI and the GUI both use this rule."""
    return min(runs, max(coefficients + 2, min(MAX_BASELINE, runs // 2)))


def baseline_rule(runs: int, chosen: int, coefficients: int) -> str:
    """One line that says which baseline was used and why."""
    return (f"baseline: the first {chosen} of {runs} runs (default: half the runs, at most {MAX_BASELINE}, at least "
            f"{coefficients + 2} for {coefficients} coefficient{'s' if coefficients != 1 else ''} and a spread)")


@dataclass(frozen=True)
class DriftSettings:
    parameters: tuple[str, ...] = ("breakaway", "viscous")
    covariates: tuple[str, ...] = ("temperature_mean", "load")
    baseline: int | None = None        # the first N runs of each series (None: default_baseline), unless named
    baseline_runs: tuple[str, ...] = ()  # "campaign/key" or "key"
    significance: float = 3.0          # |coefficient|/standard error to call a covariate found
    false_alarm: float = 0.05          # chance that a stationary campaign raises any alarm (all series, all charts)
    outlier_rate: float = 0.01         # chance per series that a stationary campaign shows an outlier run
    ewma_lambda: float = 0.2
    cusum_k: float = 0.5               # in sigma
    clip: float = 3.0                  # the charts read z clipped to +-clip (one wild run is not a drift)
    penalty: float | None = None       # change-point penalty (None: calibrated)
    min_size: int = 5                  # shortest segment between change points, runs (fewer on short series)
    draws: int = 4000                  # simulated campaigns that calibrate the limits

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


@dataclass
class Series:
    """One parameter of one series of runs: every array has one value per run (start-time order)."""

    name: str
    parameter: str
    value: np.ndarray
    se: np.ndarray
    fitted: np.ndarray
    z: np.ndarray
    ewma: np.ndarray
    ewma_limit: np.ndarray
    cusum_hi: np.ndarray
    cusum_lo: np.ndarray
    sigma: float
    limits: Limits
    covariates: dict[str, dict[str, Any]] = field(default_factory=dict)
    ewma_alarms: list[int] = field(default_factory=list)
    cusum_alarms: list[int] = field(default_factory=list)
    change_points: list[int] = field(default_factory=list)
    outliers: list[int] = field(default_factory=list)
    extrapolated: list[int] = field(default_factory=list)  # runs after the baseline outside its covariate range

    @property
    def cusum_h(self) -> float:
        return self.limits.cusum


@dataclass
class DriftResult:
    """One series of runs (one protocol and analysis settings)."""

    group: str
    settings: DriftSettings
    runs: list[str]                  # "campaign/key" per run, start-time order
    hours: np.ndarray                # run start since the series' first run, h
    distance: np.ndarray             # cumulative sliding distance at the run's end, rad
    covariate_values: dict[str, np.ndarray]
    baseline: np.ndarray             # bool per run
    coefficients: int                # fitted per parameter (intercept and covariates)
    series: dict[str, Series]        # label -> series
    axis: str = "rotary"             # the runs' axis (hilbench.common.units): the parameters' units follow it
    unmonitored: dict[str, str] = field(default_factory=dict)  # label -> why it has no charts (too few runs...)

    @property
    def monitoring_from(self) -> int | None:
        after = np.flatnonzero(~self.baseline)
        return int(after[0]) if after.size else None

    def baseline_line(self) -> str:
        line = baseline_rule(len(self.runs), int(self.baseline.sum()), self.coefficients)
        if not self.series and self.unmonitored:  # one reason for the whole series (too few runs)
            return f"{line}; not charted: {next(iter(self.unmonitored.values()))}"
        return line + "".join(f"; {label} not charted: {why}" for label, why in self.unmonitored.items())


@dataclass
class DriftReport:
    """Every series of a campaign's results."""

    settings: DriftSettings
    groups: list[DriftResult]

    @property
    def series(self) -> dict[str, Series]:
        return {label: s for g in self.groups for label, s in g.series.items()}

    def result_of(self, label: str) -> DriftResult:
        for g in self.groups:
            if label in g.series:
                return g
        raise KeyError(label)

    def summary(self) -> dict[str, Any]:
        """The JSON summary (schema hilbench-drift, version 2; docs/campaign-analysis.md): alarms and change points,
        each with its run; outliers and extrapolated runs per parameter."""
        alarms, params, groups = [], {}, []
        for g in self.groups:
            first = g.monitoring_from
            groups.append({"group": g.group, "axis": g.axis, "runs": len(g.runs), "baseline": int(g.baseline.sum()),
                           "baseline_rule": g.baseline_line(),
                           "monitoring_from": None if first is None or not g.series else g.runs[first],
                           "unmonitored": dict(g.unmonitored)})
            for label, s in g.series.items():
                cps = [{"index": i, "run": g.runs[i], "hours": float(g.hours[i]),
                        "distance_rad": float(g.distance[i - 1]) if i else 0.0,
                        "shift": float(np.mean(s.value[i:]) - np.mean(s.value[:i]))} for i in s.change_points]
                for chart, idx in (("ewma", s.ewma_alarms), ("cusum", s.cusum_alarms)):
                    alarms += [{"parameter": label, "chart": chart, "index": i, "run": g.runs[i]} for i in idx]
                alarms += [{"parameter": label, "chart": "change_point", "index": c["index"], "run": c["run"]}
                           for c in cps]
                lim = s.limits
                params[label] = {
                    "parameter": s.parameter, "group": g.group, "sigma": s.sigma, "covariates": s.covariates,
                    "change_points": cps,
                    "ewma_alarms": [{"index": i, "run": g.runs[i]} for i in s.ewma_alarms],
                    "cusum_alarms": [{"index": i, "run": g.runs[i]} for i in s.cusum_alarms],
                    "outliers": [{"index": i, "run": g.runs[i], "z": float(s.z[i])} for i in s.outliers],
                    "extrapolated": [g.runs[i] for i in s.extrapolated],
                    "baseline_mean": float(np.mean(s.value[g.baseline])),
                    "limits": {"ewma_sigma": _finite(lim.ewma), "cusum_h": _finite(lim.cusum),
                               "change_point_penalty": _finite(lim.penalty), "outlier_z": _finite(lim.outlier),
                               "false_alarm_per_chart": lim.alpha, "draws": lim.draws}}
        baseline = [r for g in self.groups for r, b in zip(g.runs, g.baseline, strict=True) if b]
        first = next((g.runs[g.monitoring_from] for g in self.groups if g.monitoring_from is not None and g.series),
                     None)
        return {"schema": "hilbench-drift", "version": 2, "runs": sum(len(g.runs) for g in self.groups),
                "groups": groups, "baseline": baseline, "monitoring_from": first,
                "settings": self.settings.to_dict(), "parameters": params, "alarms": alarms}


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def _hours(times: list[str]) -> np.ndarray:
    try:
        t = [datetime.fromisoformat(s.replace("Z", "+00:00")).timestamp() for s in times]
    except (AttributeError, ValueError) as exc:
        raise AnalysisError(f"a run's start time is not ISO 8601: {exc}") from None
    return (np.asarray(t) - t[0]) / 3600.0


def _column(rows: list[dict], name: str) -> np.ndarray:
    return np.array([np.nan if r.get(name) is None else float(r[name]) for r in rows])


def _group_key(row: dict) -> tuple[str, str, str]:
    return str(row.get("protocol") or ""), rows_axis([row]), str(row.get("settings_hash") or "")


def group_rows(rows: list[dict[str, Any]]) -> dict[str, tuple[str, list[dict[str, Any]]]]:
    """Rows by series: label -> (the series' axis, its rows); one series per protocol, axis and analysis settings
    (label: the protocol, with the axis where one protocol ran on both, and the settings' hash where one protocol
    was analysed with several settings)."""
    keys = sorted({_group_key(r) for r in rows})
    out: dict[str, tuple[str, list[dict[str, Any]]]] = {}
    for key in keys:
        p, a, h = key
        same = [k for k in keys if k[0] == p]
        label = " ".join([p] + ([a] if len({k[1] for k in same}) > 1 else [])
                         + ([h[:8]] if len({k[2] for k in same}) > 1 else [])).strip()
        out[label] = (a, [r for r in rows if _group_key(r) == key])
    return out


def _covariate_design(cov: dict[str, np.ndarray], base: np.ndarray) -> tuple[np.ndarray, list[str], dict]:
    """(design with an intercept and the usable covariates centred on the baseline, their names, the report of
    the covariates left out)."""
    report: dict[str, dict[str, Any]] = {}
    kept = []
    for name, x in cov.items():
        if not np.all(np.isfinite(x)):
            report[name] = {"found": False, "reason": "not recorded for every run"}
        elif np.ptp(x[base]) == 0:
            report[name] = {"found": False, "reason": "constant over the baseline"}
        else:
            kept.append(name)
    centres = [float(np.mean(cov[n][base])) for n in kept]
    design = np.column_stack([np.ones(base.size)] + [cov[n] - c for n, c in zip(kept, centres, strict=True)])
    for n, c in zip(kept, centres, strict=True):
        report[n] = {"centre": c}
    return design, kept, report


def _baseline(runs: list[str], s: DriftSettings, coefficients: int) -> np.ndarray:
    if s.baseline_runs:
        named = set(s.baseline_runs)
        return np.array([run in named or run.split("/", 1)[1] in named for run in runs])
    n = len(runs)
    size = default_baseline(n, coefficients) if s.baseline is None else s.baseline
    if not coefficients + 2 <= size <= n:
        raise AnalysisError(f"baseline of {size} runs: need {coefficients + 2} to {n} (the runs analysed; "
                            f"{coefficients} coefficient{'s' if coefficients != 1 else ''} and a spread)")
    return np.arange(n) < size


def _series_result(label: str, axis: str, rows: list[dict[str, Any]], s: DriftSettings, alpha: float, seed: int
                   ) -> DriftResult:
    rows = sorted(rows, key=lambda r: (str(r.get("start_time")), str(r.get("campaign")), str(r.get("key"))))
    runs = [f"{r.get('campaign')}/{r.get('key')}" for r in rows]
    n = len(runs)
    cov = {c: _column(rows, c) for c in s.covariates}
    usable = sum(bool(np.all(np.isfinite(x)) and np.ptp(x) > 0) for x in cov.values())
    hours = _hours([str(r.get("start_time")) for r in rows])
    distance = np.cumsum(np.nan_to_num(_column(rows, "sliding_distance")))
    if s.baseline is None and not s.baseline_runs and n < usable + 3:
        # too few runs for a fit and a spread: the default baseline is all of them, reported, nothing charted yet
        # (issue #38: a 4-run planned campaign has one identification and one chirp run). Over all runs a
        # covariate varies over the baseline exactly when it varies at all: the coefficients are 1 + usable.
        p = 1 + usable
        why = (f"{n} run{'s' if n != 1 else ''}: too few to chart (a baseline needs {p + 2}: {p} "
               f"coefficient{'s' if p != 1 else ''} and a spread)")
        return DriftResult(label, s, runs, hours, distance, cov, np.ones(n, bool), p, {}, axis,
                           {_label(name, label): why for name in s.parameters})
    base = _baseline(runs, s, 1 + usable)
    design, kept, report = _covariate_design(cov, base)
    p = design.shape[1]
    if int(base.sum()) < p + 2:
        raise AnalysisError(f"{label or 'the runs'}: a baseline of {int(base.sum())} runs is too short for {p} "
                            "coefficients and a spread (use a longer baseline)")
    min_size = max(2, min(s.min_size, n // 4))
    mon = ~base
    xb = design[base]
    inv = np.linalg.pinv(xb.T @ xb)
    outside = np.zeros(n, bool)
    for j in range(1, p):
        lo, hi = design[base, j].min(), design[base, j].max()
        outside |= (design[:, j] < lo) | (design[:, j] > hi)
    extrapolated = [int(i) for i in np.flatnonzero(outside & mon)]
    series, unmonitored = {}, {}
    for name in s.parameters:
        y, se = _column(rows, name), _column(rows, f"{name}_se")
        if not np.all(np.isfinite(y)):
            raise AnalysisError(f"parameter {name!r} is missing in {int(np.sum(~np.isfinite(y)))} of the runs")
        z2, fitted2, sig = standardise(y[None, :], design, base)
        z, fitted, sigma = z2[0], fitted2[0], float(sig[0])
        if not sigma > 1e-12 * max(1.0, float(np.max(np.abs(y[base])))):
            # a noise-free simulator repeats a run bit for bit (a chirp has no seed): no scale to score against
            differ = int(np.sum(np.abs(y[~base] - fitted[~base]) > 1e-12 * max(1.0, float(np.max(np.abs(y))))))
            unmonitored[_label(name, label)] = (f"no spread over the {int(base.sum())} baseline runs (identical "
                                                f"values); {differ} later run(s) differ from them")
            continue
        # the limits, calibrated on simulated in-control campaigns of this design whose noise has the law of this
        # parameter's own baseline scores (analysis.drift.calibration)
        lim = calibrate(design, base, alpha=alpha, alpha_outlier=s.outlier_rate, lam=s.ewma_lambda, k=s.cusum_k,
                        clip=s.clip, min_size=min_size, draws=s.draws, seed=seed, shape=z[base])
        coef = np.linalg.lstsq(xb, y[base], rcond=None)[0]
        cse = np.sqrt(np.diag(sigma**2 * inv))
        cov_report = {k: dict(v) for k, v in report.items()}
        for j, c in enumerate(kept, start=1):
            cov_report[c].update(found=bool(abs(coef[j]) >= s.significance * cse[j]), coefficient=float(coef[j]),
                                 se=float(cse[j]))
        zc = clipped(z2, base, s.clip)[0]
        w, lim_e, hi, lo = (np.full(n, np.nan) for _ in range(4))
        ewma_alarms: list[int] = []
        cusum_alarms: list[int] = []
        if mon.any():
            start = int(np.flatnonzero(mon)[0])
            ww, sd = ewma_paths(zc[None, mon], s.ewma_lambda)
            w[mon], lim_e[mon] = ww[0], lim.ewma * sd
            hh, ll = cusum_paths(zc[None, mon], s.cusum_k)
            hi[mon], lo[mon] = hh[0], ll[0]
            ewma_alarms = [start + i for i in signals(np.abs(w[mon]) > lim_e[mon])]
            cusum_alarms = [start + i for i in signals(np.maximum(hi[mon], lo[mon]) > lim.cusum)]
        pen = s.penalty if s.penalty is not None else lim.penalty
        label_name = _label(name, label)
        series[label_name] = Series(
            label_name, name, y, se, fitted, z, w, lim_e, hi, lo, sigma, lim, cov_report,
            ewma_alarms=ewma_alarms, cusum_alarms=cusum_alarms, change_points=change_points(zc, pen, min_size),
            outliers=[int(i) for i in np.flatnonzero(np.abs(z) > lim.outlier)], extrapolated=extrapolated)
    return DriftResult(label, s, runs, hours, distance, cov, base, p, series, axis, unmonitored)


def _label(name: str, group: str) -> str:
    return name if not group else f"{name} [{group}]"


def monitor(rows: list[dict[str, Any]], settings: DriftSettings | None = None) -> DriftReport:
    """Drift of ``settings.parameters`` over ``rows`` (one identify row per run, any order; status ``ok`` only),
    one series per protocol and analysis settings."""
    s = settings or DriftSettings()
    if not 0 < s.false_alarm < 1:
        raise AnalysisError(f"false-alarm rate {s.false_alarm:g}: must lie in (0, 1)")
    rows = [r for r in rows if r.get("status") == "ok"]
    if not rows:
        raise AnalysisError("no analysed run (status ok) to follow")
    if s.baseline_runs:
        runs = {f"{r.get('campaign')}/{r.get('key')}" for r in rows}
        missing = set(s.baseline_runs) - runs - {r.split("/", 1)[1] for r in runs}
        if missing:
            raise AnalysisError(f"baseline run(s) not in the results: {', '.join(sorted(missing))}")
    groups = group_rows(rows)
    single = len(groups) == 1
    alpha = s.false_alarm / (CHARTS * len(s.parameters) * len(groups))
    results = [_series_result("" if single else label, axis, rs, s, alpha, seed=i) for i, (label, (axis, rs)) in
               enumerate(groups.items())]
    if single:
        results[0].group = next(iter(groups))
    return DriftReport(s, results)
