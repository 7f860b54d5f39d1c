"""Per-run environment values in the campaign TOML: validated when loaded, carried into index.json, read by
``hilbench analyse`` into the ambient (degC) and load (kg) columns."""

import json

import pytest

from hilbench.bench.acquisition.campaign import CampaignError, load_campaign, run_campaign
from hilbench.bench.campaign_analysis.engine import AnalyseError, _environment

TOML = """
[defaults]
device = "sim://?pacing=lockstep"
sample_rate = 1000
current_limit = "8 A"
environment = {ambient = "23 C", load = "2 kg"}

[[run]]
name = "cold"
protocol = "identification"
amplitude = "4 A"
duration = "0.2 s"

[[run]]
name = "warm"
protocol = "identification"
amplitude = "4 A"
duration = "0.2 s"
environment = {ambient = "31.5 C", load = "2 kg"}
"""


def test_environment_is_validated_and_reaches_the_index(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(TOML)
    campaign = load_campaign(path)
    assert [r.environment for r in campaign.runs] == [{"ambient": "23 C", "load": "2 kg"},
                                                      {"ambient": "31.5 C", "load": "2 kg"}]
    entries = run_campaign(campaign, tmp_path / "out")
    index = {e["key"]: e for e in json.loads((tmp_path / "out" / "index.json").read_text())["runs"]}
    assert index["warm-1"]["environment"] == {"ambient": "31.5 C", "load": "2 kg"}
    assert {k: _environment(e, "x") for k, e in entries.items()} == {
        "cold-1": {"ambient": 23.0, "load": 2.0}, "warm-1": {"ambient": 31.5, "load": 2.0}}


def test_bad_environment_is_one_line_with_the_file_line(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(TOML.replace('environment = {ambient = "31.5 C", load = "2 kg"}', "environment = 5"))
    with pytest.raises(CampaignError, match=r"c\.toml:19: run 2: environment must be a table"):
        load_campaign(path)
    with pytest.raises(AnalyseError, match="environment ambient = '300 K' is not a number with unit C or degC"):
        _environment({"environment": {"ambient": "300 K"}}, "index.json: run a-1")
