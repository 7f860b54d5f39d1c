"""The main job end to end on the simulated bench (``hilbench demo``).

1. Start the simulated amplifier with an effect the demo does **not** declare to the analysis
   (cogging, in the simulator's private config; it never crosses the wire).
2. Run an identification run, a validation run (another seed) and a stepped-sine AFRF run, and list
   the run files.
3. The paper's mass-spring-friction system under its chirp: hysteresis and response figure.
4. Analysis steps on the logged runs, each added as it exists: identification, AFRF of the measured
   run, and the residual loop that finds the undeclared effect.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from urllib.parse import quote

import numpy as np

HIDDEN_SIM_CONFIG = """\
# Simulated bench for `hilbench demo`. The [plant] section is private to the simulator: the host and the
# analysis never see it. The demo's cogging below is the "undeclared effect" the residual loop must find.
[device]
model = "HB-SIM-1"
serial = "SIM-DEMO"

[plant]
preset = "dc_motor"
noise_current = 0.01
seed = 11
velocity_kp = 0.5
velocity_ki = 20.0

[[plant.cogging]]
order = 6
amplitude = 0.04
phase = 0.3
"""


def _say(msg: str) -> None:
    from hilbench.bench.storage.outputs import say

    say(msg)


def measure(out: Path, duration: float = 20.0) -> dict[str, Path]:
    """Steps 1-2: the runs on the simulated bench. Returns the run files by role."""
    from hilbench.bench.acquisition.protocols import Identification, SteppedSine
    from hilbench.bench.acquisition.runner import Bench

    runs = out / "runs"
    runs.mkdir(parents=True, exist_ok=True)
    config = out / "sim-hidden.toml"
    config.write_text(HIDDEN_SIM_CONFIG)
    plan = {
        # 2 kHz: above the presliding resonance (about 190 Hz) and where the residual loop is validated
        "identification": Identification(duration=duration, amplitude=16.0, period=4.0, seed=1, sample_rate=2000),
        "validation": Identification(duration=duration, amplitude=16.0, period=4.0, seed=2, sample_rate=2000),
        "afrf": SteppedSine(frequencies=(2.0, 5.0, 10.0, 20.0), amplitudes=(2.0, 5.0, 8.0), settle_periods=10,
                            measure_periods=10),
    }
    files = {}
    _say(f"[1] simulated bench: sim://?pacing=lockstep&config={config.name} (plant effects kept private)")
    # the path is percent-encoded: a folder named 'a+b' or 'a&b' must not change the URL's meaning
    with Bench.open(f"sim://?pacing=lockstep&config={quote(str(config), safe='/')}") as bench:
        ident = bench.identity()
        _say(f"    device {ident.get('model')} serial {ident.get('serial')}, firmware {ident.get('firmware')}")
        for role, protocol in plan.items():
            path = runs / f"{role}.h5"
            result = bench.run(protocol, path, operator="demo", overwrite=True,
                               notes=f"hilbench demo: {role}")
            _say(f"[2] {role:<15} {protocol.name:<15} {result.status:<10} {result.samples:>8} samples")
            files[role] = path
    _say("    run files:")
    for path in sorted(runs.glob("*.h5")):
        _say(f"      {path}  {os.path.getsize(path) / 1e6:.2f} MB")
    return files


def paper_figure(out: Path) -> Path:
    """Step 3: the paper's system under the chirp F = 5 sin(0.1 pi t^2)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hilbench.analysis.models.simulation import paper_system, simulate_chirp
    from hilbench.bench.storage.outputs import save_figure

    params = paper_system()
    run = simulate_chirp(params, 5.0)
    x, f_fr = run.out.theta, run.out.friction
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    axes[0].plot(x, f_fr, lw=0.6)
    axes[0].set(xlabel="displacement x (m)", ylabel="friction force (N)",
                title=f"Maxwell-slip hysteresis, N={params.n_elements}, chirp G=5 N")
    axes[1].plot(run.t, run.force, lw=0.5, label="force F (N)")
    axes[1].plot(run.t, x * params.spring, lw=0.8, label="k*x (N)")
    axes[1].set(xlabel="time t (s)", ylabel="force (N)", title="response to F = G sin(0.1 pi t^2)")
    axes[1].legend(loc="upper left")
    fig.tight_layout()
    path = out / "paper_chirp_hysteresis.png"
    save_figure(fig, path, dpi=120)
    plt.close(fig)
    _say(f"[3] paper system (m=1 kg, k=50 N/m, h=1.64 N, d=0.656 m, N=16), chirp G=5 N: peak x "
         f"{np.max(np.abs(x)):.3f} m, peak friction {np.max(np.abs(f_fr)):.3f} N -> {path}")
    return path


def _cli(*argv: str) -> None:
    from hilbench.bench.cli import main
    from hilbench.bench.storage import outputs

    level = {0: ["-q"], 2: ["-v"]}.get(outputs.verbosity, [])  # the demo's -q/-v reach its steps
    rc = main([*level, *(str(a) for a in argv)])
    if rc != 0:
        raise RuntimeError(f"bench {' '.join(map(str, argv))} exited {rc}")


def identify_step(files: dict[str, Path], out: Path) -> None:
    _cli("identify", files["identification"], "--validate", files["validation"], "--json", out / "model.json",
         "--plots", out / "identification", "--overwrite")  # run_demo has refused a used folder already
    _say("  (position NRMSE: the whole-record open-loop simulation integrates every torque error and the hidden "
         "cogging into drift; 'segmented' restarts it every second from the measured state, docs/model-file.md)")


def afrf_step(files: dict[str, Path], out: Path) -> None:
    _cli("afrf", files["afrf"], "--json", out / "afrf.json", "--plot", out / "afrf.png", "--overwrite")


def residual_step(files: dict[str, Path], out: Path) -> None:
    _cli("residual", files["identification"], "--validate", files["validation"], "--json", out / "residual.json",
         "--report", out / "residual", "--overwrite")
    import json

    doc = json.loads((out / "residual.json").read_text())
    for effect in doc["effects_added"]:
        scalars = {k: round(v, 6) for k, v in effect["parameters"].items() if isinstance(v, float)}
        _say(f"    added {effect['name']}: {scalars}")
    _say("    (the simulator's private config holds cogging order 6, 0.04 N*m, phase 0.3 rad; the dc_motor preset "
         "has viscous 0.004 N*m*s/rad, which the start model inertia,maxwell_slip lacks)")


def analysis_steps() -> list[tuple[str, Callable[[dict[str, Path], Path], None]]]:
    """Step 4: the analysis steps, in order."""
    return [("identification: Maxwell-slip + inertia + viscous, validated on the other seed", identify_step),
            ("AFRF (1st-3rd harmonic) of the measured stepped-sine run", afrf_step),
            ("residual loop from inertia,maxwell_slip: what does the model lack?", residual_step)]


#: What a demo leaves in its folder: another demo's files are replaced only with --overwrite.
DEMO_OUTPUTS = ("runs", "model.json", "afrf.json", "residual.json", "paper_chirp_hysteresis.png")


def run_demo(out: Path, duration: float = 20.0, overwrite: bool = False) -> int:
    from hilbench.bench.errors import BenchError

    present = [name for name in DEMO_OUTPUTS if (out / name).exists()]
    if present and not overwrite:
        raise BenchError(f"{out} holds {', '.join(present)} of a demo already; use --overwrite or another --output")
    out.mkdir(parents=True, exist_ok=True)
    files = measure(out, duration)
    paper_figure(out)
    for name, step in analysis_steps():
        _say(f"[4] {name}")
        step(files, out)
    _say(f"done: everything is in {out}/")
    return 0
