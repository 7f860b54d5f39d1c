"""Every text shows an NRMSE in percent (docs/metrics.md): the campaign page renders a small synthetic result."""

import re

from hilbench.bench.campaign_analysis.page import campaign_page


def _rows():
    base = {"status": "ok", "name": "id1", "inertia": 2.0e-4, "breakaway": 0.05, "viscous": 4.0e-3,
            "verdict": "good"}
    return [{**base, "key": f"id1-r{i}", "repeat": i, "start_time": f"2026-11-28T0{i}:00:00+00:00",
             "validation_torque_nrmse": v} for i, v in enumerate((0.0215, 0.0231))]


def test_the_page_shows_the_validation_torque_nrmse_in_percent_never_as_a_fraction():
    units = {"inertia": "kg*m^2", "breakaway": "N*m", "viscous": "N*m*s/rad", "validation_torque_nrmse": "1"}
    text = campaign_page("c", _rows(), units, [], None)
    assert "validation torque NRMSE (%)" in text
    cells = re.findall(r"<td data-v='0\.02[0-9]+'>([^<]*)</td>", text)  # the sort key keeps the fraction
    assert cells == ["2.15", "2.31"]
    assert "0.0215</td>" not in text and "0.0231</td>" not in text
    mean = re.search(r"<td>(2\.23) &plusmn; (0\.11)</td>", text)  # mean and std over the two repeats, in %
    assert mean, "the repeat summary shows percent"
    for head in ("inertia J (kg*m^2)", "break-away torque (N*m)", "viscous coefficient b (N*m*s/rad)"):
        assert head in text


class _Result:
    """The smallest residual-loop result markdown_summary reads (its to_dict), with round figures."""

    def to_dict(self):
        err = {"torque_rel_pct": 1.283, "torque_nrmse": 0.01283, "position_nrmse": 0.25, "velocity_nrmse": None}
        return {"verdict": "adequate", "start": ["maxwell_slip"], "validation_mode": "the held-out 30 %",
                "record": "torque-driven", "error_before": {"train": err, "validation": err},
                "error_after": {"train": err, "validation": err}, "published_metric": None,
                "effects_added": [], "unexplained": [], "rounds": []}


def test_the_residual_summary_names_every_error_once_and_shows_percent():
    from hilbench.analysis.residual.report import markdown_summary

    text = markdown_summary(_Result())
    assert "| validation | torque NRMSE (%) | 1.283 | 1.283 |" in text
    assert "| validation | torque relative error (%) | 1.283 | 1.283 |" in text
    assert "| validation | position NRMSE (%) | 25 | 25 |" in text
    assert "0.01283" not in text and "torque_nrmse" not in text and "torque_rel_pct" not in text


def test_a_segmented_position_nrmse_is_shown_in_percent_on_the_campaign_page():
    """The page took only ``*_nrmse`` for a fraction, so ``validation_position_nrmse_segmented`` read 0.0314; every
    text now asks common.metrics.is_fraction."""
    from hilbench.bench.campaign_analysis.page import step_sections

    row = {"step": "identify", "status": "ok", "key": "a", "repeat": 1, "validation_position_nrmse_segmented": 0.0314}
    page = "".join(step_sections([row], {}))
    assert "validation position NRMSE segmented (%)" in page
    assert re.search(r"<td data-v='0\.0314'>3\.14</td>", page), page
