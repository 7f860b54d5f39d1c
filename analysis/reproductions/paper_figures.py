"""PNG figures and the Markdown summary of the paper reproduction (:mod:`hilbench.analysis.reproductions.paper`).

One file per paper figure (matplotlib Agg, ~100 dpi, units on every axis); ``write_summary`` writes
``summary.md`` (figure map, key numbers, inferred settings) and ``summary.json`` (the same numbers).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from hilbench.analysis.reproductions.paper import (
    ENERGY_CHECK_FROM,
    HARMONICS,
    INFERRED,
    TOLERANCE,
    PaperResult,
    Study,
    maxwell_slip_closed_form,
    virgin_closed_form,
)
from hilbench.analysis.skeleton.equivalent import describing_function
from hilbench.firmware_sim.engine.friction_models import PAPER_D, PAPER_H, maxwell_virgin_curve, virgin_curve
from hilbench.firmware_sim.engine.plant import stop_operator

DPI = 100

#: our file -> (paper figure, caption)
FIGURES = {
    "fig04_virgin_hysteresis.png": (
        "Fig. 4 (and Fig. 1)",
        "continuous and 16-element virgin curve; hysteresis with an inner loop (non-local memory)",
    ),
    "fig05_chirp_response.png": (
        "Fig. 5",
        "chirp input G = 5 and displacement with Hilbert / wavelet envelopes",
    ),
    "fig06_instantaneous_frequency.png": ("Fig. 6", "instantaneous frequency, wavelet ridge vs Hilbert"),
    "fig07_08_single_run.png": (
        "Figs 7-8",
        "restoring force vs amplitude and damping force vs velocity, G = 5",
    ),
    "fig09_restoring_composed.png": ("Fig. 9", "restoring force composed over all G, with closed forms"),
    "fig10_damping_composed.png": ("Fig. 10", "damping force composed over all G; inset: the dead-zone"),
    "fig11_stiffness_errors.png": (
        "Fig. 11",
        "k_eq(A) vs virgin curve and closed forms; errors of k_eq and E per bin (dead-zone shaded)",
    ),
    "fig11b_chirp_ends.png": (
        "(ours)",
        "where a single run departs: energy error along the chirp, its ends "
        "(cone of influence) and the fast amplitude changes",
    ),
    "fig12_fits.png": ("Fig. 12", "paper's forms and monotone fits; equivalent F_k(x), F_d(v) tables"),
    "fig13_afrf.png": ("Fig. 13", "AFRFs (harmonics 1-3) of original, Coulomb and equivalent systems"),
    "fig15_motor_equivalent.png": ("Fig. 15", "motor: equivalent restoring and damping torque"),
    "fig16_motor_afrf.png": (
        "Fig. 16",
        "motor: AFRFs of the Maxwell-slip model ('measured'), Coulomb, equivalent",
    ),
}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    _plt().close(fig)
    return path


def _run(study: Study, level: float):
    return min(study.runs, key=lambda r: abs(r.level - level))


def fig04(study: Study, out: Path) -> Path:
    plt = _plt()
    p = study.params
    k, w = np.asarray(p.ms_stiffness), np.asarray(p.ms_slip)
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    x = np.linspace(0, 3.0, 600)
    ax[0].plot(x, virgin_curve(x, PAPER_H, PAPER_D), "k", label="continuous virgin curve")
    ax[0].plot(x, maxwell_virgin_curve(x, k, w), "r--", label="16-element Maxwell-slip")
    ax[0].set_xlabel("displacement x (m)")
    ax[0].set_ylabel("friction force (N)")
    ax[0].legend()
    # reversal path 0 -> 2 -> -1 -> 1 -> -0.5 -> 0.5 -> -2 (inner loops close and are forgotten)
    pts = [0, 2, -1, 1, -0.5, 0.5, -2, 2]
    xs = np.concatenate([np.linspace(a, b, 300) for a, b in zip(pts[:-1], pts[1:], strict=True)])
    f = stop_operator(xs, w / k) @ k
    ax[1].plot(xs, f, "b", lw=1)
    ax[1].plot(x, virgin_curve(x, PAPER_H, PAPER_D), "k:", lw=1, label="virgin curve")
    ax[1].set_xlabel("displacement x (m)")
    ax[1].set_ylabel("friction force (N)")
    ax[1].set_title("hysteresis with inner loops")
    ax[1].legend()
    for a in ax:
        a.grid(alpha=0.3)
    return _save(fig, out / "fig04_virgin_hysteresis.png")


def fig05_06(study: Study, out: Path) -> list[Path]:
    from scipy.signal import hilbert

    plt = _plt()
    r = _run(study, 5.0)
    env_h = np.abs(hilbert(r.x))
    ph = np.unwrap(np.angle(hilbert(r.x)))
    f_h = np.gradient(ph, r.t) / (2 * np.pi)
    inst = r.result.instantaneous
    v = inst.valid
    fig, ax = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    ax[0].plot(r.t, r.force, "k", lw=0.4)
    ax[0].set_ylabel("force F (N)")
    ax[0].set_title(f"chirp F = G*sin(pi*a*t^2), G = {r.level:g} N")
    ax[1].plot(r.t, r.x, color="0.6", lw=0.4, label="displacement")
    ax[1].plot(r.t, env_h, "c", lw=0.8, label="Hilbert envelope")
    ax[1].plot(r.t[v], inst.amplitude[v], "r.", ms=1, label="wavelet envelope (valid samples)")
    ax[1].set_xlabel("time (s)")
    ax[1].set_ylabel("displacement x (m)")
    ax[1].legend(loc="upper left", fontsize=8)
    p5 = _save(fig, out / "fig05_chirp_response.png")
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(r.t, f_h, "c", lw=0.6, label="Hilbert extraction")
    ax.plot(r.t[v], inst.frequency_hz[v], "r.", ms=1, label="wavelet extraction")
    ax.set_ylim(0, 3)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("frequency (Hz)")
    ax.legend()
    ax.grid(alpha=0.3)
    return [p5, _save(fig, out / "fig06_instantaneous_frequency.png")]


def fig07_08(study: Study, out: Path) -> Path:
    plt = _plt()
    r = _run(study, 5.0).result
    v = r.valid
    a = np.geomspace(r.amplitude[v].min(), r.amplitude[v].max(), 200)
    kc, _ = virgin_closed_form(a)
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].plot(r.amplitude[v], r.restoring_force[v], ".", ms=1, color="0.4", label="ForceVib samples")
    ax[0].plot(a, kc * a, "k", label="closed form k_eq(A)*A")
    ax[0].set_xlabel("displacement amplitude A (m)")
    ax[0].set_ylabel("restoring force of friction (N)")
    ax[1].plot(r.velocity_amplitude[v], r.damping_force[v], ".", ms=1, color="0.4", label="ForceVib samples")
    ax[1].set_xlabel("velocity amplitude V (m/s)")
    ax[1].set_ylabel("damping force (N)")
    for x in ax:
        x.grid(alpha=0.3)
        x.legend()
    ax[0].set_title("G = 5 N")
    return _save(fig, out / "fig07_08_single_run.png")


def _by_run(ax, study: Study, xs, ys):
    c = study.curves
    cmap = _plt().get_cmap("viridis")
    for i, r in enumerate(study.runs):
        m = c.points_run == i
        ax.plot(
            xs[m],
            ys[m],
            ".",
            ms=1,
            color=cmap(i / max(len(study.runs) - 1, 1)),
            label=f"G = {r.level:g}" if i % 2 == 0 else None,
        )


def fig09_10(study: Study, out: Path) -> list[Path]:
    plt = _plt()
    c = study.curves
    a = np.geomspace(c.amplitude.min(), c.amplitude.max(), 300)
    k16, e16 = maxwell_slip_closed_form(study.params, a)
    kc, ec = virgin_closed_form(a)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    _by_run(ax, study, c.points_amplitude, c.points_restoring_force)
    ax.plot(c.amplitude, c.restoring_force, "ko", ms=3, label="composed (bin medians)")
    ax.plot(a, kc * a, "k-", lw=1, label="closed form, continuous")
    ax.plot(a, k16 * a, "r--", lw=1, label="closed form, 16 elements")
    ax.set_xscale("log")
    ax.set_xlabel("displacement amplitude A (m)")
    ax.set_ylabel("restoring force of friction k_eq*A (N)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3, which="both")
    p9 = _save(fig, out / "fig09_restoring_composed.png")
    fig, ax = plt.subplots(figsize=(8, 4.5))
    _by_run(ax, study, c.points_velocity, c.points_damping_force)
    ax.plot(c.velocity, c.damping_force, "ko", ms=3, label="composed (bin medians)")
    ax.set_xlabel("velocity amplitude V (m/s)")
    ax.set_ylabel("damping force c_eq*V (N)")
    ax.legend(fontsize=7, ncol=2, loc="lower right")
    ax.grid(alpha=0.3)
    ins = ax.inset_axes([0.12, 0.5, 0.35, 0.4])
    small = c.points_velocity < 0.3
    ins.plot(c.points_velocity[small], c.points_damping_force[small], ".", ms=1, color="0.4")
    m = c.velocity < 0.3
    ins.plot(c.velocity[m], c.damping_force[m], "ko", ms=2)
    ins.set_title("dead-zone near V = 0", fontsize=7)
    ins.tick_params(labelsize=6)
    p10 = _save(fig, out / "fig10_damping_composed.png")
    return [p9, p10]


def fig11(study: Study, out: Path) -> list[Path]:
    plt = _plt()
    e = study.errors["skeleton"]
    pb = e["per_bin"]
    c = study.curves
    fig, ax = plt.subplots(1, 2, figsize=(12, 4))
    fig.subplots_adjust(wspace=0.45)
    a = np.geomspace(c.amplitude.min(), c.amplitude.max(), 300)
    kc, _ = virgin_closed_form(a)
    k16, _ = maxwell_slip_closed_form(study.params, a)
    ax[0].plot(c.amplitude, c.stiffness, "ko", ms=3, label="k_eq(A), composed")
    ax[0].plot(a, kc, "k-", lw=1, label="closed form, continuous")
    ax[0].plot(a, k16, "r--", lw=1, label="closed form, 16 elements")
    ax[0].set_xscale("log")
    ax[0].set_xlabel("displacement amplitude A (m)")
    ax[0].set_ylabel("equivalent stiffness (N/m)")
    tw = ax[0].twinx()
    tw.plot(a, virgin_curve(a, PAPER_H, PAPER_D), "b:", label="virgin curve")
    tw.set_ylabel("virgin curve (N)", color="b")
    ax[0].legend(fontsize=7, loc="center left")
    amp = pb["amplitude"]
    for key, style in (("k_16", "ro-"), ("k_continuous", "r^:"), ("E_16", "bo-"), ("E_continuous", "b^:")):
        ax[1].plot(amp, 100 * pb[key], style, ms=3, lw=0.8, label=key.replace("_", " vs "))
    ec = study.errors.get("skeleton_continuous")
    if ec is not None:
        ax[1].plot(ec["per_bin"]["amplitude"], 100 * ec["per_bin"]["E_continuous"], "gs-", ms=3, lw=0.8,
                   label=f"E vs continuous, {ec['elements']} elements")
    ax[1].axvspan(amp.min() * 0.8, e["delta_min"], color="0.85", label="dead-zone (A < smallest Delta)")
    ax[1].axvspan(amp.min() * 0.8, ENERGY_CHECK_FROM, color="0.93", zorder=-1)
    ax[1].axhspan(-100 * TOLERANCE, 100 * TOLERANCE, color="g", alpha=0.1)
    ax[1].set_ylim(-30, 30)
    ax[1].set_xscale("log")
    ax[1].set_xlabel("displacement amplitude A (m)")
    ax[1].set_ylabel("relative error (%)")
    ax[1].legend(fontsize=7)
    ax[1].grid(alpha=0.3, which="both")
    p11 = _save(fig, out / "fig11_stiffness_errors.png")
    # chirp ends: per-sample energy error along the G = 5 run
    r = _run(study, 5.0).result
    inst = r.instantaneous
    ok = np.isfinite(r.amplitude) & (r.amplitude > 0) & np.isfinite(r.h0)
    _, e16 = maxwell_slip_closed_form(study.params, np.where(ok, r.amplitude, 1.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.pi * r.damping_force * r.amplitude / e16 - 1
        rate = np.abs(inst.dA) * 2 * np.pi / (r.amplitude * np.abs(r.omega))
    t = r.t
    fig, ax = plt.subplots(figsize=(9, 4.3))
    ax.plot(t[ok & ~r.valid], 100 * err[ok & ~r.valid], ",", color="0.7", label="energy error: invalid (ends, COI)")
    ax.plot(t[r.valid], 100 * err[r.valid], ",", color="b", label="energy error: valid samples")
    ax.set_ylim(-50, 50)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("energy per cycle error vs 16-element closed form (%)", fontsize=8)
    tw = ax.twinx()
    tw.plot(t[r.valid], 100 * rate[r.valid], "r,", label="amplitude change per cycle (right axis)")
    tw.set_ylabel("|dA/dt|/(A*f): amplitude change per cycle (%)", color="r", fontsize=8)
    tw.set_ylim(0, 60)
    # below the axes: inside, it covered the samples it names
    handles = ax.get_legend_handles_labels()[0] + tw.get_legend_handles_labels()[0]
    fig.legend(handles, [h.get_label() for h in handles], loc="lower center", ncol=3, fontsize=8, markerscale=20,
               frameon=False)
    fig.subplots_adjust(bottom=0.25)
    ax.grid(alpha=0.3)
    ax.set_title("G = 5: error grows where the amplitude changes fast and at the ends of the chirp")
    return [p11, _save(fig, out / "fig11b_chirp_ends.png")]


def fig12(study: Study, out: Path) -> Path:
    plt = _plt()
    c = study.curves
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    a = np.geomspace(c.amplitude.min(), c.amplitude.max(), 300)
    v = np.linspace(0, c.velocity.max(), 300)
    ax[0].plot(c.amplitude, c.restoring_force, "ko", ms=3, label="composed")
    ax[0].plot(a, study.monotone.restoring_force(a), "g-", label="monotone fit k_eq(A)*A")
    if study.paper_fits:
        ax[0].plot(a, study.paper_fits[0](a), "m--", label="paper's form")
    fk = study.equivalent["describing"].restoring_table
    fd = study.equivalent["describing"].damping_table
    ax[0].plot(fk[0], fk[1], "b-", lw=1, label="equivalent F_k(x) (describing inversion)")
    ax[0].plot(a, describing_function(fk[0], fk[1], a), "b:", lw=1, label="its first harmonic")
    ax[0].set_xscale("log")
    ax[0].set_xlim(a.min(), a.max())
    ax[0].set_xlabel("displacement (amplitude) (m)")
    ax[0].set_ylabel("restoring force (N)")
    ax[1].plot(c.velocity, c.damping_force, "ko", ms=3, label="composed")
    ax[1].plot(v, study.monotone.damping_force(np.maximum(v, 1e-12)), "g-", label="monotone fit")
    if study.paper_fits:
        ax[1].plot(
            v,
            study.paper_fits[1](v),
            "m--",
            label=f"paper's form (dead-zone v0 = {study.paper_fits[1].params['v0']:.3g})",
        )
    ax[1].plot(fd[0], fd[1], "b-", lw=1, label="equivalent F_d(v)")
    ax[1].set_xlim(0, v.max())
    ax[1].set_xlabel("velocity (amplitude) (m/s)")
    ax[1].set_ylabel("damping force (N)")
    for x in ax:
        x.legend(fontsize=7)
        x.grid(alpha=0.3)
    return _save(fig, out / "fig12_fits.png")


# AFRF magnitudes more than this far below the largest first harmonic are numerical zeros (dB).
AFRF_FLOOR_DB = 200.0
# An even harmonic this far below the largest H1 everywhere in a panel is numerical noise (dB).
NOISE_BELOW_H1_DB = 100.0


def _afrf_grid(study: Study, path: Path, unit: str, orders=HARMONICS) -> Path:
    """One row per harmonic order, one column per system (original, Coulomb, equivalent). Points below
    the numerical floor (AFRF_FLOOR_DB under the largest H1) are not drawn; a panel with none above it says
    so in words instead of staying empty (a symmetric loop has no even harmonics: the Coulomb system's H2 is
    exactly zero)."""
    plt = _plt()
    names = ("original", "coulomb", "equivalent")
    force = "N" if unit == "m" else "N*m"
    fig, ax = plt.subplots(len(orders), 3, figsize=(13, 3 * len(orders) + 0.4), sharex=True, squeeze=False)
    cmap = plt.get_cmap("plasma")
    f = study.afrf_frequencies
    top = max(float(np.nanmax(study.afrf[name][i][:, 0])) for name in names for i in range(len(study.afrf_amplitudes)))
    floor = 20 * np.log10(max(top, 1e-300)) - AFRF_FLOOR_DB
    for j, name in enumerate(names):
        data = study.afrf[name]
        for hi in range(len(orders)):
            drawn, peak = 0, -np.inf
            for i, g in enumerate(study.afrf_amplitudes):
                y = 20 * np.log10(np.maximum(data[i][:, hi], 1e-300))
                y = np.where(y > floor, y, np.nan)
                drawn += int(np.isfinite(y).sum())
                peak = max(peak, float(np.nanmax(y, initial=-np.inf)))
                ax[hi, j].semilogx(f, y, color=cmap(0.9 * i / max(len(study.afrf_amplitudes) - 1, 1)), lw=1,
                                   label=f"G = {g:g} {force}" if hi == 0 and j == 0 else None)
            a = ax[hi, j]
            a.grid(alpha=0.3, which="both")
            a.set_ylabel(f"|H{orders[hi]}| (dB re 1 {unit})")
            if not drawn:
                a.set_ylim(floor - 10, floor + 90)
                a.text(0.5, 0.5, f"H{orders[hi]} = 0\n(more than {AFRF_FLOOR_DB:g} dB below the largest H1"
                       + (":\na symmetric loop has no even harmonics)" if orders[hi] % 2 == 0 else ")"),
                       transform=a.transAxes, ha="center", va="center", fontsize=9)
            elif orders[hi] % 2 == 0 and peak < floor + AFRF_FLOOR_DB - NOISE_BELOW_H1_DB:
                a.set_title(f"(> {NOISE_BELOW_H1_DB:g} dB below H1: numerical noise of a symmetric loop)", fontsize=8,
                            color="0.4")
        ax[0, j].set_title(name)
        ax[-1, j].set_xlabel("frequency (Hz)")
    handles, labels = ax[0, 0].get_legend_handles_labels()
    fig.tight_layout()
    fig.legend(handles, labels, title="drive amplitude", loc="upper center", bbox_to_anchor=(0.5, 0.0),
               ncol=len(labels), fontsize=8, frameon=False)  # below the panels; _save's tight bbox keeps it
    return _save(fig, path)


def fig15(study: Study, out: Path) -> Path:
    plt = _plt()
    c = study.curves
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    _by_run(ax[0], study, c.points_amplitude, c.points_restoring_force)
    ax[0].plot(c.amplitude, c.restoring_force, "ko", ms=3, label="composed")
    a = np.geomspace(c.amplitude.min(), c.amplitude.max(), 300)
    k16, _ = maxwell_slip_closed_form(study.params, a)
    ax[0].plot(a, k16 * a, "r--", lw=1, label="closed form (model)")
    ax[0].set_xscale("log")
    ax[0].set_xlabel("displacement amplitude (rad)")
    ax[0].set_ylabel("restoring torque (N*m)")
    _by_run(ax[1], study, c.points_velocity, c.points_damping_force)
    ax[1].plot(c.velocity, c.damping_force, "ko", ms=3, label="composed")
    ax[1].set_xscale("log")
    ax[1].set_xlabel("velocity amplitude (rad/s)")
    ax[1].set_ylabel("damping torque (N*m)")
    for x in ax:
        x.legend(fontsize=7)
        x.grid(alpha=0.3, which="both")
    return _save(fig, out / "fig15_motor_equivalent.png")


def write_figures(result: PaperResult, out: str | Path) -> list[Path]:
    """All figures into ``out`` (created); returns the paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    s, m = result.simulated, result.motor
    paths = [
        fig04(s, out),
        *fig05_06(s, out),
        fig07_08(s, out),
        *fig09_10(s, out),
        *fig11(s, out),
        fig12(s, out),
        _afrf_grid(s, out / "fig13_afrf.png", "m"),
        fig15(m, out),
        _afrf_grid(m, out / "fig16_motor_afrf.png", "rad", orders=(1,)),
    ]
    return paths


# --- summary ---------------------------------------------------------------------------------------------


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def summary_numbers(result: PaperResult) -> dict:
    """The key numbers (JSON-ready) and the pass/fail of each stated tolerance."""
    sk = result.simulated.errors["skeleton"]
    skc = result.simulated.errors["skeleton_continuous"]
    checks = {
        "k_eq within 5 % of the 16-element closed form (excited range above the dead-zone)": sk["max_k_16"]
        < TOLERANCE,
        "k_eq within 5 % of the continuous closed form": sk["max_k_continuous"] < TOLERANCE,
        f"E median within 5 % of the continuous closed form (A >= {ENERGY_CHECK_FROM} m)": sk[
            "median_E_continuous_checked"
        ]
        < TOLERANCE,
        f"E within 5 % of the 16-element closed form in every bin (A >= {ENERGY_CHECK_FROM} m)": sk[
            "max_E_16_checked"
        ]
        < TOLERANCE,
        f"{skc['elements']} elements: E within 5 % of the continuous closed form in every bin "
        f"(A >= {skc['checked_from']:g} m)": skc["max_E_continuous_checked"] < TOLERANCE,
        f"{skc['elements']} elements: k_eq within 5 % of the continuous closed form in every bin": skc[
            "max_k_continuous"
        ]
        < TOLERANCE,
        "motor k_eq within 10 % of its closed form (k_eq >= 2 % of sum k_i)": result.motor.errors[
            "motor_k_16_max"
        ]
        < 2 * TOLERANCE,
    }
    out = {
        "seconds": result.seconds,
        "skeleton": {k: v for k, v in sk.items() if k != "per_bin"},
        "skeleton_continuous": {k: v for k, v in skc.items() if k != "per_bin"},
        "skeleton_continuous_per_bin": {
            k: [None if not math.isfinite(x) else float(x) for x in v] for k, v in skc["per_bin"].items()
        },
        "skeleton_per_bin": {
            k: [None if not math.isfinite(x) else float(x) for x in v] for k, v in sk["per_bin"].items()
        },
        "motor_k_16_max": result.motor.errors["motor_k_16_max"],
        "motor_k_checked_range": result.motor.errors["motor_k_checked_range"],
        "checks": checks,
        "inferred": INFERRED,
    }
    for st, key in ((result.simulated, "afrf_simulated"), (result.motor, "afrf_motor")):
        out[key] = {name[5:]: rows for name, rows in st.errors.items() if name.startswith("afrf_")}
        out[key + "_frequencies_hz"] = [
            float(st.afrf_frequencies[0]),
            float(st.afrf_frequencies[-1]),
            int(st.afrf_frequencies.size),
        ]
        if st.paper_fits:
            out[key.replace("afrf", "fits")] = {
                "restoring": st.paper_fits[0].params,
                "damping": st.paper_fits[1].params,
            }
    return out


def _afrf_table(rows_by_model: dict, unit: str) -> list[str]:
    lines = [
        f"| amplitude ({unit}) | equivalent H1 / H2 / H3 (dB rms) | equivalent H1 median / max rel. "
        "| paper's direct form H1 / H2 / H3 (dB) | Coulomb H1 / H2 / H3 (dB) |",
        "|---|---|---|---|---|",
    ]
    eq, di, co = rows_by_model["equivalent"], rows_by_model["direct"], rows_by_model["coulomb"]
    for e, d, c in zip(eq, di, co, strict=True):

        def db(r):
            return " / ".join(f"{v:.2f}" for v in r["rms_db"])

        lines.append(
            f"| {e['amplitude']:g} | {db(e)} | {_pct(e['h1_median_rel'])} / {_pct(e['h1_max_rel'])} "
            f"| {db(d)} | {db(c)} |"
        )
    return lines


def write_summary(result: PaperResult, out: str | Path, figure_prefix: str = "") -> tuple[Path, Path]:
    """summary.md and summary.json into ``out``; figure links are ``figure_prefix + file name``."""
    out = Path(out)
    nums = summary_numbers(result)
    sk = nums["skeleton"]
    lines = [
        "# Reproducing Tjahjowidodo (2012) on the simulated bench",
        "",
        f"Run time: simulated system {result.seconds['simulated']:.1f} s, motor "
        f"{result.seconds['motor']:.1f} s.",
        "",
        "## Figures",
        "",
        "| ours | paper | content |",
        "|---|---|---|",
    ]
    for name, (paper, caption) in FIGURES.items():
        lines.append(f"| [{name}]({figure_prefix}{name}) | {paper} | {caption} |")
    lines += [
        "",
        "## Skeleton of the Maxwell-slip system against closed forms",
        "",
        f"Excited amplitude range {sk['excited_range'][0]:.3g} .. {sk['excited_range'][1]:.3g} m; "
        f"dead-zone below the smallest slip displacement {sk['delta_min']:.3g} m (no damping there: every "
        "element sticks). '16' = closed form of the simulated 16-element model, 'cont.' = continuous "
        "virgin curve (the two differ by the discretisation).",
        "",
        "| A band (m) | bins | k_eq max err 16 / cont. | E max err 16 / cont. | E median err 16 / cont. |",
        "|---|---|---|---|---|",
    ]
    for b in sk["bands"]:
        lines.append(
            f"| {b['band'][0]:g} .. {b['band'][1]:g} | {b['bins']} | {_pct(b['max_k_16'])} / "
            f"{_pct(b['max_k_continuous'])} | {_pct(b['max_E_16'])} / {_pct(b['max_E_continuous'])} | "
            f"{_pct(b['median_E_16'])} / {_pct(b['median_E_continuous'])} |"
        )
    skc = nums["skeleton_continuous"]
    lines += [
        "",
        f"The same chirps on the system with {skc['elements']} elements (within 0.6 % of the continuous virgin "
        "curve), so that the error left is the skeleton method's own, against the continuous closed forms. "
        f"Below {skc['checked_from']:g} m only quasi-static, uniformly growing samples of the two smallest "
        "chirps reach, where the loss factor is below 1e-3; below the smallest slip displacement lies the "
        "dead-zone.",
        "",
        "| A band (m) | bins | k_eq max err | E max err | E median err |",
        "|---|---|---|---|---|",
    ]
    for b in skc["bands"]:
        lines.append(
            f"| {b['band'][0]:g} .. {b['band'][1]:g} | {b['bins']} | {_pct(b['max_k_continuous'])} | "
            f"{_pct(b['max_E_continuous'])} | {_pct(b['median_E_continuous'])} |"
        )
    lines += ["", "Checks:", ""]
    lines += [f"- {'PASS' if ok else 'FAIL'}: {text}" for text, ok in nums["checks"].items()]
    lines += [
        "",
        f"Motor: k_eq within {_pct(nums['motor_k_16_max'])} of its closed form over "
        f"{nums['motor_k_checked_range'][0]:.3g} .. {nums['motor_k_checked_range'][1]:.3g} rad.",
        "",
        "## AFRF error against the original (Maxwell-slip) system",
        "",
        "One number per amplitude and harmonic: RMS over the frequency grid of 20*log10(|X_model| / "
        "|X_original|) (magnitudes floored at 1e-4 of the largest first harmonic). 'equivalent' is our "
        "describing-function inversion, 'direct' the paper's use of the skeleton curves as F_k(x), F_d(v).",
        "",
        f"Simulated system, no linear spring, {nums['afrf_simulated_frequencies_hz'][0]:g}-"
        f"{nums['afrf_simulated_frequencies_hz'][1]:g} Hz:",
        "",
    ]
    lines += _afrf_table(nums["afrf_simulated"], "N")
    lines += [
        "",
        f"DC motor model, {nums['afrf_motor_frequencies_hz'][0]:g}-"
        f"{nums['afrf_motor_frequencies_hz'][1]:g} Hz:",
        "",
    ]
    lines += _afrf_table(nums["afrf_motor"], "N*m")
    lines += ["", "## Inferred settings", ""] + [f"- **{k}**: {v}" for k, v in INFERRED.items()]
    md = out / "summary.md"
    md.write_text("\n".join(lines) + "\n")
    js = out / "summary.json"
    js.write_text(json.dumps(nums, indent=1, default=float))
    return md, js
