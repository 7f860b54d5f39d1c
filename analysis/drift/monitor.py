"""Drift of identified parameters over a campaign's runs: covariates first, then charts on the residuals.

For each monitored parameter y (one value per run, in start-time order):

1. The dependence on the covariates (winding temperature, load) is fitted on the baseline runs by ordinary
   least squares, y = c0 + sum_j c_j*(x_j - mean_b(x_j)), over every covariate recorded for all runs that
   varies over the baseline. A dependence is "found" when its coefficient stands out (|c_j| >= ``significance``
   times its standard error); a weaker one stays in the fit (it costs one degree of freedom, and dropping a
   real but weak dependence would leave it in the residuals to raise alarms).
2. Residuals r = y - fit over every run; sigma from the baseline residuals (n_b - p degrees of freedom);
   z = r/sigma.
3. EWMA and CUSUM over the runs after the baseline on z clipped to +-``clip`` (3): the estimates of short runs
   have heavy tails (a poorly excited run may land 8 sigma off), and one wild run must not read as a drift,
   while a sustained shift still moves both charts. PELT change points on z over all runs
   (analysis.drift.charts). An alarm names the run where it starts.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from datetime import datetime
from typing import Any

import numpy as np

from hilbench.analysis.drift.charts import change_points, cusum, default_penalty, ewma, signals
from hilbench.analysis.errors import AnalysisError


@dataclass(frozen=True)
class DriftSettings:
    parameters: tuple[str, ...] = ("breakaway", "viscous")
    covariates: tuple[str, ...] = ("temperature_mean", "load")
    baseline: int = 50                 # the first N runs, unless baseline_runs names them
    baseline_runs: tuple[str, ...] = ()  # "campaign/key" or "key"
    significance: float = 3.0          # |coefficient|/standard error to keep a covariate
    ewma_lambda: float = 0.2
    ewma_limit: float = 4.0            # in sigma of the EWMA (false alarms: docs/campaign-analysis.md)
    cusum_k: float = 0.5               # in sigma
    cusum_h: float = 8.0               # in sigma
    clip: float = 3.0                  # the charts read z clipped to +-clip (one wild run is not a drift)
    penalty: float | None = None       # PELT penalty (None: 3 ln n)
    min_size: int = 5                  # shortest segment between change points, runs

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


@dataclass
class Series:
    """One parameter's monitoring: every array has one value per run (start-time order)."""

    name: str
    value: np.ndarray
    se: np.ndarray
    fitted: np.ndarray
    z: np.ndarray
    ewma: np.ndarray
    ewma_limit: np.ndarray
    cusum_hi: np.ndarray
    cusum_lo: np.ndarray
    sigma: float
    covariates: dict[str, dict[str, Any]] = field(default_factory=dict)
    ewma_alarms: list[int] = field(default_factory=list)
    cusum_alarms: list[int] = field(default_factory=list)
    change_points: list[int] = field(default_factory=list)


@dataclass
class DriftResult:
    settings: DriftSettings
    runs: list[str]                  # "campaign/key" per run, start-time order
    hours: np.ndarray                # run start since the first run, h
    distance: np.ndarray             # cumulative sliding distance at the run's end, rad
    covariate_values: dict[str, np.ndarray]
    baseline: np.ndarray             # bool per run
    series: dict[str, Series]

    def summary(self) -> dict[str, Any]:
        """The JSON summary: alarms and change points, each with its run."""
        alarms, params = [], {}
        first = int(np.flatnonzero(~self.baseline)[0]) if (~self.baseline).any() else len(self.runs)
        for name, s in self.series.items():
            cps = [{"index": i, "run": self.runs[i], "hours": float(self.hours[i]),
                    "distance_rad": float(self.distance[i - 1]) if i else 0.0,
                    "shift": float(np.mean(s.value[i:]) - np.mean(s.value[:i]))} for i in s.change_points]
            for chart, idx in (("ewma", s.ewma_alarms), ("cusum", s.cusum_alarms)):
                alarms += [{"parameter": name, "chart": chart, "index": i, "run": self.runs[i]} for i in idx]
            alarms += [{"parameter": name, "chart": "change_point", "index": c["index"], "run": c["run"]}
                       for c in cps]
            params[name] = {"sigma": s.sigma, "covariates": s.covariates, "change_points": cps,
                            "ewma_alarms": [{"index": i, "run": self.runs[i]} for i in s.ewma_alarms],
                            "cusum_alarms": [{"index": i, "run": self.runs[i]} for i in s.cusum_alarms],
                            "baseline_mean": float(np.mean(s.value[self.baseline]))}
        return {"schema": "hilbench-drift", "version": 1, "runs": len(self.runs),
                "baseline": [r for r, b in zip(self.runs, self.baseline, strict=True) if b],
                "monitoring_from": self.runs[first] if first < len(self.runs) else None,
                "settings": self.settings.to_dict(), "parameters": params, "alarms": alarms}


def _hours(times: list[str]) -> np.ndarray:
    try:
        t = [datetime.fromisoformat(s.replace("Z", "+00:00")).timestamp() for s in times]
    except (AttributeError, ValueError) as exc:
        raise AnalysisError(f"a run's start time is not ISO 8601: {exc}") from None
    return (np.asarray(t) - t[0]) / 3600.0


def _column(rows: list[dict], name: str) -> np.ndarray:
    return np.array([np.nan if r.get(name) is None else float(r[name]) for r in rows])


def _fit_covariates(y: np.ndarray, cov: dict[str, np.ndarray], base: np.ndarray, significance: float
                    ) -> tuple[np.ndarray, float, dict[str, dict[str, Any]]]:
    """(fitted over all runs, residual sigma of the baseline, covariate report)."""
    report: dict[str, dict[str, Any]] = {}
    kept = []
    for name, x in cov.items():
        xb = x[base]
        if not np.all(np.isfinite(x)):
            report[name] = {"found": False, "reason": "not recorded for every run"}
        elif np.ptp(xb) == 0:
            report[name] = {"found": False, "reason": "constant over the baseline"}
        else:
            kept.append(name)
    centres = {n: float(np.mean(cov[n][base])) for n in kept}
    design = np.column_stack([np.ones(y.size)] + [cov[n] - centres[n] for n in kept])
    coef, *_ = np.linalg.lstsq(design[base], y[base], rcond=None)
    resid = y[base] - design[base] @ coef
    dof = int(base.sum()) - design.shape[1]
    if dof < 2:
        raise AnalysisError(f"the baseline has {int(base.sum())} runs: too few for {design.shape[1]} "
                            "coefficients and a spread (use a longer baseline)")
    s2 = float(resid @ resid) / dof
    se = np.sqrt(np.diag(s2 * np.linalg.pinv(design[base].T @ design[base])))
    for j, n in enumerate(kept, start=1):
        report[n] = {"found": bool(abs(coef[j]) >= significance * se[j]), "coefficient": float(coef[j]),
                     "se": float(se[j]), "centre": centres[n]}
    return design @ coef, math.sqrt(s2), report


def monitor(rows: list[dict[str, Any]], settings: DriftSettings | None = None) -> DriftResult:
    """Drift of ``settings.parameters`` over ``rows`` (one identify row per run, any order; status ``ok`` only)."""
    s = settings or DriftSettings()
    rows = [r for r in rows if r.get("status") == "ok"]
    if not rows:
        raise AnalysisError("no analysed run (status ok) to follow")
    rows.sort(key=lambda r: (str(r.get("start_time")), str(r.get("campaign")), str(r.get("key"))))
    runs = [f"{r.get('campaign')}/{r.get('key')}" for r in rows]
    if s.baseline_runs:
        named = set(s.baseline_runs)
        base = np.array([run in named or run.split("/", 1)[1] in named for run in runs])
        missing = named - {r for r in runs} - {r.split("/", 1)[1] for r in runs}
        if missing:
            raise AnalysisError(f"baseline run(s) not in the results: {', '.join(sorted(missing))}")
    else:
        if not 3 <= s.baseline <= len(rows):
            raise AnalysisError(f"baseline of {s.baseline} runs: need 3 to {len(rows)} (the runs analysed)")
        base = np.arange(len(rows)) < s.baseline
    distance = np.cumsum(np.nan_to_num(_column(rows, "sliding_distance")))
    cov = {c: _column(rows, c) for c in s.covariates}
    series = {}
    for name in s.parameters:
        y, se = _column(rows, name), _column(rows, f"{name}_se")
        if not np.all(np.isfinite(y)):
            raise AnalysisError(f"parameter {name!r} is missing in {int(np.sum(~np.isfinite(y)))} of the runs")
        fitted, sigma, report = _fit_covariates(y, cov, base, s.significance)
        if sigma == 0:
            raise AnalysisError(f"{name}: no spread over the baseline; the charts need one")
        z = (y - fitted) / sigma
        # the charts run from the first run after the baseline (phase II); NaN before it
        start = int(np.flatnonzero(~base)[0]) if (~base).any() else z.size
        w, lim, hi, lo = (np.full(z.size, np.nan) for _ in range(4))
        if start < z.size:
            zc = np.clip(z[start:], -s.clip, s.clip)
            w[start:], lim[start:] = ewma(zc, s.ewma_lambda, s.ewma_limit)
            hi[start:], lo[start:] = cusum(zc, s.cusum_k, s.cusum_h)
        series[name] = Series(
            name, y, se, fitted, z, w, lim, hi, lo, sigma, report,
            ewma_alarms=[start + i for i in signals(np.abs(w[start:]) > lim[start:])],
            cusum_alarms=[start + i for i in signals(np.maximum(hi[start:], lo[start:]) > s.cusum_h)],
            change_points=change_points(z, s.penalty if s.penalty is not None else default_penalty(z.size),
                                        s.min_size))
    return DriftResult(s, runs, _hours([str(r.get("start_time")) for r in rows]), distance, cov, base, series)
