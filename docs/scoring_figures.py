"""Each door's validation figures of the Maxwell-slip model on the same runs (docs/metrics.md, "Scoring held-out
data"): ``hilbench identify``'s, ``compare``'s maxwell_slip row, ``residual``'s start, and the campaign steps' rows.

    cd REPO && OPENBLAS_NUM_THREADS=1 .venv/bin/python docs/scoring_figures.py
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.analysis... (the runs' excitation)

from hilbench.analysis.identification import analyse as identify  # noqa: E402
from hilbench.analysis.models.compare import CompareSettings  # noqa: E402
from hilbench.analysis.models.compare import analyse as compare  # noqa: E402
from hilbench.analysis.record import load_record  # noqa: E402
from hilbench.analysis.record_split import split  # noqa: E402
from hilbench.analysis.residual import ResidualSettings  # noqa: E402
from hilbench.analysis.residual import analyse as residual  # noqa: E402
from hilbench.bench.campaign_analysis.steps import StepSettings, step  # noqa: E402
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign  # noqa: E402
from hilbench.common.runfile import RunWriter  # noqa: E402
from hilbench.firmware_sim.engine.friction_models import dc_motor  # noqa: E402
from hilbench.firmware_sim.engine.plant import simulate  # noqa: E402
from tests.analysis.identification.test_identification import random_enveloped  # noqa: E402


def pct(v: float) -> str:
    return f"{100 * v:.4f} %"


def run(folder: Path, fs: float, seed: int, seconds: float = 3.0) -> Path:
    """A 3 s DC-motor run (viscous 0.01 N*m*s/rad, 2^20 counts/rev, measured current) as a run file."""
    p = dc_motor().replace(viscous=0.01, counts_per_rev=2**20, seed=seed)
    n = int(seconds * fs)
    out = simulate(p, random_enveloped(n, fs, seed, 6.0), 1 / fs)
    path = folder / f"{int(fs)}_{seed}.h5"
    with RunWriter(path, sample_rate=fs, channels=("sample_index", "t", "torque", "position")) as w:
        w.append({"sample_index": np.arange(n), "t": np.arange(n) / fs,
                  "torque": p.torque_constant * out.current_meas, "position": out.position_meas})
    return path


def doors(folder: Path) -> None:
    for fs in (2000.0, 10000.0, 20000.0):
        a, b = run(folder, fs, 1), run(folder, fs, 2)
        for layout in ("70/30 split", "two runs"):
            tr, va = split(load_record(a), 0.3) if layout != "two runs" else (load_record(a), load_record(b))
            i = identify(tr, validation=va).figures
            r = compare(tr, va, CompareSettings(families=("maxwell_slip",))).rows[0].validation
            st = residual(tr, ResidualSettings(start=("maxwell_slip",), candidates=("offset",)), validation=[va])
            start = st.start_model["figures"]["validation_torque_nrmse"]
            print(f"{fs:>7.0f} Hz {layout:11s} | validation torque NRMSE: "
                  f"identify {pct(i['validation_torque_nrmse'])}, "
                  f"compare {pct(r['torque_nrmse'])}, residual start {pct(start)}"
                  f" | segmented position NRMSE: identify {pct(i['validation_position_nrmse_segmented'])}, "
                  f"compare {pct(r['position_nrmse_segmented'])}", flush=True)


def steps(folder: Path) -> None:
    for fs in (2000.0, 10000.0):
        d = folder / f"campaign_{int(fs)}"
        write_campaign(d, SyntheticCampaign(runs=1, duration=8.0, seed=5, sample_rate=fs))
        path = str(sorted(d.rglob("*.h5"))[0])
        s = StepSettings(compare_families=("maxwell_slip",))
        i, c, r = step("identify")(path, s), step("compare")(path, s), step("residual")(path, s)
        print(f"campaign steps at {fs:.0f} Hz | validation torque NRMSE: identify {pct(i['validation_torque_nrmse'])}, "
              f"compare maxwell_slip {pct(c['validation_torque_nrmse'])}, residual start "
              f"{pct(r['validation_torque_nrmse_start'])} ({r['model']})", flush=True)


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as tmp:
        doors(Path(tmp))
        steps(Path(tmp))
