"""Series a planned campaign gives the drift monitor (issue #38): one run per protocol (a 4-run plan), a chirp
repeated bit for bit by a noise-free simulator (no spread), and runs of a linear axis, whose figures read N, kg and
m, not the rotary units of the Parquet field's `unit`."""

import numpy as np
import pytest

from hilbench.analysis.drift.monitor import DriftSettings, monitor
from hilbench.analysis.drift.plots import drift_figure, write_figures
from hilbench.analysis.errors import AnalysisError
from hilbench.bench.campaign_analysis.table import SCHEMA
from hilbench.common.units import AXES, field_unit, schema_units
from tests.analysis.drift.pools import campaign


def _chirps(n: int, ident: list[dict]) -> list[dict]:
    """n chirp rows with one value each (the same run every time), interleaved in time with ``ident``."""
    return [{**ident[i], "key": f"chirp-{i + 1}", "protocol": "chirp", "breakaway": 0.759, "viscous": 0.0042,
             "start_time": ident[i]["start_time"].replace(":00Z", ":30Z")} for i in range(n)]


def test_one_run_per_protocol_is_all_baseline_reported_and_not_charted():
    ident = campaign("flat", 1, np.random.default_rng(1))
    for r in ident:
        r["temperature_mean"] = None
    report = monitor(ident + _chirps(1, ident))  # the old code: "baseline of 1 runs: need 3 to 1", exit 2
    assert report.series == {}
    s = report.summary()
    assert s["alarms"] == [] and s["monitoring_from"] is None and s["runs"] == 2 and s["parameters"] == {}
    for g in s["groups"]:
        assert (g["runs"], g["baseline"]) == (1, 1)
        assert g["unmonitored"] == {f"{p} [{g['group']}]": "1 run: too few to chart (a baseline needs 3: 1 "
                                    "coefficient and a spread)" for p in ("breakaway", "viscous")}
        assert g["baseline_rule"].endswith("not charted: 1 run: too few to chart (a baseline needs 3: 1 coefficient "
                                           "and a spread)")
    with pytest.raises(AnalysisError, match="baseline of 2 runs: need 3 to 1"):  # a baseline asked for is checked
        monitor(ident, DriftSettings(baseline=2))


def test_a_series_without_spread_is_said_and_the_others_are_charted():
    ident = campaign("flat", 20, np.random.default_rng(2))
    for r in ident:
        r["temperature_mean"] = None
    chirps = _chirps(20, ident)
    report = monitor(ident + chirps)
    assert set(report.series) == {"breakaway [identification]", "viscous [identification]"}
    assert report.result_of("breakaway [identification]").axis == "rotary"
    g = {x["group"]: x for x in report.summary()["groups"]}["chirp"]
    assert g["unmonitored"]["breakaway [chirp]"] == ("no spread over the 10 baseline runs (identical values); 0 later "
                                                     "run(s) differ from them")
    chirps[15]["breakaway"] = 0.8  # one later run off a constant baseline: counted, not scored
    g = {x["group"]: x for x in monitor(ident + chirps).summary()["groups"]}["chirp"]
    assert g["unmonitored"]["breakaway [chirp]"].endswith("1 later run(s) differ from them")
    assert "viscous [chirp]" in g["unmonitored"]


def test_a_linear_axis_series_keeps_its_axis_and_its_figures_read_linear_units(tmp_path):
    rows = campaign("flat", 12, np.random.default_rng(3))
    for r in rows:
        r["temperature_mean"], r["axis"] = None, "linear"
    report = monitor(rows)
    (g,) = report.groups
    assert g.axis == "linear" and report.summary()["groups"][0]["axis"] == "linear"
    units = {axis: schema_units(SCHEMA, axis) for axis in AXES}
    assert units["linear"]["breakaway"] == "N" and units["rotary"]["breakaway"] == "N*m"
    fig = drift_figure(g, "breakaway", units["linear"]["breakaway"])
    labels = [(ax.get_xlabel(), ax.get_ylabel()) for ax in fig.axes if ax.get_visible()]
    assert labels[0][1] == "breakaway (N)" and labels[1] == ("cumulative sliding distance (m)", "breakaway (N)")
    saved = []
    write_figures(report, units, tmp_path, lambda f, p: saved.append([ax.get_ylabel() for ax in f.axes]))
    assert saved[0][0] == "breakaway (N)" and saved[2][0] == "viscous (N*s/m)"  # drift-breakaway, drift-viscous


def test_runs_of_both_axes_are_two_series_and_a_field_reads_its_axis_unit(tmp_path):
    rng = np.random.default_rng(4)
    rotary, linear = campaign("flat", 6, rng), campaign("flat", 6, rng)
    for r in linear:
        r["axis"], r["key"] = "linear", "l" + r["key"]
    report = monitor(rotary + linear, DriftSettings(parameters=("breakaway",), covariates=()))
    assert [(g.group, g.axis) for g in report.groups] == [("identification linear", "linear"),
                                                          ("identification rotary", "rotary")]
    names = write_figures(report, {axis: schema_units(SCHEMA, axis) for axis in AXES}, tmp_path, lambda f, p: None)
    # a series' figure is named cleanly (the label "breakaway [identification linear]" once gave "breakaway--...")
    assert sorted(p.name for p in names) == [f"{kind}-breakaway-identification-{axis}.png" for kind in
                                             ("charts", "drift") for axis in ("linear", "rotary")]
    meta = SCHEMA.field("viscous").metadata
    assert field_unit(meta, "linear") == "N*s/m" and field_unit(meta, "rotary") == "N*m*s/rad"
    assert field_unit(SCHEMA.field("duration").metadata, "linear") == "s" and field_unit(None) == ""
