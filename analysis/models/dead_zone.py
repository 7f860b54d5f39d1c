"""The skeleton and the AFRF on the continuous hysteresis model: does the damping dead-zone go?

The paper's discretised Maxwell-slip model has no damping below its smallest slip displacement: every element
sticks there. This is the dead-zone of the equivalent damping, an artefact of the discretisation. The paper
expected a continuous model to remove it. This module runs the paper's skeleton procedure on the paper's
mass-spring system (m = 1 kg, k = 50 N/m, h = 1.64 N, d = 0.656 m) twice: once with the 16-element
Maxwell-slip friction, once with the continuous virgin-curve hysteresis (firmware_sim.engine.plant.Hysteresis).
The procedure is the same chirps, ForceVib and composition (``analysis.reproductions.paper``). The module then
builds the continuous model's equivalent (describing form) and compares its AFRF with the original's
(docs/compare.md, "Skeleton and AFRF of the continuous model").
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hilbench.analysis.afrf.frf import settle_schedule, simulate_afrf_models
from hilbench.analysis.reproductions.paper import (
    CONTINUOUS_LEVELS,
    PAPER_AFRF_AMPLITUDES,
    afrf_db_error,
    chirp_analysis,
    virgin_closed_form,
)
from hilbench.analysis.skeleton.equivalent import equivalent_params
from hilbench.analysis.skeleton.forcevib import compose
from hilbench.analysis.skeleton.skeleton_fit import fit_skeleton_monotone
from hilbench.firmware_sim.engine.friction_models import PAPER_D, PAPER_H, PAPER_MASS, PAPER_SPRING, paper_system
from hilbench.firmware_sim.engine.plant import Hysteresis, PlantParams

DEAD_ZONE_LEVEL = 0.05  # N: the chirp that stays below the 16-element model's smallest slip displacement
#: Bins below this amplitude (m) are the skeleton method's noise floor at G = 0.05 for both models (E ~ 1e-8 J,
#: the quasi-static start of the chirp), not friction.
NOISE_FLOOR_AMPLITUDE = 1.5e-3


def continuous_system(stack: int = 64) -> PlantParams:
    """The paper's mass-spring system with the continuous virgin-curve hysteresis instead of 16 elements."""
    return PlantParams(inertia=PAPER_MASS, spring=PAPER_SPRING, hysteresis=Hysteresis(PAPER_H, PAPER_D, stack))


def dead_zone(levels: tuple[float, ...] = (DEAD_ZONE_LEVEL,), rate: float = 0.05, duration: float = 40.0,
              fs: float = 1000.0) -> dict:
    """Skeleton energy per cycle against the continuous closed form E = 4hA^3/(d+A)^2, for both models, in the
    bins between the noise floor and the 16-element model's smallest slip displacement Delta_min.

    Returns per model: the bin amplitudes (m) and E/E_closed - 1 there, and the band's median."""
    ms = paper_system(16)
    delta_min = float(np.min(np.asarray(ms.ms_slip) / np.asarray(ms.ms_stiffness)))
    out: dict = {"delta_min": delta_min, "levels": list(levels)}
    for name, params in (("maxwell_slip_16", ms), ("continuous", continuous_system())):
        curves = compose([chirp_analysis(params, g, rate, duration, fs).result for g in levels], n_bins=30)
        a = curves.amplitude
        band = (a >= NOISE_FLOOR_AMPLITUDE) & (a < delta_min)
        rel = curves.energy[band] / virgin_closed_form(a[band])[1] - 1
        out[name] = {"amplitude": a[band].tolist(), "energy_rel_error": rel.tolist(),
                     "median_energy_rel_error": float(np.median(rel))}
    return out


def continuous_skeleton_and_afrf(levels: tuple[float, ...] = CONTINUOUS_LEVELS,
                                 amplitudes: tuple[float, ...] = PAPER_AFRF_AMPLITUDES, n_frequencies: int = 25,
                                 rate: float = 0.05, duration: float = 40.0, fs: float = 1000.0,
                                 progress: Callable[[str], None] = print) -> dict:
    """The composed skeleton of the continuous model against its closed forms (k_eq and E per bin), its
    equivalent model, and the AFRF error of that equivalent against the original (no spring, as in the paper)."""
    params = continuous_system()
    progress(f"  continuous model: {len(levels)} chirps")
    curves = compose([chirp_analysis(params, g, rate, duration, fs).result for g in levels], n_bins=30)
    kc, ec = virgin_closed_form(curves.amplitude)
    k_rel = curves.stiffness / kc - 1
    e_rel = curves.energy / ec - 1
    checked = curves.amplitude >= 0.01
    mono = fit_skeleton_monotone(curves.amplitude, curves.stiffness, curves.velocity, curves.damping_force)
    equivalent = equivalent_params(mono, params.inertia, 0.0, form="describing")
    original = params.replace(spring=0.0)
    frequencies = np.geomspace(0.1, 10.0, n_frequencies)
    slow_mode = 2 * np.pi / np.sqrt(2 * PAPER_H / PAPER_D / params.inertia)
    settle = settle_schedule(frequencies, min_periods=40, min_time=20 * slow_mode)
    progress(f"  AFRF: {len(amplitudes)} amplitudes x {n_frequencies} frequencies, original and equivalent")
    res = simulate_afrf_models({"original": original, "equivalent": equivalent}, amplitudes, frequencies,
                               samples_per_period=256, settle_periods=settle, measure_periods=10, n_harmonics=3)
    ref = res["original"].magnitudes
    eq = res["equivalent"].magnitudes
    rows = [{"amplitude": float(g), "rms_db": [float(v) for v in afrf_db_error(eq[i], ref[i])],
             "h1_median_rel": float(np.median(np.abs(eq[i][:, 0] / ref[i][:, 0] - 1)))}
            for i, g in enumerate(amplitudes)]
    return {
        "skeleton": {"amplitude": curves.amplitude.tolist(), "k_rel_error": k_rel.tolist(),
                     "energy_rel_error": e_rel.tolist(), "checked_from": 0.01,
                     "max_k_rel_error_checked": float(np.max(np.abs(k_rel[checked]))),
                     "max_energy_rel_error_checked": float(np.max(np.abs(e_rel[checked]))),
                     "median_energy_rel_error_checked": float(np.median(np.abs(e_rel[checked])))},
        "afrf": rows,
        "frequencies_hz": frequencies.tolist(),
    }


def main() -> None:
    """Print the dead-zone band and the continuous model's skeleton and AFRF figures (about 1-2 min)."""
    d = dead_zone()
    print(f"below Delta_min = {d['delta_min'] * 1e3:.2f} mm (G = {DEAD_ZONE_LEVEL} N): skeleton E/E_closed - 1, "
          f"median: 16 elements {d['maxwell_slip_16']['median_energy_rel_error']:+.3f}, "
          f"continuous {d['continuous']['median_energy_rel_error']:+.3f}")
    r = continuous_skeleton_and_afrf()
    s = r["skeleton"]
    print(f"continuous skeleton, A >= 0.01 m: max |k_eq error| {s['max_k_rel_error_checked']:.4f}, "
          f"max |E error| {s['max_energy_rel_error_checked']:.4f}, median {s['median_energy_rel_error_checked']:.4f}")
    print("AFRF, equivalent against original, rms dB over frequency (H1 / H2 / H3):")
    for row in r["afrf"]:
        print(f"  G = {row['amplitude']:g} N: " + " / ".join(f"{v:.2f}" for v in row["rms_db"]))


if __name__ == "__main__":
    main()
