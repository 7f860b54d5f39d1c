"""A scripted measurement campaign with the Python API: identification at three seeds, then identify the
friction model on the first run and validate it on the others.

    python examples/scripted_campaign.py runs/scripted
"""

import sys
from pathlib import Path

from hilbench.analysis.identification.identify import identify
from hilbench.analysis.identification.maxwell_fit import LipSettings
from hilbench.analysis.record import load_record
from hilbench.bench.acquisition.protocols import Identification
from hilbench.bench.acquisition.runner import Bench
from hilbench.common.metrics import percent


def main(out: Path) -> None:
    files = []
    with Bench.open("sim://?pacing=lockstep") as bench:
        for seed in (1, 2, 3):
            result = bench.run(Identification(duration=10, amplitude=16.0, seed=seed), out / f"id-{seed}.h5",
                               operator="script", overwrite=True)
            print(result.status, result.path)
            files.append(result.path)
    train = load_record(files[0])  # the one loader: channel, torque timing and checks as the CLI reads them
    for path in files[1:]:
        fit = identify(train.arrays(), validate=load_record(path).arrays(), settings=LipSettings(timing=train.timing))
        m = fit.model
        print(f"{path.name}: inertia J = {m.inertia:.6g} kg*m^2, break-away torque {m.breakaway:.4f} N*m, "
              f"validation position NRMSE {percent(fit.figures['validation_position_nrmse']):.3g} %")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "runs/scripted"))
