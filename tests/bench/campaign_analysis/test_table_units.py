"""The results table's units follow the run's axis (hilbench.common.units), not a fixed rotary set."""

from hilbench.bench.campaign_analysis.page import campaign_page
from hilbench.bench.campaign_analysis.table import SCHEMA, column_units, to_table
from hilbench.common.units import AXIS_UNITS


def test_an_axis_quantity_column_carries_both_units_and_says_what_it_follows():
    meta = SCHEMA.field("inertia").metadata
    assert meta == {b"unit": b"kg*m^2", b"unit_linear": b"kg", b"unit_follows": b"axis"}
    assert SCHEMA.field("initial_stiffness").metadata[b"unit_linear"] == b"N/m"
    assert SCHEMA.field("validation_torque_nrmse").metadata == {b"unit": b"1"}  # a fraction on every axis
    assert SCHEMA.field("duration").metadata == {b"unit": b"s"}


def test_column_units_on_each_axis_come_from_the_common_units():
    for axis, u in AXIS_UNITS.items():
        units = column_units(axis)
        assert units["inertia"] == u["inertia"] and units["breakaway"] == u["torque"]
        assert units["viscous"] == u["viscous"] and units["afrf_compliance_low_amplitude"] == u["compliance"]
        assert units["sliding_distance"] == u["position"] and units["duration"] == "s"


def test_a_linear_run_row_keeps_its_axis_and_its_page_shows_linear_units():
    row = {"campaign": "c", "key": "r1", "axis": "linear", "status": "ok", "name": "r1", "inertia": 2.1,
           "breakaway": 20.0, "viscous": 200.0, "validation_torque_nrmse": 0.03}
    assert to_table([row]).to_pylist()[0]["axis"] == "linear"
    text = campaign_page("c", [row], column_units("linear"), [], None, "linear")
    assert "inertia J (kg)" in text and "viscous coefficient b (N*s/m)" in text and "kg*m^2" not in text
    assert "break-away force (N)" in text and "break-away torque" not in text


def test_each_campaign_page_shows_the_units_given_for_its_runs_axis(tmp_path):
    """write_pages takes the units by axis (the table's metadata, schema_units) and shows the page of a campaign
    the units of its runs' axis, those given and no other (it once overwrote them with the code's own)."""
    from hilbench.bench.campaign_analysis.page import write_pages
    from hilbench.common.units import AXES, schema_units

    base = {"key": "r1", "status": "ok", "name": "r1", "inertia": 2.1, "breakaway": 20.0, "viscous": 200.0}
    rows = [{**base, "campaign": "lin", "axis": "linear"}, {**base, "campaign": "rot", "axis": None}]
    units = {axis: schema_units(SCHEMA, axis) for axis in AXES}
    units["linear"] = {**units["linear"], "breakaway": "kN"}  # a unit only the given dictionary has
    pages = write_pages(rows, units, [], None, tmp_path)
    assert [p.name for p in pages] == ["campaign-lin.html", "campaign-rot.html"]
    lin, rot = (p.read_text() for p in pages)
    assert "break-away force (kN)" in lin and "viscous coefficient b (N*s/m)" in lin and "(N*m)" not in lin
    assert "break-away torque (N*m)" in rot and "viscous coefficient b (N*m*s/rad)" in rot and "(N)" not in rot


def test_drift_of_a_linear_axis_campaign_speaks_in_linear_units(tmp_path, monkeypatch, capsys):
    """`hilbench drift` on rows of a linear axis: its lines and figures read N, N*s/m and m (the columns'
    `unit_linear`), not the rotary units of the field's `unit` (issue #38)."""
    import numpy as np
    import pyarrow.parquet as pq

    from hilbench.bench.cli import main
    from hilbench.bench.storage import outputs
    from tests.analysis.drift.pools import campaign

    rows = [{**r, "axis": "linear", "step": "identify"} for r in campaign("warm", 12, np.random.default_rng(6))]
    pq.write_table(to_table(rows), tmp_path / "results.parquet")
    labels: dict[str, list[str]] = {}
    save = outputs.save_figure

    def keep_labels(fig, path):
        labels[path.name] = [t for ax in fig.axes if ax.get_visible() for t in (ax.get_xlabel(), ax.get_ylabel())]
        return save(fig, path)

    monkeypatch.setattr(outputs, "save_figure", keep_labels)
    assert main(["drift", str(tmp_path)]) == 0
    said = capsys.readouterr().out
    assert "breakaway: temperature " in said and " N/K (" in said and "N*m" not in said
    assert "viscous: temperature " in said and " N*s/m/K (" in said
    assert "breakaway (N)" in labels["drift-breakaway.png"] and "cumulative sliding distance (m)" in labels[
        "drift-breakaway.png"]
    assert "viscous (N*s/m)" in labels["drift-viscous.png"]
    assert not any("rad" in t or "N*m" in t for ts in labels.values() for t in ts)
