"""Identification speed and quality: the default NNLS method (``fit_lip``) against the paper's baseline
(differential evolution + Nelder-Mead on the simulation error, N = 16), on one simulated DC-motor
run of 100 000 samples with 64 candidate thresholds, validated on another seed. Under the execution
policy (analysis.execution: one BLAS thread), as every door runs it.

Targets (issue #37): fit_lip <= 0.3 s on an idle machine; <= 1.3x that with the other core busy (a
CPU-spinning process beside it, interleaved with the idle calls in the same run); >= 300x the paper's
method at a lower validation error. The default BLAS threads beside a busy core are measured too
(what the policy avoids; no target). Times are the least of the repeats (the machine is shared); the
CPU seconds of the idle fit are reported beside its wall time."""

from __future__ import annotations

import multiprocessing
import os
import time

import numpy as np
from scipy import signal
from threadpoolctl import threadpool_limits

from hilbench.analysis.execution import limited
from hilbench.analysis.identification.maxwell_fit import LipSettings, fit_lip
from hilbench.analysis.identification.output_error import simulation_error
from hilbench.analysis.identification.paper_baseline import fit_paper
from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import simulate


def _excitation(n: int, fs: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    r = signal.sosfilt(signal.butter(4, 40.0, fs=fs, output="sos"), rng.uniform(-1, 1, n))
    w = 2 * np.pi / 4.0
    t = np.arange(n) / fs
    env = 4 / np.pi * (np.sin(w * t) + np.sin(3 * w * t) / 3 + np.sin(5 * w * t) / 5)
    return 6.0 * env * r / np.max(np.abs(r))


def _run(seed: int, n: int, fs: float):
    p = dc_motor().replace(counts_per_rev=2**20, noise_current=0.02, seed=seed)
    out = simulate(p, _excitation(n, fs, seed), 1 / fs)
    return p.torque_constant * out.current_meas, out.position_meas


def _spin(busy, stop) -> None:
    """The busy core: a pure-Python loop while ``busy`` is set (checked every few ms), idle otherwise."""
    while not stop.is_set():
        if busy.wait(0.05):
            while busy.is_set():
                for _ in range(20_000):
                    pass


def _timed(fn) -> tuple[float, float]:
    """(wall s, CPU s of this process) of one call."""
    c0, t0 = time.process_time(), time.perf_counter()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def fit_times(fit, repeats: int) -> dict[str, float]:
    """Least wall times of ``fit()`` idle and with a CPU-spinning process beside it, calls interleaved (idle,
    busy, idle, ...) so that the machine's other load weighs on both alike; and the least CPU times of both (on a
    shared machine the wall times carry the other users' load too; the CPU times what the busy core itself costs
    the fit: caches, memory bandwidth, BLAS threads waiting for a core)."""
    ctx = multiprocessing.get_context("fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn")
    busy, stop = ctx.Event(), ctx.Event()
    spinner = ctx.Process(target=_spin, args=(busy, stop), daemon=True)
    spinner.start()
    idle, loaded, cpu, cpu_loaded = [], [], [], []
    try:
        for _ in range(repeats):
            wall, used = _timed(fit)
            idle.append(wall)
            cpu.append(used)
            busy.set()
            time.sleep(0.05)  # the spinner is running before the call starts
            wall, used = _timed(fit)
            loaded.append(wall)
            cpu_loaded.append(used)
            busy.clear()
    finally:
        stop.set()
        busy.clear()
        spinner.join(5)
        if spinner.is_alive():
            spinner.kill()
    return {"idle": min(idle), "busy": min(loaded), "cpu": min(cpu), "cpu_busy": min(cpu_loaded)}


def run(quick: bool = False) -> list[dict]:
    fs = 4000.0
    n = 20_000 if quick else 100_000
    tau, x = _run(1, n, fs)
    tau_v, x_v = _run(2, n, fs)
    settings = LipSettings(timing="hold_previous", n_thresholds=64)

    # steady-state speed: one untimed call loads scipy's modules and the C engine, then the least of the repeats
    # (the baseline's minute-long run is insensitive to both)
    repeats = 2 if quick else 7
    with limited():
        lip = fit_lip(x, tau, fs, settings=settings)
        times = fit_times(lambda: fit_lip(x, tau, fs, settings=settings), repeats)
    default_blas = None
    if not quick:  # seconds of a smoke run for a row without a target
        with threadpool_limits(limits=os.cpu_count() or 1):  # numpy's default: a BLAS thread per core
            default_blas = fit_times(lambda: fit_lip(x, tau, fs, settings=settings), 3)
    t_lip = times["idle"]
    nrmse_lip, _ = simulation_error(lip.model, x_v, tau_v, fs, timing="hold_previous")

    budget = (
        dict(maxiter=2, popsize=2, nm_maxfev=200) if quick else dict(maxiter=30, popsize=4, nm_maxfev=3000)
    )
    with limited():
        c0, t0 = time.process_time(), time.perf_counter()
        paper, _ = fit_paper(x, tau, fs, n_elements=16, timing="hold_previous", **budget)
        t_paper, cpu_paper = time.perf_counter() - t0, time.process_time() - c0
    nrmse_paper, _ = simulation_error(paper, x_v, tau_v, fs, timing="hold_previous")
    nmse_lip, nmse_paper = 100 * nrmse_lip**2, 100 * nrmse_paper**2
    speedup = t_paper / t_lip
    full = not quick
    rows = [
        {
            "name": f"identify_lip_wall_{n}_samples_64_thresholds",
            "value": t_lip,
            "unit": "s",
            "baseline_name": "paper DE+NM (N=16)",
            "baseline_value": t_paper,
            "ratio": t_lip / t_paper,
            "target": f"<= 0.3 s idle on 100000 samples (CPU {times['cpu']:.3f} s)",
            "ok": (t_lip <= 0.3) if full else None,
            "cpu_s": times["cpu"],
        },
        {
            "name": "identify_lip_wall_other_core_busy",
            "value": times["busy"],
            "unit": "s",
            "baseline_name": "fit_lip idle, same run",
            "baseline_value": t_lip,
            "ratio": times["busy"] / t_lip,
            "target": f"<= 1.3x idle (CPU time: {times['cpu_busy'] / times['cpu']:.2f}x)",
            "ok": (times["busy"] <= 1.3 * t_lip) if full else None,
        },
        {
            "name": "identify_speedup_vs_paper",
            "value": speedup,
            "unit": "x",
            "baseline_name": "paper DE+NM (N=16)",
            "baseline_value": 1.0,
            "ratio": speedup,
            "target": f">= 300x faster at lower validation NMSE (CPU time: {cpu_paper / times['cpu']:.0f}x)",
            "ok": (speedup >= 300 and nmse_lip < nmse_paper) if full else None,
            "cpu_ratio": cpu_paper / times["cpu"],
        },
        {
            "name": "identify_validation_position_nmse_lip",
            "value": nmse_lip,
            "unit": "%",
            "baseline_name": "paper DE+NM (N=16)",
            "baseline_value": nmse_paper,
            "ratio": nmse_lip / nmse_paper,
            "target": "< baseline",
            "ok": nmse_lip < nmse_paper,
        },
    ]
    if default_blas is not None:
        rows.insert(2, {
            "name": "identify_lip_default_blas_other_core_busy",
            "value": default_blas["busy"],
            "unit": "s",
            "baseline_name": "one BLAS thread, busy",
            "baseline_value": times["busy"],
            "ratio": default_blas["busy"] / times["busy"],
            "target": "report (what the execution policy avoids)",
            "ok": None,
        })
    return rows


if __name__ == "__main__":
    for row in run():
        print(row)
