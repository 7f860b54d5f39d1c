"""No module other than the schema owner (``hilbench.common.runfile``) spells a run-file key as a string literal.

A key spelled twice drifts: drivers wrote ``"sample_times"`` as a bare literal that ``analysis/record.py``
interpreted. The rule reads every module of the package folders with :mod:`ast`; it flags a string constant (not a
docstring) equal to a *distinctive* key of the schema: an identity key, a root attribute, a JSON dataset path, the
schema's name or a channel added by host-clocked drives. Device-clocked channel names (``torque``, ``position``,
``t``...) and attributes spelled like ordinary words (``axis``, ``status``, ``notes``) are not distinctive: a report
or a setting may use the same word for its own purpose, so they are left out of the rule.
"""

from __future__ import annotations

import ast
from dataclasses import fields
from pathlib import Path

from hilbench.common.runfile import schema

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = ("bench", "drivers", "firmware_sim", "analysis", "hilbench")
OWNER = ROOT / "hilbench" / "common" / "runfile"
#: root attributes of every run file (docs/run-file.md) that no other format uses (schema_version: reports too)
ROOT_ATTRIBUTES = ("writer_pid", "writer_host", "flush_interval", "end_time")


def distinctive_keys() -> set[str]:
    identity = {f.name for f in fields(schema.DeviceIdentity)} | {schema.SAMPLE_TIMES_KEY}
    channels = set(schema.HOST_CLOCKED_CHANNELS) - set(schema.DEVICE_CHANNELS) - {"velocity", "torque_cmd", "cycle"}
    paths = {"device/identity", "device/config", "device/calibration", "protocol/parameters"}
    keys = {schema.SCHEMA, *ROOT_ATTRIBUTES, *paths, *channels, *identity}
    return {k for k in keys if "_" in k or "-" in k or "/" in k}  # compound: never an ordinary word


def _docstrings(tree: ast.AST) -> set[int]:
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                out.add(id(first.value))
    return out


def literal_keys(source: str, keys: set[str], where: str) -> list[str]:
    """``where:line: 'key'`` for every string constant of ``source`` (docstrings aside) that is one of ``keys``."""
    tree = ast.parse(source)
    docs = _docstrings(tree)
    return [f"{where}:{node.lineno}: {node.value!r}" for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in keys
            and id(node) not in docs]


def test_the_rule_covers_the_keys_that_drifted_and_no_ordinary_word():
    keys = distinctive_keys()
    assert {"sample_times", "host_time", "drive_status", "writer_pid", "hilbench-run"} <= keys
    ordinary = {"schema_version", "torque", "position", "t", "axis", "status", "notes", "name", "model", "url"}
    assert not keys & ordinary


def test_the_rule_flags_a_literal_key_and_spares_docstrings_and_the_constant():
    keys = distinctive_keys()
    bad = 'def info():\n    """Says "sample_times" in its docstring."""\n    return {"sample_times": "drive"}\n'
    assert literal_keys(bad, keys, "x.py") == ["x.py:3: 'sample_times'"]
    good = ('from hilbench.common.runfile import SAMPLE_TIMES_KEY\n\n\ndef info():\n'
            '    """Says sample_times."""\n    return {SAMPLE_TIMES_KEY: "drive", "time": 1}\n')
    assert literal_keys(good, keys, "x.py") == []


def test_no_module_but_the_schema_owner_spells_a_run_file_key():
    keys = distinctive_keys()
    found = []
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            if OWNER in path.parents:
                continue
            found += literal_keys(path.read_text(encoding="utf-8"), keys, str(path.relative_to(ROOT)))
    assert not found, "run-file keys spelled outside hilbench.common.runfile (use its constants):\n" + "\n".join(found)
