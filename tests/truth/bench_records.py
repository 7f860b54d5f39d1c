"""Clean records of the default simulated bench (``sim://``, the dc_motor preset: inertia, 16 Maxwell-slip
elements and viscous friction, no injected effect) for the blind matrix, made by the CLI against the simulated
amplifier in lockstep (bit-identical to the real-time run, about 4x faster) and memoised on disk.

These come from the project's own plant, not from the independent generator: they check the rule "a clean record
adds nothing the start model does not lack, and ends without an unexplained verdict" on exactly the data of
issue 29 (``hilbench run identification`` on ``sim://``, whose residual showed a false line at 0.977 Hz).
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

_ROOT = Path(__file__).resolve().parents[2]
# the sources a bench record depends on: the plant, its preset, the simulated device and the protocols
_SOURCES = ("firmware_sim/engine/plant.c", "firmware_sim/engine/plant.py", "firmware_sim/engine/friction_models.py",
            "firmware_sim/devices/default_sim.toml", "firmware_sim/devices/device.py", "bench/acquisition/protocols.py")


@dataclass(frozen=True)
class BenchCase:
    """A protocol run twice on the clean simulated bench: train with ``train_args`` (seed s), validate with
    ``valid_args`` (seed s + 1000 where the protocol takes a seed)."""

    protocol: str
    train_args: tuple[str, ...]
    valid_args: tuple[str, ...]
    seeded: bool = True


def _source_hash() -> bytes:
    h = hashlib.sha256()
    for rel in _SOURCES:
        p = _ROOT / rel
        for f in sorted(p.rglob("*.py")) if p.is_dir() else [p]:
            if f.exists():
                h.update(f.read_bytes())
    return h.digest()


def bench_run(protocol: str, args: tuple[str, ...]) -> Path:
    """The run file of ``hilbench run PROTOCOL ARGS --device sim://?pacing=lockstep``, memoised on disk."""
    from hilbench.bench.cli import main
    from tests.truth.matrix import _cache_dir

    key = hashlib.sha256(repr((protocol, args)).encode() + _source_hash()).hexdigest()[:24]
    path = _cache_dir() / f"bench-{key}.h5"
    if path.exists():
        return path
    tmp = path.with_name(f"bench-{key}.{os.getpid()}.h5")
    rc = main(["run", protocol, *args, "--device", "sim://?pacing=lockstep", "--quiet", "--overwrite",
               "-o", str(tmp)])
    if rc != 0:
        raise RuntimeError(f"hilbench run {protocol} {' '.join(args)} failed (exit {rc})")
    tmp.replace(path)
    return path


def prepared_pair(case: BenchCase, seed: int):
    """(train, validation) prepared as ``hilbench residual`` prepares a run file (the one record loader, then
    prepare_run with the record's torque timing)."""
    from hilbench.analysis.record import load_record
    from hilbench.analysis.residual import prepare_run

    seed_args = (lambda s: ("--seed", str(s))) if case.seeded else (lambda s: ())
    runs = []
    for args, s in ((case.train_args, seed), (case.valid_args, seed + 1000)):
        path = bench_run(case.protocol, tuple(args) + seed_args(s))
        rec = load_record(path)
        runs.append(prepare_run(rec.position, rec.torque, rec.sample_rate, axis=rec.axis, name=str(path),
                                timing=rec.timing))
    return runs[0], runs[1]
