"""``hilbench skeleton`` on run files of the paper's system under chirps (written with hilbench.common.runfile)."""

import json

import numpy as np
import pytest

from hilbench.analysis.reproductions.paper import maxwell_slip_closed_form
from hilbench.bench.cli import main
from hilbench.common.runfile import RunWriter
from hilbench.firmware_sim.engine.friction_models import paper_system
from hilbench.firmware_sim.engine.plant import simulate

pytestmark = pytest.mark.device_free  # starts no device: runs in make test's parallel part

FS = 1000.0


def _write_chirp(path, g, a=0.05, duration=40.0):
    p = paper_system()
    n = int(duration * FS)
    t = np.arange(n) / FS
    out = simulate(p, g * np.sin(np.pi * a * t**2), 1 / FS, substeps=4)
    # a device logs the torque as the mean over [t_k-1, t_k); here the held command, i.e. hold_next timing
    # shifted by one sample = hold_previous
    torque = np.insert(g * np.sin(np.pi * a * t[:-1] ** 2), 0, 0.0)
    with RunWriter(
        path,
        sample_rate=FS,
        channels=("sample_index", "t", "torque", "position"),
        calibration={"inertia": p.inertia},
    ) as w:
        w.append({"sample_index": np.arange(n), "t": t, "torque": torque, "position": out.theta})
    return p


def test_skeleton_cli_composes_runs(tmp_path, capsys):
    files = [tmp_path / f"g{g}.h5" for g in (0.5, 5.0, 20.0)]
    for f, g in zip(files, (0.5, 5.0, 20.0), strict=True):
        p = _write_chirp(f, g)
    rc = main(
        [
            "skeleton",
            *map(str, files),
            "--spring",
            "50",
            "--json",
            str(tmp_path / "s.json"),
            "--plot",
            str(tmp_path / "s.png"),
        ]
    )
    assert rc == 0
    doc = json.loads((tmp_path / "s.json").read_text())
    a = np.array(doc["amplitude"])
    assert doc["mass"] == 1.0 and doc["units"]["stiffness"] == "N*m/rad"
    assert a.min() < 0.02 and a.max() > 3.0
    # k_eq against the 16-element closed form: 5 % (as the paper reproduction; measured < 2 %)
    k16, e16 = maxwell_slip_closed_form(p, a)
    np.testing.assert_array_less(np.abs(np.array(doc["stiffness"]) / k16 - 1), 0.05)
    # energy where it matters (A >= 0.1): median within 5 % (three runs only: a sparse composition)
    m = a >= 0.1
    assert np.median(np.abs(np.array(doc["energy"])[m] / e16[m] - 1)) < 0.05
    assert (tmp_path / "s.png").stat().st_size > 10_000


def test_skeleton_cli_errors(tmp_path, capsys):
    assert main(["skeleton", str(tmp_path / "missing.h5")]) == 2
    assert "no such run file" in capsys.readouterr().err
    f = tmp_path / "a.h5"
    _write_chirp(f, 1.0, duration=20.0)
    assert main(["skeleton", str(f), "--mass", "-1"]) == 2
    assert "--mass" in capsys.readouterr().err


@pytest.mark.parametrize(
    "timing, expect",
    [("hold_previous", [1.5, 2.5, 3.0]), ("hold_next", [1.0, 1.5, 2.5]), ("instant", [1.0, 2.0, 3.0])],
)
def test_centred_force(timing, expect):
    from hilbench.analysis.skeleton import centred_force

    np.testing.assert_allclose(centred_force(np.array([1.0, 2.0, 3.0]), timing), expect)


def test_the_gui_skeleton_warns_on_a_run_that_is_no_chirp(tmp_path):
    """Issue 28: the browser's skeleton of an identification run said "done" with F_k down to -2e4 N*m; it now
    carries the warning the CLI prints (the same chirp data filed under the chirp protocol has none)."""
    from hilbench.bench.gui.analyses import run_analysis
    from tests.analysis.skeleton.test_skeleton_stream import _write_chirp as write

    for protocol in ("identification", "chirp"):
        path = tmp_path / f"{protocol}.h5"
        write(path, paper_system(), 5.0, duration=20.0, protocol=protocol)
        shown = run_analysis("skeleton", path, {"inertia": 1.0})
        assert bool(shown.warnings) == (protocol != "chirp"), shown.warnings
        assert all("not a chirp" in w for w in shown.warnings)
    # one reading: the browser's skeleton is the command's (same call, same defaults, same curves)
    assert main(["skeleton", str(path), "--mass", "1.0", "--json", str(tmp_path / "s.json"), "-q"]) == 0
    doc = json.loads((tmp_path / "s.json").read_text())
    numbers = {q: v for q, v, _u in shown.numbers}
    k_med = float(numbers["median k_eq"])
    assert k_med == pytest.approx(float(np.median(doc["stiffness"])), rel=1e-5)  # shown to 6 digits
    assert shown.figures[0].curves[0][1].tolist() == pytest.approx(doc["amplitude"], rel=1e-12)
