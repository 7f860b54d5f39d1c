"""AFRF speed: the paper's Fig 13 grid (science.md §5) on 2 cores against the same grid serially.

Grid: 9 amplitudes (0.1, 0.2, 0.5, 0.8, 1, 1.5, 2, 5, 10 N) x 50 frequencies (0.1-10 Hz, log-spaced) x 3
models: the original Maxwell-slip system (paper_system(spring=0), N = 16), Coulomb (m = 1, Fc = 1.5 N) and
the equivalent built from the closed forms k_eq(A), E(A) (hilbench.analysis.afrf.frf.closed_form_equivalent, a
placeholder for the fitted skeleton model). Settings (docs/afrf.md): 256 samples per period, settle
max(40 periods, 60 s) of which the first half is a smooth onset, 10 measured periods.

Target (issue 6): under 60 s on 2 cores. Baseline, measured in the same run: the same grid in one process.
Also reported: the fraction of cells in steady state (period-to-period change < 1e-3 of |X(f)|) and the
equivalent-vs-original error of the first harmonic per amplitude (rms of the dB difference).
"""

from __future__ import annotations

import time

import numpy as np

AMPLITUDES = (0.1, 0.2, 0.5, 0.8, 1.0, 1.5, 2.0, 5.0, 10.0)


def _row(name, value, unit, baseline_name=None, baseline_value=None, target="", ok=None):
    ratio = None if not baseline_value else value / baseline_value
    return {"name": name, "value": float(value), "unit": unit, "baseline_name": baseline_name,
            "baseline_value": None if baseline_value is None else float(baseline_value), "ratio": ratio,
            "target": target, "ok": ok}


def run(quick: bool = False) -> list[dict]:
    from hilbench.analysis.afrf.frf import (
        afrf_error,
        closed_form_equivalent,
        coulomb_system,
        settle_schedule,
        simulate_afrf_models,
    )
    from hilbench.firmware_sim.engine.friction_models import PAPER_D, PAPER_H, paper_system

    models = {"original": paper_system(spring=0.0), "coulomb": coulomb_system(1.5),
              "equivalent": closed_form_equivalent(PAPER_H, PAPER_D)}
    if quick:
        amps, freqs = (0.5, 5.0), np.geomspace(0.1, 10.0, 4)
        kw = dict(samples_per_period=128, settle_periods=settle_schedule(freqs, 10, 0.0), measure_periods=3)
    else:
        amps, freqs = AMPLITUDES, np.geomspace(0.1, 10.0, 50)
        kw = dict(samples_per_period=256, settle_periods=settle_schedule(freqs, 40, 60.0), measure_periods=10)
    n_cells = len(amps) * freqs.size * len(models)

    t0 = time.perf_counter()
    par = simulate_afrf_models(models, amps, freqs, workers=2, axis="linear", **kw)
    t_par = time.perf_counter() - t0
    t0 = time.perf_counter()
    ser = simulate_afrf_models(models, amps, freqs, workers=1, axis="linear", **kw)
    t_ser = time.perf_counter() - t0
    same = all(np.array_equal(par[k].response, ser[k].response) for k in models)

    grid = "quick grid" if quick else "Fig 13 grid"
    rows = [_row(f"afrf {grid} ({n_cells} cells), 2 workers", t_par, "s", "same grid, 1 process", t_ser,
                 "< 60 s on 2 cores", (t_par < 60.0) and same)]
    for name, r in par.items():
        rows.append(_row(f"afrf steady cells (conv < 1e-3), {name}", float(np.mean(r.convergence < 1e-3)), "1"))
    table = afrf_error(par["original"], par["equivalent"])
    for row in table[table["harmonic"] == 1]:
        rows.append(_row(f"afrf equivalent vs original, 1f, G={row['amplitude']:g}", row["rms_db"], "dB rms"))
    return rows


if __name__ == "__main__":
    for r in run():
        print(r)
