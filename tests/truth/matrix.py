"""The strict blind matrix of the residual loop on records from the independent truth generator.

A case is a true system (``generator.Truth``) and the set of library terms that describe its effects
(the map in docs/residual-blind-matrix.md). The loop starts from ``START`` = inertia + Maxwell-slip +
viscous (every family has presliding, Coulomb-like and viscous friction), trains on one record and
validates on another (seed + 1000), and is right only if the set it adds equals the expected set.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from tests.truth.bench_records import BenchCase, prepared_pair
from tests.truth.generator import Record, Truth, simulate_torque_driven

START = ("inertia", "maxwell_slip", "viscous")
DURATION = 10.0  # s per record (train and validation each)
FS = 1000.0

# which library term describes which truth effect (documented in docs/residual-blind-matrix.md)
EFFECT_MAP = {
    "stribeck": "stribeck",  # any exponent, any family's own Stribeck curve
    "asymmetry": "asymmetric_friction",
    "angle_level": "position_dependent_friction",  # the record covers the level's period
    "preload": "preload_variation",  # a level varying over a period longer than the stroke, or along the travel
    "cogging": "position_periodic",  # non-sinusoidal profile: a fundamental and its 2nd harmonic
    "current_lag": "delay",  # a first-order lag, not a pure delay
    "offset": "offset",
    "drift": "offset_drift",  # a drifting load includes its constant part
    "belt": None,  # no library term: the right answer is to add nothing
    "backlash": None,
}

_BELT = (26.0, 0.028, 0.0011)  # k_b N*m/rad, c_b N*m*s/rad, J_l kg*m^2: resonance near 30 Hz, 10 % damping


def _t(family: str = "maxwell", **kw) -> Truth:
    return Truth(family=family, **kw)


CASES: dict[str, tuple[Truth, frozenset]] = {}


def _case(name: str, truth: Truth, *effects: str) -> None:
    CASES[name] = (truth, frozenset(e for e in (EFFECT_MAP[x] for x in effects) if e))


for fam in ("maxwell", "lugre", "dahl", "gms"):
    _case(f"clean-{fam}", _t(fam))
_case("stribeck-lugre", _t("lugre", stribeck_excess=0.3, stribeck_velocity=2.0), "stribeck")
_case("stribeck-exp1", _t("maxwell", stribeck_excess=0.3, stribeck_velocity=3.0, stribeck_exponent=1.0),
      "stribeck")
_case("stribeck-exp4-gms", _t("gms", stribeck_excess=0.3, stribeck_velocity=2.0, stribeck_exponent=4.0),
      "stribeck")
_case("angle-level", _t("maxwell", angle_level=(5.0, 0.2, 0.7)), "angle_level")
_case("cogging", _t("maxwell", cogging=(9.0, 0.06, 1.1)), "cogging")
_case("current-lag", _t("maxwell", current_lag=0.003), "current_lag")
_case("asymmetry", _t("lugre", asymmetry=0.15), "asymmetry")
_case("offset", _t("maxwell", offset=0.1), "offset")
_case("drift", _t("maxwell", offset=0.05, drift=0.015), "drift")
_case("belt", _t("maxwell", belt=_BELT), "belt")
_case("backlash", _t("maxwell", belt=_BELT, backlash=0.002), "belt", "backlash")
_case("stribeck+cogging", _t("lugre", stribeck_excess=0.3, stribeck_velocity=2.0, cogging=(9.0, 0.06, 0.3)),
      "stribeck", "cogging")
_case("angle-level+lag", _t("maxwell", angle_level=(7.0, 0.2, 2.0), current_lag=0.003), "angle_level",
      "current_lag")
_case("cogging+lag", _t("dahl", cogging=(6.0, 0.06, 0.0), current_lag=0.002), "cogging", "current_lag")
_case("asymmetry+cogging", _t("maxwell", asymmetry=0.15, cogging=(11.0, 0.06, 2.0)), "asymmetry", "cogging")
_case("stribeck+lag", _t("gms", stribeck_excess=0.3, stribeck_velocity=2.0, current_lag=0.003), "stribeck",
      "current_lag")
_case("angle-level+cogging", _t("lugre", angle_level=(4.0, 0.2, 0.0), cogging=(10.0, 0.06, 1.0)), "angle_level",
      "cogging")

# clean records of the default simulated bench (tests/truth/bench_records.py): the plant is inertia + Maxwell-slip
# + viscous, exactly START's structure, so the right answer is to add nothing and leave nothing unexplained
BENCH_CASES = {
    "bench-identification": BenchCase("identification", ("--duration", "20"), ("--duration", "20")),
    "bench-identification-1k": BenchCase("identification", ("--duration", "20", "--sample-rate", "1000"),
                                         ("--duration", "20", "--sample-rate", "1000")),
    "bench-chirp": BenchCase("chirp", ("--duration", "20", "--gain", "6", "--sweep", "linear"),
                             ("--duration", "20", "--gain", "6", "--sweep", "log", "--f-start", "0.3"), seeded=False),
}
for _name in BENCH_CASES:
    CASES[_name] = (None, frozenset())

# issue 29: a friction level whose period exceeds the stroke (an eccentric preload once per revolution seen over
# 0.5-5 rad) or that changes along a linear axis' travel; a position loop keeps the motor within the stroke. An
# 18-bit encoder: with the 20000-count one the loop's own clean-data error on these slow closed-loop records was
# 15-19 % (0.8 % at 2^18 counts; the quantised low-speed rows, see docs/residual-blind-matrix.md)
_ENC = 2**18
_case("eccentric-stroke0.5", _t("maxwell", angle_level=(1.0, 0.25, 0.3), stroke=0.5, counts_per_rev=_ENC), "preload")
_case("eccentric-stroke2", _t("lugre", angle_level=(1.0, 0.25, 1.2), stroke=2.0, counts_per_rev=_ENC), "preload")
_case("eccentric-stroke5", _t("maxwell", angle_level=(1.0, 0.25, 2.0), stroke=5.0, counts_per_rev=_ENC), "preload")
_case("preload-linear", _t("maxwell", level_slope=0.2, stroke=2.0, axis="linear", counts_per_rev=_ENC), "preload")
_case("preload-linear-gms", _t("gms", level_slope=0.2, stroke=2.0, axis="linear", counts_per_rev=_ENC), "preload")
_case("clean-stroke1", _t("maxwell", stroke=1.0, counts_per_rev=_ENC))
_case("clean-stroke4-dahl", _t("dahl", stroke=4.0, counts_per_rev=_ENC))

SEEDS = (1, 2, 3)
#: the representative subset run by ``make test`` (one seed; the whole matrix is benchmarks/bench_residual.py)
QUICK = ("clean-dahl", "stribeck-exp1", "angle-level", "current-lag", "stribeck+cogging", "bench-identification")


def is_clean(case: str) -> bool:
    """Clean data: a friction family the start model describes, no effect (clean-*, bench-*)."""
    return case.startswith(("clean-", "bench-"))


def _cache_dir() -> Path:
    d = Path(os.environ.get("HILBENCH_TRUTH_CACHE", Path(tempfile.gettempdir()) / "hilbench-truth-cache"))
    d.mkdir(parents=True, exist_ok=True)
    return d


def record(truth: Truth, seed: int, duration: float = DURATION, fs: float = FS) -> Record:
    """A torque-driven record, memoised on disk (the integration takes seconds; the key is the truth,
    the seed, the duration, the rate and the generator's source)."""
    src = Path(__file__).with_name("generator.py").read_bytes()
    key = hashlib.sha256(repr((truth, seed, duration, fs)).encode() + src).hexdigest()[:24]
    path = _cache_dir() / f"{key}.pkl"
    if path.exists():
        try:
            return pickle.loads(path.read_bytes())
        except Exception:  # a damaged cache entry is regenerated
            pass
    rec = simulate_torque_driven(truth, seed, duration, fs)
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_bytes(pickle.dumps(rec))
    tmp.replace(path)
    return rec


def prepared(rec: Record, name: str):
    from hilbench.analysis.residual import prepare_run

    return prepare_run(rec.position, rec.torque, rec.fs, name=name, timing="instant", axis=rec.truth.axis)


@dataclass
class Outcome:
    case: str
    seed: int
    expected: frozenset
    added: tuple
    seconds: float  # the loop's wall time (the records are generated beforehand)
    verdict: str
    alternatives: dict = None  # added term -> the terms the loop declared it indistinguishable from
    unexplained: tuple = ()  # diagnostics still significant at the end

    @property
    def clean(self) -> bool:
        """A record without any effect beyond the start model (issue 29: it must also end explained)."""
        return is_clean(self.case)

    @property
    def right(self) -> bool:
        return frozenset(self.added) == self.expected and not (self.clean and self.unexplained)

    @property
    def declared(self) -> bool:
        """Wrong, but every wrong term was declared indistinguishable from a missed truth term, one for one (the
        loop said it could not tell them apart on these data). Counted apart from right, never as right."""
        if self.right:
            return False
        extra = [a for a in self.added if a not in self.expected]
        missed = set(self.expected) - set(self.added)
        if not extra:  # nothing wrongly added (a clean run wrong only by its unexplained verdict): nothing declared
            return False
        alts = self.alternatives or {}
        named = {m for a in extra for m in alts.get(a, ()) if m in missed}
        return len(extra) == len(missed) and named == missed and all(
            set(alts.get(a, ())) & missed for a in extra)


def run_case(case: str, seed: int, options=None) -> Outcome:
    from hilbench.analysis.residual import LoopOptions, residual_loop

    truth, expected = CASES[case]
    if case in BENCH_CASES:
        train, valid = prepared_pair(BENCH_CASES[case], seed)
    else:
        train = prepared(record(truth, seed), f"{case}-{seed}")
        valid = prepared(record(truth, seed + 1000), f"{case}-{seed + 1000}")
    t0 = time.perf_counter()
    res = residual_loop(train, valid, start=START, options=options or LoopOptions(sim_window=None))
    dt = time.perf_counter() - t0
    alts = {e["name"]: tuple(e.get("indistinguishable_from", ())) for e in res.effects_added}
    return Outcome(case, seed, expected, tuple(res.names_added), dt, res.verdict, alts,
                   tuple(u["diagnostic"] for u in res.unexplained))
