"""``hilbench report NAME RUN``: any registered analysis by its entry; bad input is one line and exit 2, nothing
written. (Its figures against every other consumer: tests/analysis/test_protocol_tracking_probe.py.)"""

from __future__ import annotations

import json

import pytest

from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign
from hilbench.bench.cli import main

pytestmark = pytest.mark.device_free


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("report") / "c"
    write_campaign(folder, SyntheticCampaign(runs=1, duration=1.0, sample_rate=2000.0, seed=5))
    return folder / json.loads((folder / "index.json").read_text())["runs"][0]["file"]


def _one_line(capsys, argv) -> str:
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, (code, err)
    return err[0]


def test_bad_input_is_one_line_and_nothing_is_written(run, tmp_path, capsys):
    out = tmp_path / "s.json"
    assert "unknown analysis 'nothing' (available: identify, compare" in _one_line(
        capsys, ["report", "nothing", str(run), "--json", str(out)])
    assert "compare scores its models on a validation run" in _one_line(
        capsys, ["report", "compare", str(run), "--json", str(out)])
    assert "is an input of this command" in _one_line(capsys, ["report", "identify", str(run), "--json", str(run)])
    assert "not a break-away probe" in _one_line(capsys, ["report", "breakaway", str(run), "--json", str(out)])
    assert not out.exists()


def test_the_summary_shows_nrmse_in_percent_and_keeps_the_fraction_in_json(run, tmp_path, capsys):
    out = tmp_path / "s.json"
    assert main(["report", "identify", str(run), "--hold-out", "0.3", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    summary = json.loads(out.read_text())["summary"]
    for key in ("validation_torque_nrmse", "validation_position_nrmse_segmented"):
        value = summary[key]
        assert 0 < value < 1, key  # a fraction in the JSON, percent in the text
        head = key.replace("nrmse", "NRMSE").replace("_", " ") + ":"
        line = next(ln.strip() for ln in text.splitlines() if ln.strip().startswith(head))
        assert float(line.split(":")[1].split()[0]) == pytest.approx(100 * value, rel=5e-4) and line.endswith(" %")
    assert main(["report", "identify", str(run), "--json", str(out)]) == 2  # no --overwrite: refused
    assert "exists; use --overwrite" in capsys.readouterr().err
    assert main(["-q", "report", "identify", str(run), "-o", str(tmp_path / "files")]) == 0
    assert (tmp_path / "files" / "model.json").is_file()  # the entry's files
