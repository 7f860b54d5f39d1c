"""The analysis protocol's consistency for the two analyses of runs of their own: the compensation metrics of a
compensated run and the break-away probe. Each reaches every consumer it has through the registry: the Python API,
the CLI's JSON (``hilbench report``; for the compensation also the matrix report ``hilbench compensate`` and a
``[[compensate]]`` campaign write; for the probe ``analyse_probe``, which ``hilbench plan`` sizes from), the GUI's
result (its summary, and the table it shows to six digits), the campaign's Parquet row (the run's protocol picks
the step, ``steps_for``) and the campaign page's cell; each gives the same figure to 1e-6, and the figure is its
closed form (the rms and peak of reference - position) or near the simulated motor's sliding current.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hilbench.analysis import protocol
from hilbench.analysis.record import load_record
from hilbench.bench.acquisition.breakaway_probe import BreakawayProbe
from hilbench.bench.acquisition.compensation import CompensatedReference
from hilbench.bench.campaign_analysis.steps import steps_for
from hilbench.bench.cli import main
from hilbench.bench.gui.analyses import run_analysis
from hilbench.common.runfile import (
    CURRENT_CMD,
    POSITION_CMD,
    SAMPLE_INDEX,
    TIME,
    RunWriter,
)
from hilbench.firmware_sim.engine.friction_models import DC_MOTOR_BREAKAWAY, DC_MOTOR_TORQUE_CONSTANT, dc_motor
from hilbench.firmware_sim.engine.plant import simulate
from tests.analysis.consistency import CLOCK_IDS, CLOCKS, RTOL, campaign_row, clocked, one_run_campaign, page_cell

pytestmark = pytest.mark.device_free


#: the GUI's table shows six significant digits: within half a unit of the sixth
SHOWN = 5e-6


def _shown(result, column: str) -> float:
    """The number the GUI's result table shows for ``column`` (its text, as the operator reads it)."""
    (text,) = [value for quantity, value, _unit in result.numbers if quantity == column]
    return float(text)


def _report_json(name: str, run: Path, out: Path) -> dict:
    """The summary ``hilbench report NAME RUN --json`` writes."""
    assert main(["-q", "report", name, str(run), "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["analysis"] == name
    return doc["summary"]


def _compensated_run(path: Path, fs: float, host: bool) -> tuple[CompensatedReference, np.ndarray]:
    """A compensated run (sine reference at ``fs``, scored with a 0.02 s glitch window) whose position lags the
    reference by 3 samples plus a 7 Hz ripple of 10 µrad: the tracking error is known sample by sample; written as
    a device-clocked device or (``host``) a host-clocked drive writes it. Returns the protocol and that error."""
    proto = CompensatedReference(reference="sine", amplitudes=(1e-3, 1e-2), frequency=1.0, cycles=1, rest=0.1,
                                 window=0.02, sample_rate=int(fs))
    ref, fs = proto.reference_path, float(proto.sample_rate)
    k = np.arange(ref.n)
    position = np.concatenate([np.zeros(3), ref.position[:-3]]) + 1e-5 * np.sin(2 * np.pi * 7 * k / fs)
    zeros = np.zeros(ref.n)
    channels, data, kw = clocked(
        (SAMPLE_INDEX, TIME, CURRENT_CMD, "current", "torque", "position", "counts", POSITION_CMD),
        {SAMPLE_INDEX: k, TIME: k / fs, CURRENT_CMD: 0.3 * np.sin(k / 50), "current": zeros, "torque": zeros,
         "position": position, "counts": k * 0, POSITION_CMD: ref.position}, fs, host)
    with RunWriter(path, sample_rate=fs, protocol_name=proto.name, protocol_params=proto.parameters(),
                   channels=channels, **kw) as w:
        w.append(data)
    return proto, ref.position - position


@pytest.mark.parametrize(("rate", "host_clocked"), CLOCKS, ids=CLOCK_IDS)
def test_the_compensation_metrics_read_one_figure_everywhere(rate, host_clocked, tmp_path, capsys):
    """At 2, 10 and 20 kHz and as a host-clocked drive records it. No 70/30 split: the compensation metrics take
    no validation run (they score the run's own tracking against its own reference)."""
    from hilbench.bench.acquisition.compensation_matrix import MatrixSettings, measured_case, write_report

    folder = tmp_path / "c"
    folder.mkdir()
    run = folder / "m.sine.none-1.h5"
    proto, error = _compensated_run(run, rate, host_clocked)
    rec = load_record(run, channels=(CURRENT_CMD,))
    # the drive's last trigger came early (the jitter's seed), so its grid ends one sample short of the reference:
    # the entry scores the samples the grid holds (it once refused the run as not completed)
    assert rec.position.size == proto.reference_path.n - host_clocked
    if host_clocked:  # the closed form on the grid the loader resampled the drive's samples onto
        error = proto.reference_path.position[:rec.position.size] - rec.position
    one_run_campaign(folder, run.name, proto.name)
    assert steps_for(proto.name, tuple(protocol.ANALYSES)) == ["compensation"]
    comp = protocol.entry("compensation")
    summary = comp.report(comp.analyse(comp.read([run], protocol.ReadOptions())))[1]
    closed = {"rms_error_rad": float(np.sqrt(np.mean(error**2))), "max_error_rad": float(np.max(np.abs(error)))}
    for column, value in closed.items():  # the closed form: reference - position, sample by sample
        assert summary[column] == pytest.approx(value, rel=1e-12), column
    # the glitch: the peak |error| within the run's own 0.02 s after each reversal of the reference
    assert summary["glitch_window_s"] == 0.02
    window = round(0.02 * rate)
    peaks = [np.max(np.abs(error[k:k + window])) for k in summary["reversal_sample"]]
    assert summary["glitch_rad"] == pytest.approx(peaks, rel=1e-12)
    cli = _report_json("compensation", run, tmp_path / "r.json")
    # the matrix report `hilbench compensate --matrix` and a [[compensate]] campaign write from the played run
    write_report([measured_case(proto.case, run, MatrixSettings(window=0.02))], tmp_path / "matrix",
                 {"source": "test", "window_s": 0.02, "tolerance_rad": 1e-4})
    (matrix,) = json.loads((tmp_path / "matrix" / "compensation.json").read_text())["runs"]
    shown = run_analysis("compensation", run)
    row = campaign_row(folder, tmp_path / "row", "compensation", 0.3)
    checked = [c for c in comp.columns if isinstance(summary.get(c), float) and np.isfinite(summary[c])]
    assert {"rms_error_rad", "max_error_rad", "glitch_mean_rad", "glitch_max_rad", "effort_rms_a"} <= set(checked)
    for column in checked:
        value = summary[column]
        for where, got in (("report", cli[column]), ("matrix", matrix[column]), ("gui", shown.summary[column]),
                           ("row", row[column]), ("page", page_cell(row, column)[0])):
            assert got == pytest.approx(value, rel=RTOL), (column, where)
        assert _shown(shown, column) == pytest.approx(value, rel=SHOWN), column
    capsys.readouterr()


def _probe_run(path: Path, fs: float, host: bool) -> float:
    """A break-away probe (at ``fs``, 0.5 s ramps to twice the break-away current) played on the simulated DC
    motor's plant (8 Maxwell-slip elements) and written as the runner writes it, or (``host``) as a host-clocked
    drive writes it. Returns the motor's sliding current (sum W_i / K_t, A)."""
    kt = DC_MOTOR_TORQUE_CONSTANT
    probe = BreakawayProbe(peak=2 * DC_MOTOR_BREAKAWAY / kt, ramp_time=0.5, hold=0.2, sample_rate=int(fs))
    u, fs = probe.setpoints(), float(probe.sample_rate)
    out = simulate(dc_motor(8), u, 1 / fs)
    k = np.arange(u.size)
    channels, data, kw = clocked(
        (SAMPLE_INDEX, TIME, CURRENT_CMD, "current", "torque", "position", "counts"),
        {SAMPLE_INDEX: k, TIME: k / fs, CURRENT_CMD: u, "current": out.current_meas, "torque": out.torque,
         "position": out.theta, "counts": out.counts}, fs, host)
    with RunWriter(path, sample_rate=fs, protocol_name=probe.name, protocol_params=probe.parameters(),
                   protocol_arrays=probe.protocol_arrays(), channels=channels, **kw) as w:
        w.append(data)
    return DC_MOTOR_BREAKAWAY / kt


@pytest.mark.parametrize(("rate", "host_clocked"), CLOCKS, ids=CLOCK_IDS)
def test_the_breakaway_probe_reads_one_figure_everywhere(rate, host_clocked, tmp_path, capsys):
    """At 2, 10 and 20 kHz and as a host-clocked drive records it. No 70/30 split: the probe takes no validation
    run (its levels are read off the run's own ramps)."""
    from hilbench.bench.acquisition.breakaway_probe import analyse_probe

    folder = tmp_path / "c"
    folder.mkdir()
    run = folder / "probe-1.h5"
    level = _probe_run(run, rate, host_clocked)
    assert any(n.startswith("resampled on host_time") for n in load_record(run).notes) == host_clocked
    one_run_campaign(folder, run.name, BreakawayProbe.name)
    assert steps_for(BreakawayProbe.name, tuple(protocol.ANALYSES)) == ["breakaway"]
    probe = protocol.entry("breakaway")
    summary = probe.report(probe.analyse(probe.read([run], protocol.ReadOptions())))[1]
    # the motor: every element slips at sum W_i / K_t, the fitted sliding current within 3 % (as test_plan.py);
    # the slide shows (the velocity threshold) once most elements slip, at 80-100 % of it
    assert summary["sliding_positive"] == pytest.approx(level, rel=0.03)
    assert summary["sliding_negative"] == pytest.approx(-level, rel=0.03)
    assert 0.8 * level < summary["breakaway_positive_A"] <= level
    assert -level <= summary["breakaway_negative_A"] < -0.8 * level
    planned = analyse_probe(run).as_dict()  # what `hilbench plan` sizes its campaign from
    cli = _report_json("breakaway", run, tmp_path / "r.json")
    shown = run_analysis("breakaway", run)
    row = campaign_row(folder, tmp_path / "row", "breakaway", 0.3)
    for column in probe.columns:
        value = summary[column]
        for where, got in (("plan", planned[column]), ("report", cli[column]), ("gui", shown.summary[column]),
                           ("row", row[column]), ("page", page_cell(row, column)[0])):
            assert got == pytest.approx(value, rel=RTOL), (column, where)
        assert _shown(shown, column) == pytest.approx(value, rel=SHOWN), column
    capsys.readouterr()


def test_a_campaign_plays_probes_and_analyses_them_with_the_breakaway_step(tmp_path):
    """[[run]] protocol = "breakaway_probe" plans a probe (the break-away followed over a campaign), and the
    campaign's steps give its runs the breakaway step: the run's protocol is one the entry names."""
    from hilbench.bench.acquisition.campaign import load_campaign

    (tmp_path / "c.toml").write_text('[defaults]\ndevice = "sim://"\n\n[[run]]\nprotocol = "breakaway_probe"\n'
                                     'peak = "3 A"\nramp_time = "0.5 s"\nrepeats = 2\n')
    campaign = load_campaign(tmp_path / "c.toml")
    assert [r.key for r in campaign.runs] == ["breakaway_probe1-1", "breakaway_probe1-2"]
    assert all(r.protocol == BreakawayProbe(peak=3.0, ramp_time=0.5) for r in campaign.runs)
    assert steps_for(campaign.runs[0].protocol.name, ("identify", "breakaway")) == ["breakaway"]
