"""The dependency rules of README.md and docs/architecture.md, checked on every import statement of the package
(function-level ones included), and shown to fail when a rule is broken."""

import shutil
from pathlib import Path

import pytest

from tests.import_contract import check, cycles, edges

ROOT = Path(__file__).resolve().parent.parent


def test_the_package_keeps_every_dependency_rule_and_has_no_import_cycle():
    assert check(ROOT) == []


def test_the_reading_sees_function_level_and_relative_imports(tmp_path):
    pkg = tmp_path / "analysis"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from .b import g\n    import hilbench.drivers.device\n")
    (pkg / "b.py").write_text("g = 1\n")
    for p in ("bench", "drivers", "firmware_sim"):
        (tmp_path / p).mkdir()
    found = {(e.source, e.target) for e in edges(tmp_path)}
    assert ("hilbench.analysis.a", "hilbench.analysis.b.g") in found
    assert ("hilbench.analysis.a", "hilbench.drivers.device") in found


@pytest.mark.parametrize(("where", "text", "rule"), [
    ("drivers/device.py", "from hilbench.bench.acquisition import runner", "drivers never imports"),
    ("drivers/links.py", "def f():\n    import hilbench.firmware_sim.engine.plant\n", "drivers never imports"),
    ("analysis/errors.py", "def f():\n    from hilbench.bench.storage.outputs import say\n", "analysis never imports"),
    ("analysis/record.py", "from hilbench.drivers import device", "analysis never imports"),
    ("firmware_sim/devices/device.py", "from hilbench.drivers.amplifier import Amplifier", "only protocol definitions"),
    ("firmware_sim/engine/plant.py", "def f():\n    from hilbench.analysis import record\n", "simulated device never"),
    ("bench/gui/analyses.py", "def f():\n    from hilbench.bench.cli.commands.identify import run\n", "the GUI is an"),
    ("bench/cli/commands/show.py", "from hilbench.bench.cli.commands.identify import run", "never import each other"),
    ("bench/acquisition/runner.py", "def f():\n    from hilbench.bench.cli import main\n", "never import the CLI"),
    ("bench/storage/importers.py", "from hilbench.bench.gui import app", "never import the CLI or the GUI"),
    ("bench/campaign_analysis/engine.py", "from hilbench.bench.cli.commands import run", "never import the CLI"),
    ("bench/storage/outputs.py", "from hilbench.bench.acquisition.runner import Bench", "storage never imports"),
    ("firmware_sim/engine/drift.py", "from hilbench.firmware_sim.devices import device", "engine never imports"),
])
def test_a_planted_violating_import_is_caught(tmp_path, where, text, rule):
    tree = tmp_path / "tree"  # the real module with the planted line (the rules are judged import by import)
    for pkg in ("bench", "drivers", "firmware_sim", "analysis"):
        (tree / pkg).mkdir(parents=True)
    target = tree / where
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(ROOT / where, target)
    assert not [line for line in check(tree) if where in line and rule in line]  # clean before the planting
    target.write_text(target.read_text() + "\n" + text + "\n")
    found = check(tree)
    assert any(rule in line and where in line for line in found), found


def test_a_planted_cycle_is_caught():
    graph = {"hilbench.a": {"hilbench.b"}, "hilbench.b": {"hilbench.c"}, "hilbench.c": {"hilbench.a"},
             "hilbench.d": {"hilbench.a"}}
    assert cycles(graph) == [["hilbench.a", "hilbench.b", "hilbench.c"]]


def test_the_bottom_layer_imports_nothing_else_of_hilbench(tmp_path):
    tree = tmp_path / "tree"
    for pkg in ("bench", "drivers", "firmware_sim", "analysis"):
        (tree / pkg).mkdir(parents=True)
    common = tree / "hilbench" / "common"
    common.mkdir(parents=True)
    (common / "__init__.py").write_text("")
    (common / "units.py").write_text("from hilbench.common import __doc__\n")
    (tree / "drivers" / "device.py").write_text("from hilbench.common import units\n")
    assert check(tree) == []  # anyone may import the bottom layer, and it may import itself
    (common / "units.py").write_text("def f():\n    from hilbench.analysis import record\n")
    found = check(tree)
    assert any("hilbench/common/units.py" in line and "bottom layer" in line for line in found), found
