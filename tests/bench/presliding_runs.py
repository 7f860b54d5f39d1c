"""A presliding run on the simulated bench and its analysis, as the tests that need one make it.

The simulated device is paced in lockstep: the device owns the sample clock, so its samples are bit for bit
those of a realtime run (checked on a 46 500-sample run), computed as fast as the link allows instead of
in 18 s of wall time."""

from __future__ import annotations

import json
from pathlib import Path

from hilbench.bench.cli import main

#: the simulated DC-motor bench with 10 mA current noise (examples/presliding_sim.toml)
SIM_CONFIG = Path(__file__).resolve().parents[2] / "examples" / "presliding_sim.toml"


def run_and_analyse(tmp_path: Path, counts_per_rev: int, *run_args: str, replicates: int = 2) -> tuple[Path, dict]:
    """``hilbench run presliding`` (``run_args`` added) at ``counts_per_rev``, then ``hilbench presliding``:
    (the run file, the presliding.json document)."""
    h5, out = tmp_path / "p.h5", tmp_path / "out"
    assert main(["run", "presliding", *run_args, "--counts-per-rev", str(counts_per_rev),
                 "--device", f"sim://?pacing=lockstep&config={SIM_CONFIG}", "-o", str(h5), "--quiet"]) == 0
    assert main(["presliding", str(h5), "-o", str(out), "--replicates", str(replicates)]) == 0
    return h5, json.loads((out / "presliding.json").read_text())
