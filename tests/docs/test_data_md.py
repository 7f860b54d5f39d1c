"""docs/data.md is true: its worked examples run as written and print what the page shows, and its tables of
column names and units are the importer's own."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import h5py
import numpy as np
import pytest

from hilbench.bench.cli import main
from hilbench.bench.storage.import_units import ALIASES, UNITS

PAGE = Path(__file__).resolve().parents[2] / "docs" / "data.md"
BLOCK = re.compile(r"<!-- (?P<kind>file: \S+|python|console) -->\n```[a-z]*\n(?P<body>.*?)```", re.S)


def _table(marker: str) -> dict[str, str]:
    text = PAGE.read_text().split(marker, 1)[1]
    rows = {}
    for line in text.splitlines()[3:]:
        if not line.startswith("|"):
            break
        key, value = (cell.strip().strip("`") for cell in line.strip("|").split("|"))
        rows[key] = value
    return rows


def test_alias_and_unit_tables_are_the_code():
    assert _table("<!-- aliases:") == {ch: ", ".join(names) for ch, names in ALIASES.items()}
    units = _table("<!-- units:")
    for quantity, table in UNITS.items():
        if quantity == "counts":
            continue
        listed = units[quantity.replace("_", " ")].replace(" (with `--counts-per-rev N`)", "").split(", ")
        assert [u for u in listed if u != "counts"] == list(table), quantity


def test_worked_examples_run_as_written(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    blocks = list(BLOCK.finditer(PAGE.read_text()))
    assert [b["kind"].split(":")[0] for b in blocks] == ["file", "console", "python", "console"]
    commands = 0
    for block in blocks:
        kind, body = block["kind"], block["body"]
        if kind.startswith("file: "):
            (tmp_path / kind[len("file: "):]).write_text(body)
        elif kind == "python":
            exec(compile(body, str(PAGE), "exec"), {})
        else:
            for step in re.split(r"^\$ ", body, flags=re.M)[1:]:
                command, *expected = step.rstrip("\n").split("\n")
                argv = shlex.split(command)
                assert argv[0] == "hilbench"
                main(argv[1:])
                captured = capsys.readouterr()
                assert (captured.out + captured.err).rstrip("\n").split("\n") == expected, command
                commands += 1
    assert commands == 4
    # what the CSV example says the file holds
    with h5py.File(tmp_path / "rig.h5", "r") as f:
        s = f["samples"]
        assert s["position"][1] == pytest.approx(np.radians(0.05), rel=1e-12)
        assert s["torque"][1] == pytest.approx(0.05753, rel=1e-12)
        assert s["t"][6] == pytest.approx(0.006) and s["position"][6] == pytest.approx(np.radians(1.85), rel=1e-12)
        assert f.attrs["torque_timing"] == "hold_previous"
    with h5py.File(tmp_path / "rig_mat.h5", "r") as f:
        s = f["samples"]
        np.testing.assert_allclose(s["torque"][:], 0.12 * 0.8 * np.cos(2 * np.pi * np.arange(2000) / 1000))
        np.testing.assert_allclose(s["position"][:], s["counts"][:] * 2 * np.pi / 4096, rtol=1e-15)
