"""Every analysis command refuses an aborted run in one line naming the reason; with --allow-incomplete it runs
and its report says the record is incomplete (docs/record.md)."""

import json

import numpy as np
import pytest

from hilbench.bench.cli import main
from hilbench.common.runfile import RunWriter
from hilbench.firmware_sim.engine.friction_models import dc_motor
from hilbench.firmware_sim.engine.plant import simulate
from tests.analysis.identification.test_identification import random_enveloped
from tests.bench.test_identify_command import _write_run


def _aborted(path, seed=3, fs=2000.0, n=12_000, planned=40_000):
    """An identification run stopped by the operator after n of its planned samples."""
    p = dc_motor().replace(counts_per_rev=2**20, seed=seed)
    out = simulate(p, random_enveloped(n, fs, seed, 6.0), 1 / fs)
    with RunWriter(path, sample_rate=fs, protocol_name="identification",
                   protocol_arrays={"setpoints": np.zeros(planned)},
                   channels=("sample_index", "t", "torque", "position")) as w:
        w.append({"sample_index": np.arange(n), "t": np.arange(n) / fs,
                  "torque": p.torque_constant * out.current_meas, "position": out.position_meas})
        w.abort(f"aborted by operator after {n} of {planned} samples")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("inc")
    _aborted(d / "ab.h5")
    _write_run(d / "ok.h5", 2)
    return d


@pytest.mark.parametrize("argv", [
    ["identify", "{ab}", "--json", "{d}/m.json"],
    ["identify", "{ok}", "--validate", "{ab}", "--json", "{d}/m.json"],
    ["residual", "{ab}", "--json", "{d}/r.json"],
    ["compare", "{ab}", "--validate", "{ok}", "-o", "{d}/cmp"],
    ["skeleton", "{ab}", "--mass", "0.0022", "--json", "{d}/s.json"],
    ["afrf", "{ab}", "--json", "{d}/a.json"],
    ["presliding", "{ab}", "-o", "{d}/p"],
])
def test_an_aborted_run_is_refused_in_one_line(files, capsys, argv):
    args = [a.format(ab=files / "ab.h5", ok=files / "ok.h5", d=files) for a in argv]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert "refusing an incomplete record: the run is aborted (aborted by operator after 12000 of 40000" in err
    assert "--allow-incomplete" in err


def test_with_allow_incomplete_every_report_says_so(files, capsys):
    assert main(["identify", str(files / "ab.h5"), "--validate", str(files / "ok.h5"), "--json",
                 str(files / "m.json"), "--allow-incomplete"]) == 0
    err = capsys.readouterr().err
    assert "warning: INCOMPLETE RECORD ab.h5: the run is aborted" in err
    doc = json.loads((files / "m.json").read_text())
    assert doc["data"]["train"]["incomplete"].startswith("the run is aborted")
    assert doc["data"]["validation"]["incomplete"] is None
    assert main(["compare", str(files / "ok.h5"), "--validate", str(files / "ab.h5"), "--families", "maxwell_slip",
                 "-o", str(files / "cmp"), "--allow-incomplete"]) == 0
    doc = json.loads((files / "cmp" / "compare.json").read_text())
    assert doc["data"]["validation"]["incomplete"].startswith("the run is aborted")
