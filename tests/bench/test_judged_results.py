"""Issue 13 item 5 and issue 12 items 8 and 11 for the analysis commands: identify and residual agree on the
torque channel and the metric; every summary number has its unit; a poor fit gets a one-line verdict saying what
to try; bad numbers give one line and exit 2, bounded before allocation."""

import json
import re

import h5py
import numpy as np
import pytest

from hilbench.bench.cli import main
from hilbench.bench.verdict import judge
from hilbench.common.metrics import FAIR_TORQUE_PCT, GOOD_TORQUE_PCT
from hilbench.common.runfile import RunWriter
from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import simulate
from tests.analysis.identification.test_identification import random_enveloped
from tests.bench.test_paper_skeleton_commands import _write_chirp

FS, N = 2000.0, 16_000


def _write(path, seed=1, scale_cmd=1.0, amplitude=6.0, n=N):
    """A device-like run with both torque (measured) and torque_cmd (here a different, scaled signal)."""
    p = dc_motor().replace(counts_per_rev=2**20, seed=seed)
    u = random_enveloped(n, FS, seed, amplitude)
    out = simulate(p, u, 1 / FS)
    torque = p.torque_constant * out.current_meas
    with RunWriter(path, sample_rate=FS, channels=("sample_index", "t", "torque", "torque_cmd", "position")) as w:
        w.append({"sample_index": np.arange(n), "t": np.arange(n) / FS, "torque": torque,
                  "torque_cmd": scale_cmd * p.torque_constant * u, "position": out.position_meas})


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("judged")
    _write(d / "a.h5", 1, scale_cmd=3.0)
    _write(d / "b.h5", 2, scale_cmd=3.0)
    _write(d / "strong.h5", 4, amplitude=16.0, n=40_000)  # as the demo's identification run
    return d


def test_identify_and_residual_read_the_same_channel_and_report_the_same_metric(runs, capsys):
    assert main(["identify", str(runs / "a.h5"), "--validate", str(runs / "b.h5"), "--json",
                 str(runs / "m.json")]) == 0
    ident = capsys.readouterr().out
    assert main(["residual", str(runs / "a.h5"), "--validate", str(runs / "b.h5"), "--json", str(runs / "r.json"),
                 "--candidates", "viscous"]) == 0
    resid = capsys.readouterr().out
    model, report = json.loads((runs / "m.json").read_text()), json.loads((runs / "r.json").read_text())
    assert model["data"]["train"]["torque_channel"] == report["inputs"]["torque_channel"] == "torque"
    assert model["data"]["train"]["torque_timing"] == report["inputs"]["timing"] == "hold_previous"
    assert "on torque (hold_previous)" in ident and "on torque (hold_previous)" in resid
    # the same metric, by name and definition: rms(error)/std(measured) in %
    assert "validation torque NRMSE" in ident and "validation torque NRMSE" in resid
    i_pct = float(re.search(r"validation torque NRMSE ([\d.]+) %", ident).group(1))
    assert i_pct == pytest.approx(100 * model["figures"]["validation_torque_nrmse"], rel=5e-3)  # printed to 3 digits
    r_pct = float(re.search(r"validation torque NRMSE ([\d.]+) %", resid).group(1))
    assert r_pct == pytest.approx(100 * report["error_before"]["validation"]["torque_nrmse"], rel=5e-3)


def test_every_summary_number_has_a_unit(runs, capsys):
    assert main(["identify", str(runs / "a.h5"), "--json", str(runs / "m2.json"), "--coulomb"]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if " J = " in ln)
    for part in ("J = ", "break-away torque ", "b = ", "Fc = "):
        number = re.search(re.escape(part) + r"(-?[\d.e+-]+) (\S+)", line)
        assert number, (part, line)
        assert number.group(2).rstrip(",;") in ("kg*m^2", "N*m", "N*m*s/rad"), line
    assert re.search(r"train torque NRMSE [\d.]+ %, position NRMSE [\d.]+ %", line)


def test_a_poor_fit_gets_a_verdict_that_says_what_to_try(runs, capsys):
    # a friction-dominated motor fitted without friction elements (J and b only): measured 50-60 % NRMSE
    assert main(["identify", str(runs / "strong.h5"), "--thresholds", "0", "--json", str(runs / "j.json")]) == 0
    out = capsys.readouterr().out.splitlines()
    verdict = [ln for ln in out if ln.startswith("verdict:")]
    assert len(verdict) == 1 and verdict[0].startswith("verdict: poor torque fit") and "try:" in verdict[0]
    nrmse = json.loads((runs / "j.json").read_text())["figures"]["train_torque_nrmse"]
    assert 100 * nrmse > FAIR_TORQUE_PCT


def test_verdict_bands():
    assert judge(GOOD_TORQUE_PCT).startswith("verdict: good") and "try" not in judge(GOOD_TORQUE_PCT)
    assert judge(FAIR_TORQUE_PCT).startswith("verdict: fair") and "hilbench residual" in judge(FAIR_TORQUE_PCT)
    assert judge(FAIR_TORQUE_PCT + 1).startswith("verdict: poor")
    drift = judge(3.0, 205.0, 12.0)  # the position NRMSE of 2.05, which got no comment
    assert "drifts (position NRMSE 205 %, segmented 12 %)" in drift and "try:" in drift
    assert "no torque error" in judge(None)


def _poison(src, dst, channel, values):
    import shutil

    shutil.copy(src, dst)
    with h5py.File(dst, "r+") as f:
        g = f["samples"]
        attrs = dict(g[channel].attrs)
        del g[channel]
        ds = g.create_dataset(channel, data=values, maxshape=(None,), chunks=True)
        for k, v in attrs.items():
            ds.attrs[k] = v


@pytest.mark.parametrize("command", ["identify", "residual", "skeleton"])
def test_hostile_values_are_one_line_and_exit_2(runs, tmp_path, capsys, command):
    huge = tmp_path / "huge.h5"
    with h5py.File(runs / "a.h5", "r") as f:
        t = f["samples"]["torque"][...]
    _poison(runs / "a.h5", huge, "torque", t * 1e300)
    text = tmp_path / "text.h5"
    _poison(runs / "a.h5", text, "torque", np.array([b"abc"] * t.size))
    extra = ["--mass", "1"] if command == "skeleton" else ["--json", str(tmp_path / "o.json")]
    for path, expect in ((huge, "beyond the analysis bound"), (text, "holds strings, not numbers")):
        assert main([command, str(path), *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and expect in err and "'torque'" in err, err


@pytest.mark.parametrize("argv, expect", [
    (["identify", "{a}", "--json", "{o}", "--cutoff", "0"], "--cutoff 0 Hz: must lie in (0, 1000) Hz"),
    (["identify", "{a}", "--json", "{o}", "--cutoff", "5000"], "Nyquist"),
    (["residual", "{a}", "--json", "{o}", "--cutoff", "0"], "--cutoff 0 Hz"),
    (["identify", "{a}", "--json", "{o}", "--thresholds", "1e6"], "--thresholds 1000000: must lie in [0, 1024]"),
])
def test_bad_numbers_are_bounded_in_one_line(runs, tmp_path, capsys, argv, expect):
    args = [a.format(a=runs / "a.h5", o=tmp_path / "o.json") for a in argv]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and expect in err
    assert not (tmp_path / "o.json").exists()


def test_skeleton_bins_bounded_before_allocation(tmp_path, capsys):
    f = tmp_path / "c.h5"
    _write_chirp(f, 1.0, duration=20.0)
    assert main(["skeleton", str(f), "--mass", "1", "--bins", "1e9"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--bins 1000000000: must lie in [1, 10000]" in err


def test_skeleton_never_returns_a_negative_stiffness_silently(tmp_path, capsys):
    # the paper's system without its spring, and --spring subtracting one it does not have: k_eq < 0
    from hilbench.common.runfile import RunWriter as Writer
    from hilbench.firmware_sim.engine.friction_models import paper_system

    p = paper_system(spring=0.0)
    n = int(40 * 1000)
    t = np.arange(n) / 1000.0
    g = 0.5 * np.sin(np.pi * 0.05 * t**2)
    out = simulate(p, g, 1e-3, substeps=4)
    path = tmp_path / "free.h5"
    with Writer(path, sample_rate=1000.0, channels=("sample_index", "t", "torque", "position")) as w:
        w.append({"sample_index": np.arange(n), "t": t, "torque": np.insert(g[:-1], 0, 0.0), "position": out.theta})
    assert main(["skeleton", str(path), "--mass", "1", "--spring", "4", "--json", str(tmp_path / "s.json")]) == 0
    err = capsys.readouterr().err
    doc = json.loads((tmp_path / "s.json").read_text())
    assert min(doc["stiffness"]) < 0  # the case of the issue ...
    assert "warning: k_eq < 0 in" in err and doc["warnings"] and "spring subtracted (4 N*m/rad)" in doc["warnings"][0]
    assert main(["skeleton", str(path), "--mass", "1", "--spring", "50"]) == 2  # ... and with no bin positive
    assert "k_eq < 0 in every amplitude bin" in capsys.readouterr().err


def test_show_lists_a_string_typed_channel_without_a_traceback(runs, tmp_path, capsys):
    # #12 item 11: a string-typed channel made `show` end in a numpy traceback
    text = tmp_path / "text.h5"
    with h5py.File(runs / "a.h5", "r") as f:
        n = f["samples"]["torque"].shape[0]
    _poison(runs / "a.h5", text, "torque", np.array([b"abc"] * n))
    assert main(["show", str(text)]) == 0
    out = capsys.readouterr().out
    row = next(ln for ln in out.splitlines() if ln.strip().startswith("torque"))
    assert "not numeric: |S3" in row, row
    assert main(["show", str(text), "--json", "-"]) == 0
    rows = {c["name"]: c for c in json.loads(capsys.readouterr().out)["channels"]}
    assert rows["torque"]["not_numeric"] == "|S3" and rows["torque"]["mean"] is None
    assert rows["position"]["mean"] is not None
