"""Residual loop on the real data sets: EMPS (train DATA_EMPS, validate DATA_EMPS_PULSES) and HSM150.

    .venv/bin/python examples/residual_emps.py [OUT_DIR]

EMPS ships with the repository (tests/data/emps/, Janot, Gautier and Brunot 2019; from an installed wheel:
$HILBENCH_REAL_DATA/emps/); HSM150 is read from $HILBENCH_REAL_DATA/hsm150/. Each is left out, with a note, when
it is not found.

EMPS starts from the benchmark's reference model (mass, Coulomb, viscous, offset) and uses the IDIM-LS
filter band (cutoff 40 Hz ~ the decimate anti-alias band, decimation 10). HSM150 trains on repeats 1 and 2
of all four step files (both directions) and validates on repeat 3, with the commanded torque.
"""

from __future__ import annotations

import glob
import os
import sys
from pathlib import Path

import numpy as np
from scipy.io import loadmat

from hilbench.analysis.reproductions.emps import PUBLISHED, fit_idim, idim_observation, load_emps
from hilbench.analysis.residual import EMPS_START, prepare_run, residual_loop
from hilbench.analysis.residual.report import write_json, write_report

#: EMPS in a source tree; copied out of an installed wheel (`hilbench examples`) the script has no tests/ beside it
#: and reads $HILBENCH_REAL_DATA/emps/ instead, as HSM150
EMPS = Path(__file__).resolve().parent.parent / "tests" / "data" / "emps"


def emps_folder() -> Path | None:
    """The folder holding DATA_EMPS.mat: the source tree's, else $HILBENCH_REAL_DATA/emps (None: neither)."""
    root = os.environ.get("HILBENCH_REAL_DATA")
    for folder in (EMPS, Path(root) / "emps" if root else None):
        if folder is not None and (folder / "DATA_EMPS.mat").is_file():
            return folder
    return None


def emps(out: Path) -> None:
    folder = emps_folder()
    if folder is None:
        print("EMPS: skipped (not in a source tree: set HILBENCH_REAL_DATA to the folder holding emps/DATA_EMPS.mat)")
        return
    a, b = load_emps(folder / "DATA_EMPS.mat"), load_emps(folder / "DATA_EMPS_PULSES.mat")
    fs = 1.0 / (a.t[1] - a.t[0])
    kw = {"axis": "linear", "cutoff": 40.0, "decimation": 10}
    result = residual_loop(prepare_run(a.qm, a.force, fs, name="DATA_EMPS", **kw),
                           prepare_run(b.qm, b.force, fs, name="DATA_EMPS_PULSES", **kw), start=EMPS_START)
    idim = fit_idim(*idim_observation(a.t, a.qm, a.force))
    w, y = idim_observation(b.t, b.qm, b.force)
    idim_test = 100 * np.linalg.norm(y - w @ idim.params) / np.linalg.norm(y)
    notes = [f"published IDIM-LS force relative error: {PUBLISHED['relative_error_train']} % (DATA_EMPS), "
             f"{PUBLISHED['relative_error_test']} % (PULSES); IDIM-LS reproduced here: {idim.relative_error:.2f} % / "
             f"{idim_test:.2f} %. The loop's torque_rel_pct uses the bench's filter (40 Hz, rows at rest "
             "projected), so compare before/after within the loop."]
    write_json(result, out / "emps.json")
    write_report(result, out / "emps", title="EMPS residual loop", notes=notes)
    print("EMPS:", result.verdict)
    for part in ("train", "validation"):
        print(f"  {part}: torque_rel_pct {result.error_before[part]['torque_rel_pct']:.2f} % -> "
              f"{result.error_after[part]['torque_rel_pct']:.2f} %")
    print("  " + notes[0])
    for e in result.effects_added:
        p = {k: round(v, 4) for k, v in e["parameters"].items() if isinstance(v, float)}
        print(f"  + {e['name']} ({e['physics']}): {p}")
    for u in result.unexplained:
        print(f"  ? {u['description']}")


def hsm150(out: Path) -> None:
    root = os.environ.get("HILBENCH_REAL_DATA")
    files = sorted(glob.glob(os.path.join(root, "hsm150", "idf_*.mat"))) if root else []
    if not files:
        print("HSM150: skipped (set HILBENCH_REAL_DATA to the folder holding hsm150/idf_*.mat)")
        return
    runs = []
    for f in files:
        d = loadmat(f)["data"]
        runs.append(prepare_run(d[:, 2], d[:, 4], 1000.0, name=Path(f).stem, cutoff=50.0))
    train = [r for r in runs if not r.name.endswith("_3")]
    valid = [r for r in runs if r.name.endswith("_3")]
    result = residual_loop(train, valid)
    write_json(result, out / "hsm150.json")
    write_report(result, out / "hsm150", title="HSM150 residual loop")
    print("HSM150:", result.verdict)
    print(f"  validation torque_rel_pct {result.error_before['validation']['torque_rel_pct']:.2f} % -> "
          f"{result.error_after['validation']['torque_rel_pct']:.2f} %")
    for e in result.effects_added:
        p = {k: float(f"{v:.4g}") for k, v in e["parameters"].items() if isinstance(v, float)}
        print(f"  + {e['name']} ({e['physics']}): {p}")
    for u in result.unexplained:
        print(f"  ? {u['description']}")


if __name__ == "__main__":
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "residual_reports")
    out.mkdir(parents=True, exist_ok=True)
    emps(out)
    hsm150(out)
