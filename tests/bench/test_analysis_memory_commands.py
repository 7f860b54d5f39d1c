"""``--memory`` and progress of ``hilbench afrf``, ``skeleton`` and ``presliding`` (issue 26): over the budget a
record is read chunk by chunk with the same answer (within docs/long-runs.md's tolerances), a budget that even the
chunked read cannot meet is refused in one line before the samples are read, and the progress bar goes to standard
error unless -q. The records are small, so the whole read's cost per sample is raised to put them over budget."""

from __future__ import annotations

import json
import sys

import pytest

from hilbench.analysis import afrf, presliding, skeleton
from hilbench.bench import analysis_progress
from hilbench.bench.cli import main
from hilbench.firmware_sim.engine.friction_models import DC_MOTOR_D, paper_system
from hilbench.firmware_sim.engine.plant import PlantParams
from tests.analysis.afrf.test_afrf_stream import _write as write_stepped_sine
from tests.analysis.presliding.records import smooth_path
from tests.analysis.presliding.test_presliding_stream import _noisy
from tests.analysis.presliding.test_presliding_stream import _write as write_presliding
from tests.analysis.skeleton.test_skeleton_stream import _write_chirp

pytestmark = pytest.mark.device_free  # starts no device: runs in make test's parallel part


def _one_line_exit_2(argv, capsys, *texts):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert all(t in err for t in texts) and "\n" not in err, err


def test_afrf_streams_over_budget_and_refuses_what_cannot_fit(tmp_path, capsys, monkeypatch):
    path = tmp_path / "ss.h5"
    write_stepped_sine(path, PlantParams(inertia=1.0, spring=50.0, viscous=10.0), [1.0, 3.0], [0.5, 2.0])
    assert main(["afrf", str(path), "--json", str(tmp_path / "whole.json"), "-q"]) == 0
    monkeypatch.setattr(afrf, "ARRAY_BYTES_PER_SAMPLE", 1 << 30)
    assert main(["afrf", str(path), "--json", str(tmp_path / "stream.json"), "--memory", "1G", "-q"]) == 0
    whole, stream = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("whole", "stream"))
    assert stream == whole  # window by window: bit for bit
    monkeypatch.setattr(afrf, "WINDOW_BYTES_PER_SAMPLE", 1 << 30)
    _one_line_exit_2(["afrf", str(path), "--memory", "1G"], capsys, "longest step window", "over --memory 1024 MiB")


def test_skeleton_streams_over_budget_with_warnings_in_the_json(tmp_path, monkeypatch):
    path = tmp_path / "c.h5"
    _write_chirp(path, PlantParams(inertia=1.0, spring=1e4, viscous=10.0), 50.0)
    monkeypatch.setattr(skeleton, "ARRAY_BYTES_PER_SAMPLE", 1 << 30)
    assert main(["skeleton", str(path), "--json", str(tmp_path / "s.json"), "--memory", "1G", "-q"]) == 0
    doc = json.loads((tmp_path / "s.json").read_text())
    assert doc["per_run"][0]["read"].startswith("chunk by chunk, decimated by")
    assert len(doc["warnings"]) == 1 and "too narrow" in doc["warnings"][0]


def test_skeleton_refuses_a_budget_its_decimated_copy_cannot_meet(tmp_path):
    path = tmp_path / "g5.h5"
    _write_chirp(path, paper_system(), 5.0)
    with pytest.raises(Exception, match="over --memory 1 MiB: raise --memory or narrow --band"):
        skeleton.analyse_stream([path], skeleton.SkeletonSettings(spring=50.0), budget=1 << 20)


def test_presliding_streams_over_budget(tmp_path, capsys, monkeypatch):
    x = smooth_path(DC_MOTOR_D, 100)
    path = tmp_path / "p.h5"
    write_presliding(path, x, _noisy(x))
    monkeypatch.setattr(presliding, "ARRAY_BYTES_PER_SAMPLE", 1 << 30)
    assert main(["presliding", str(path), "-o", str(tmp_path / "o"), "--replicates", "2", "--memory", "1G",
                 "-q"]) == 0
    doc = json.loads((tmp_path / "o" / "presliding.json").read_text())
    assert doc["read"] == "chunk by chunk (--memory)" and doc["warnings"] == []
    monkeypatch.setattr(presliding, "STREAM_BYTES", 2 << 30)
    _one_line_exit_2(["presliding", str(path), "-o", str(tmp_path / "o2"), "--memory", "1G"], capsys,
                     "even read chunk by chunk, over --memory 1024 MiB")
    assert not (tmp_path / "o2").exists()


def test_progress_on_stderr_unless_quiet(tmp_path, capsys, monkeypatch):
    path = tmp_path / "ss.h5"
    write_stepped_sine(path, PlantParams(inertia=1.0, spring=50.0, viscous=10.0), [1.0, 3.0], [0.5, 2.0])
    monkeypatch.setattr(analysis_progress, "DELAY_S", 0.0)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)  # tqdm draws on a terminal only
    assert main(["afrf", str(path)]) == 0
    err = capsys.readouterr().err
    assert "afrf" in err and "100%" in err, err
    assert main(["afrf", str(path), "-q"]) == 0
    assert capsys.readouterr().err == ""
