"""Blind-matrix cases on records of the second independent generator (tests/foreign/generator.py, issue 39).

Scored as the first matrix (tests/truth/matrix.py, docs/residual-blind-matrix.md): right only if the set of terms
the loop adds equals the truth's, and a clean record (``clean-*``) also ends with nothing unexplained.

| case | record | truth | expected |
|---|---|---|---|
| clean-bw-stroke | torque-driven, Bouc-Wen, 2 rad stroke | nothing beyond presliding + Coulomb + viscous | nothing |
| clean-bw-tribometer | displacement-driven linear, Bouc-Wen, 100 reversals, split in halves | nothing | nothing |
| bw-tribometer-slope | the same, the level x (1 + 1000/m x) (+-30 % over the travel) | | preload_variation |
| bw-eccentric-0.3rev | train 0.3 rev, validate 0.6 rev | level x (1 + 0.25 sin(theta+phi)) | preload_variation |
| bw-eccentric-0.6rev | torque-driven, train over 0.6 rev, validate over 0.8 rev | the same | preload_variation |
| bw-delay | torque-driven, 2 rad stroke, a pure delay of 3 samples (3 ms) | delay | delay |
"""

from __future__ import annotations

import hashlib
import os
import pickle
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from tests.foreign.generator import BoucWen, Foreign, displacement_record, torque_record
from tests.truth.matrix import START, Outcome

TWO_PI = 2 * np.pi
TRIBOMETER = BoucWen(coulomb=40.0, delta=0.08e-3, viscous=0.0)

#: case -> (generator, keyword arguments of the training record, those of the validation record, expected terms)
CASES: dict[str, tuple] = {
    "clean-bw-stroke": ("torque", {"law": BoucWen(), "stroke": 2.0}, {"law": BoucWen(), "stroke": 2.0},
                        frozenset()),
    "clean-bw-tribometer": ("halves", {"law": TRIBOMETER}, None, frozenset()),
    "bw-tribometer-slope": ("halves", {"law": replace(TRIBOMETER, slope=1000.0)}, None,
                            frozenset({"preload_variation"})),
    "bw-eccentric-0.3rev": ("torque", {"law": BoucWen(eccentric=(0.25, 0.3)), "stroke": 0.3 * TWO_PI},
                            {"law": BoucWen(eccentric=(0.25, 0.3)), "stroke": 0.6 * TWO_PI},
                            frozenset({"preload_variation"})),
    "bw-eccentric-0.6rev": ("torque", {"law": BoucWen(eccentric=(0.25, 2.0)), "stroke": 0.6 * TWO_PI},
                            {"law": BoucWen(eccentric=(0.25, 2.0)), "stroke": 0.8 * TWO_PI},
                            frozenset({"preload_variation"})),
    "bw-delay": ("torque", {"law": BoucWen(), "stroke": 2.0, "delay": 3}, {"law": BoucWen(), "stroke": 2.0,
                                                                          "delay": 3}, frozenset({"delay"})),
}
SEEDS = (1, 2, 3)
#: the representative subset ``make test`` runs (one seed)
QUICK = ("clean-bw-tribometer", "bw-tribometer-slope", "bw-eccentric-0.3rev", "bw-delay")


def _cached(kind: str, seed: int, kw: dict) -> Foreign:
    """A record, memoised on disk (key: the arguments, the seed and the generator's source)."""
    src = Path(__file__).with_name("generator.py").read_bytes()
    key = hashlib.sha256(repr((kind, seed, sorted(kw.items()))).encode() + src).hexdigest()[:24]
    d = Path(os.environ.get("HILBENCH_TRUTH_CACHE", Path(tempfile.gettempdir()) / "hilbench-truth-cache"))
    d.mkdir(parents=True, exist_ok=True)
    path = d / f"foreign-{key}.pkl"
    if path.exists():
        try:
            return pickle.loads(path.read_bytes())
        except Exception:  # a damaged cache entry is regenerated
            pass
    rec = displacement_record(seed, **kw) if kind == "displacement" else torque_record(seed, **kw)
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_bytes(pickle.dumps(rec))
    tmp.replace(path)
    return rec


def runs(case: str, seed: int):
    """(training run, validation run, loop options) of a case."""
    from hilbench.analysis.residual import LoopOptions, prepare_run

    kind, kw_train, kw_valid, _ = CASES[case]
    if kind == "halves":
        rec = _cached("displacement", seed, kw_train)
        parts = [rec.half(0), rec.half(1)]
        timing, opts = "instant", LoopOptions(sim_window=None, record="displacement-driven")
    else:
        parts = [_cached("torque", seed, kw_train), _cached("torque", seed + 1000, kw_valid)]
        timing, opts = "hold_next", LoopOptions(sim_window=None)
    train, valid = (prepare_run(r.position, r.torque, r.fs, axis=r.axis, timing=timing, name=f"{case}-{i}")
                    for i, r in enumerate(parts))
    return train, valid, opts


def start(case: str) -> tuple:
    """The start model: the matrix's (inertia, Maxwell-slip, viscous) for torque-driven records; a
    displacement-driven record's force has no inertia, and the Bouc-Wen tribometer truth no viscous term."""
    return ("inertia", "maxwell_slip") if CASES[case][0] == "halves" else START


def run_case(case: str, seed: int) -> Outcome:
    from hilbench.analysis.residual import residual_loop

    train, valid, opts = runs(case, seed)
    t0 = time.perf_counter()
    res = residual_loop(train, valid, start=start(case), options=opts)
    dt = time.perf_counter() - t0
    alts = {e["name"]: tuple(e.get("indistinguishable_from", ())) for e in res.effects_added}
    return Outcome(case, seed, CASES[case][3], tuple(res.names_added), dt, res.verdict, alts,
                   tuple(u["diagnostic"] for u in res.unexplained))
