"""``hilbench identify`` end to end on run files written with hilbench.common.runfile (bench uses analysis)."""

import json
import re

import numpy as np

from hilbench.bench.cli import main
from hilbench.common.runfile import RunWriter
from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import simulate
from tests import real_data
from tests.analysis.identification.test_identification import random_enveloped
from tests.figure_checks import recording_figures


def _write_run(path, seed, channels=("sample_index", "t", "torque", "position")):
    fs, n = 2000.0, 20_000
    p = dc_motor().replace(counts_per_rev=2**20, seed=seed)
    out = simulate(p, random_enveloped(n, fs, seed, 6.0), 1 / fs)
    block = {
        "sample_index": np.arange(n),
        "t": np.arange(n) / fs,
        "torque": p.torque_constant * out.current_meas,
        "position": out.position_meas,
    }
    with RunWriter(path, sample_rate=fs, channels=channels) as w:
        w.append({k: block[k] for k in channels})
    return p


def test_identify_cli_writes_model_and_plots(tmp_path, capsys):
    p = _write_run(tmp_path / "a.h5", 1)
    _write_run(tmp_path / "b.h5", 2)
    with recording_figures() as seen:  # issue 13: every axis labelled with a unit, no empty legend
        rc = main(
            [
                "identify",
                str(tmp_path / "a.h5"),
                "--validate",
                str(tmp_path / "b.h5"),
                "--json",
                str(tmp_path / "m.json"),
                "--plots",
                str(tmp_path / "plots"),
            ]
        )
    assert rc == 0
    assert set(seen) == {"virgin_curve.png", *(f"{p}_{k}.png" for p in ("train", "validation")
                                               for k in ("fit", "residuals", "hysteresis"))}
    assert not any(seen.values()), seen
    doc = json.loads((tmp_path / "m.json").read_text())
    # 2 kHz undersamples the 187 Hz presliding mode a little: J within 2 % here (1 % at 4 kHz)
    assert abs(doc["parameters"]["inertia"] / p.inertia - 1) < 0.02
    assert doc["figures"]["validation_torque_nrmse"] < 0.05
    assert (tmp_path / "plots" / "virgin_curve.png").is_file()
    assert "validation torque NRMSE" in capsys.readouterr().out


def test_identify_cli_missing_torque_is_a_one_line_error(tmp_path, capsys):
    _write_run(tmp_path / "a.h5", 1, channels=("sample_index", "t", "position"))
    rc = main(["identify", str(tmp_path / "a.h5"), "--json", str(tmp_path / "m.json")])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert "no torque channel (torque or torque_cmd" in err and "\n" not in err


REAL_EMPS = real_data.EMPS  # ships in tests/data/emps: never skipped


def test_identify_imported_emps_with_and_without_maxwell_slip(tmp_path, capsys):
    # EMPS stores time in float32 (4e-5 of dt off a uniform grid); identification must accept it. The
    # reference model (J, Fc, b, offset: --thresholds 0) and the one with Maxwell-slip, trained on DATA_EMPS
    # and validated on DATA_EMPS_PULSES, are reported on the same data (measured validation torque NRMSE
    # 0.0457 and 0.0438: the elements help a little).
    runs = {}
    for name in ("DATA_EMPS", "DATA_EMPS_PULSES"):
        runs[name] = tmp_path / f"{name}.h5"
        assert main(["import", "emps", str(REAL_EMPS / f"{name}.mat"), "-o", str(runs[name])]) == 0
    figures = {}
    for n in (0, 64):
        out = tmp_path / f"m{n}.json"
        argv = ["identify", str(runs["DATA_EMPS"]), "--validate", str(runs["DATA_EMPS_PULSES"]), "--coulomb",
                "--offset", "--thresholds", str(n), "--json", str(out)]
        assert main(argv) == 0
        doc = json.loads(out.read_text())
        figures[n] = doc["figures"]
        assert (len(doc["parameters"]["ms_stiffness"]) == 0) == (n == 0)
        assert 90 < doc["parameters"]["inertia"] < 100  # the published M is 95.11 kg
    assert figures[64]["validation_torque_nrmse"] <= figures[0]["validation_torque_nrmse"] < 0.06


def test_identify_plots_name_their_runs_and_are_never_replaced_without_overwrite(tmp_path, capsys):
    # issue 28: `identify --plots DIR` silently replaced the plots in DIR, and the titles said only "train run"
    _write_run(tmp_path / "a.h5", 1)
    _write_run(tmp_path / "b.h5", 2)
    argv = ["identify", str(tmp_path / "a.h5"), "--validate", str(tmp_path / "b.h5"), "--json",
            str(tmp_path / "m.json"), "--plots", str(tmp_path / "plots"), "--thresholds", "16"]
    figures: dict = {}
    with recording_figures(figures):
        assert main(argv) == 0
    for name, fig in figures.items():  # every title of the figure, the figure's own and each panel's
        titles = " ".join([fig.get_suptitle(), *(ax.get_title() for ax in fig.axes)])
        run = "b.h5 (validation run)" if name.startswith("validation") else "a.h5 (train run)"
        assert run in titles, (name, titles)
    before = {p.name: p.read_bytes() for p in (tmp_path / "plots").iterdir()}
    assert len(before) == 7
    capsys.readouterr()
    # a new --json, the same --plots: refused in one line before any work, nothing replaced
    again = [*argv[:5], str(tmp_path / "m2.json"), *argv[6:]]
    assert main(again) == 2
    err = capsys.readouterr().err.strip()
    assert "virgin_curve.png exists; use --overwrite" in err and "--plots" in err and "\n" not in err
    assert {p.name: p.read_bytes() for p in (tmp_path / "plots").iterdir()} == before
    assert not (tmp_path / "m2.json").exists()
    # one plot of the validation run is enough to refuse
    for name in before:
        if name != "validation_hysteresis.png":
            (tmp_path / "plots" / name).unlink()
    assert main(again) == 2 and "validation_hysteresis.png exists" in capsys.readouterr().err
    assert main([*again, "--overwrite"]) == 0
    assert {p.name for p in (tmp_path / "plots").iterdir()} == set(before)


def test_the_hysteresis_legend_says_how_many_samples_a_dot_stands_for(tmp_path):
    # it read "model, every 2th sample"
    from hilbench.analysis.identification.plots import MAX_DOTS, hysteresis_figure

    n = 3 * MAX_DOTS
    t = np.arange(n) / 1000.0
    x = 1e-3 * np.sin(2 * np.pi * t)
    figures: dict = {}
    with recording_figures(figures) as seen:
        hysteresis_figure(x, np.tanh(x / 2e-4), [("model", np.tanh(x / 2.1e-4))], {"position": "rad",
                          "torque": "N*m"}, "id.h5 (train run): friction", tmp_path / "h.png", t=t)
    assert seen == {"h.png": []}, seen
    texts = [t.get_text() for leg in figures["h.png"].legends for t in leg.get_texts()]
    assert "model, one sample in 3" in texts, texts
    assert not any(re.search(r"\\d(th|nd|rd|st) sample", t) for t in texts), texts


def test_a_held_out_tail_gets_its_hysteresis_figure_on_the_scored_rows(tmp_path, monkeypatch):
    """``--hold-out`` scores the tail filtered together with the run before it: the validation hysteresis figure
    (it failed with 'hysteresis rows do not match the fit rows') shows the filtered position of the whole run at
    the scored rows, to 1e-12."""
    import h5py

    from hilbench.analysis.identification import plots
    from hilbench.analysis.identification.regressors import filtered_data

    _write_run(tmp_path / "a.h5", 1)
    shown: dict = {}
    original = plots.hysteresis_figure

    def spy(x, measured, models, units, title, path, t=None):
        shown[path.name] = (np.asarray(x), np.asarray(t))
        return original(x, measured, models, units, title, path, t=t)

    lips = []
    real_hysteresis = plots._identification_hysteresis

    def keep_lip(result, c, u, title, path):
        lips.append((result.lip, c))
        return real_hysteresis(result, c, u, title, path)

    monkeypatch.setattr(plots, "hysteresis_figure", spy)
    monkeypatch.setattr(plots, "_identification_hysteresis", keep_lip)
    assert main(["identify", str(tmp_path / "a.h5"), "--hold-out", "0.3", "--json", str(tmp_path / "m.json"),
                 "--plots", str(tmp_path / "plots"), "-q"]) == 0
    assert (tmp_path / "plots" / "validation_hysteresis.png").is_file()
    x, t = shown["validation_hysteresis.png"]
    with h5py.File(tmp_path / "a.h5", "r") as f:
        position = f["samples/position"][()]
    fs, (lip, c) = 2000.0, lips[-1]
    whole = filtered_data(position, np.zeros(position.size), fs, lip.cutoff, order=lip.settings.order,
                          decimation=lip.decimation, timing=lip.settings.timing)
    lead = c["lead_position"].size  # the samples before the tail
    assert lead == round(0.7 * position.size)
    rows = lead + np.round((t - c["t"][0]) * fs).astype(int)  # the scored rows, as indices into the whole run
    at = np.searchsorted(whole.rows, rows)
    assert t.size > 100
    np.testing.assert_array_equal(whole.rows[at], rows)
    np.testing.assert_allclose(x, whole.position[at], rtol=0, atol=1e-12)


def test_a_run_with_fewer_rows_than_unknowns_is_one_line_naming_the_option(tmp_path, capsys):
    """700 samples at 2 kHz leave 66 regression rows for 66 unknowns (64 thresholds, J, b): it was an IndexError
    from the triangular solve ("index 66 is out of bounds"); now one line naming --thresholds, exit 2, and fewer
    thresholds fit the same run."""
    fs, n = 2000.0, 700
    p = dc_motor().replace(counts_per_rev=2**20, seed=3)
    out = simulate(p, random_enveloped(n, fs, 3, 6.0), 1 / fs)
    with RunWriter(tmp_path / "s.h5", sample_rate=fs, channels=("sample_index", "t", "torque", "position")) as w:
        w.append({"sample_index": np.arange(n), "t": np.arange(n) / fs,
                  "torque": p.torque_constant * out.current_meas, "position": out.position_meas})
    assert main(["identify", str(tmp_path / "s.h5"), "--json", str(tmp_path / "m.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "66 rows for 66 unknowns" in err and "--thresholds" in err, err
    assert not (tmp_path / "m.json").exists()
    assert main(["identify", str(tmp_path / "s.h5"), "--json", str(tmp_path / "m.json"), "--thresholds", "16"]) == 0
