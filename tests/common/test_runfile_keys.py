"""No module other than the schema owner (``hilbench.common.runfile``) spells a run-file key as a string literal.

A key spelled twice drifts: drivers wrote ``"sample_times"`` as a bare literal that ``analysis/record.py``
interpreted. The rule reads every module of the package folders with :mod:`ast` (docstrings aside). Two kinds of key:

- a *distinctive* key of the schema (an identity key, a root attribute, a JSON dataset path, the schema's name) is
  flagged wherever it is spelled: nothing else uses those words;
- a *compound* channel or event-record name (``sample_index``, ``current_cmd``, ``position_cmd``, ``torque_cmd``,
  ``host_time``...) is the run file's key unless the literal sits among names no run file has: in a dict display,
  a tuple, list or set display, or among the keys one variable is subscripted (or ``.get``) with in one function,
  another name beside it that is neither a channel nor an event field says the mapping is another vocabulary that
  shares the word (a driver's live state ``{"state", "current_cmd", ...}``, the plant's outputs ``theta``..., the
  live view's ``current_meas``, an importer's column aliases ``pos_ref``, a wire message's ``__slots__``).

One-word channel names (``torque``, ``position``, ``t``...) and attributes spelled like ordinary words (``axis``,
``status``, ``notes``) are left out: a report or a setting may use the same word for its own purpose.
"""

from __future__ import annotations

import ast
from dataclasses import fields
from pathlib import Path

import pytest

from hilbench.common.runfile import schema

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = ("bench", "drivers", "firmware_sim", "analysis", "hilbench")
OWNER = ROOT / "hilbench" / "common" / "runfile"
#: root attributes of every run file (docs/run-file.md) that no other format uses (schema_version: reports too)
ROOT_ATTRIBUTES = ("writer_pid", "writer_host", "flush_interval", "end_time")


#: every name a run file gives a sample channel or an event record's field (the linear aliases included)
RUN_FILE_NAMES = {*schema.CHANNELS, *schema.EVENT_DTYPE.names, *schema.LINEAR_ALIASES}


def distinctive_keys() -> set[str]:
    identity = {f.name for f in fields(schema.DeviceIdentity)} | {schema.SAMPLE_TIMES_KEY}
    paths = {"device/identity", "device/config", "device/calibration", "protocol/parameters"}
    keys = {schema.SCHEMA, *ROOT_ATTRIBUTES, *paths, *identity}
    return {k for k in keys if "_" in k or "-" in k or "/" in k}  # compound: never an ordinary word


def channel_keys() -> set[str]:
    """The compound channel and event-record names (never an ordinary word)."""
    return {k for k in RUN_FILE_NAMES if "_" in k}


def _docstrings(tree: ast.AST) -> set[int]:
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                out.add(id(first.value))
    return out


def _strings(nodes) -> set[str]:
    return {n.value for n in nodes if isinstance(n, ast.Constant) and isinstance(n.value, str)}


def _neighbours(tree: ast.AST) -> dict[int, set[str]]:
    """id(string constant) -> the names spelled beside it: the other keys (or values) of its dict display, the
    other items of its tuple/list/set display, or every key its variable is subscripted or ``.get`` with in the
    same function (module level: the module)."""
    out: dict[int, set[str]] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for group in ([k for k in node.keys if k is not None], node.values):
                for item in group:
                    out[id(item)] = _strings(group)
        elif isinstance(node, ast.Tuple | ast.List | ast.Set):
            for item in node.elts:
                out[id(item)] = _strings(node.elts)
    scopes = [tree, *(n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef))]
    for scope in scopes:
        keys: dict[str, list[ast.AST]] = {}
        for node in ast.walk(scope):
            if isinstance(node, ast.Subscript):
                keys.setdefault(ast.unparse(node.value), []).append(node.slice)
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.args
                  and node.func.attr in ("get", "pop", "setdefault")):
                keys.setdefault(ast.unparse(node.func.value), []).append(node.args[0])
        for used in keys.values():
            for item in used:
                if isinstance(item, ast.Constant):
                    out[id(item)] = out.get(id(item), set()) | _strings(used)
    return out


def literal_keys(source: str, keys: set[str], where: str, channels: set[str] | None = None) -> list[str]:
    """``where:line: 'key'`` for every string constant of ``source`` (docstrings aside) that is one of ``keys``, or
    one of ``channels`` (default :func:`channel_keys`) spelled among run-file names only (module docstring)."""
    channels = channel_keys() if channels is None else channels
    tree = ast.parse(source)
    docs = _docstrings(tree)
    beside = _neighbours(tree)
    found = []
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Constant) and isinstance(node.value, str)) or id(node) in docs:
            continue
        if node.value in keys or (node.value in channels and beside.get(id(node), set()) <= RUN_FILE_NAMES):
            found.append(f"{where}:{node.lineno}: {node.value!r}")
    return found


def test_the_rule_covers_the_keys_that_drifted_and_no_ordinary_word():
    keys, channels = distinctive_keys(), channel_keys()
    assert {"sample_times", "writer_pid", "hilbench-run"} <= keys
    assert {"sample_index", "current_cmd", "position_cmd", "torque_cmd", "velocity_cmd", "current_ff", "host_time",
            "drive_status", "wall_time", "force_cmd"} == channels
    ordinary = {"schema_version", "torque", "position", "t", "axis", "status", "notes", "name", "model", "url"}
    assert not (keys | channels) & ordinary


def test_the_rule_flags_a_literal_key_and_spares_docstrings_and_the_constant():
    keys = distinctive_keys()
    bad = 'def info():\n    """Says "sample_times" in its docstring."""\n    return {"sample_times": "drive"}\n'
    assert literal_keys(bad, keys, "x.py") == ["x.py:3: 'sample_times'"]
    good = ('from hilbench.common.runfile import SAMPLE_TIMES_KEY\n\n\ndef info():\n'
            '    """Says sample_times."""\n    return {SAMPLE_TIMES_KEY: "drive", "time": 1}\n')
    assert literal_keys(good, keys, "x.py") == []


# every way a channel name was spelled as the run file's key, each flagged
RUN_FILE_USES = {
    "block": 'w.append({"sample_index": k, "t": k / fs, "torque": u})',
    "channel list": 'RunWriter(p, channels=("sample_index", "t", "position_cmd"))',
    "subscript": 'x = rec.channels["position_cmd"] - rec.position',
    "read": 'load_record(p, channels=("current_cmd",)).channel("current_cmd")',
    "get": 'ref = reference.get("current_ff")',
    "comparison": 'skip = name == "sample_index"',
    "event field": 'line = f"{e[\'sample_index\']} {e[\'kind\']}"',
}
# the same words in another vocabulary: a name beside them that no run file has
OTHER_VOCABULARIES = {
    "live state": 'live = {"state": s, "faults": [], "cycle": 3, "current_cmd": 0.5}',
    "live state read": 'def f(live):\n    return live["faults"], live["current_cmd"]',
    "live view": 'self.live.append(t, {"current_cmd": a, "current_meas": b, "position_cmd": c})',
    "plant outputs": 'OUTPUT_UNITS = {"theta": "rad", "current_cmd": "A"}',
    "wire fields": '__slots__ = ("seq", "first_index", "counts", "current_cmd")',
    "column aliases": 'ALIASES = {POSITION_CMD: ("position_cmd", "position_ref", "pos_ref")}',
}


@pytest.mark.parametrize("use", RUN_FILE_USES)
def test_a_channel_name_spelled_as_the_run_files_key_is_flagged(use):
    assert literal_keys(RUN_FILE_USES[use], set(), "x.py"), use


@pytest.mark.parametrize("use", OTHER_VOCABULARIES)
def test_the_same_word_in_another_vocabulary_is_not(use):
    assert literal_keys(OTHER_VOCABULARIES[use], set(), "x.py") == [], use


def test_a_literal_planted_in_the_runner_is_caught():
    """The runner writes every block through the schema's names; spelling one of them again is caught."""
    path = ROOT / "bench" / "acquisition" / "runner.py"
    source = path.read_text(encoding="utf-8")
    assert literal_keys(source, distinctive_keys(), "runner.py") == []
    planted = source.replace("writer.append({SAMPLE_INDEX: blk.index", 'writer.append({"sample_index": blk.index', 1)
    assert planted != source
    (line,) = literal_keys(planted, distinctive_keys(), "runner.py")
    assert line.endswith(": 'sample_index'")


def test_no_module_but_the_schema_owner_spells_a_run_file_key():
    keys = distinctive_keys()
    found = []
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            if OWNER in path.parents:
                continue
            found += literal_keys(path.read_text(encoding="utf-8"), keys, str(path.relative_to(ROOT)))
    assert not found, "run-file keys spelled outside hilbench.common.runfile (use its constants):\n" + "\n".join(found)
