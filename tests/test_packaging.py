"""The distribution as a lab installs it: a wheel built with ``pip wheel``, installed into a fresh venv, run from
a folder outside the source tree.

To stay fast and offline the fresh venv gets the wheel with ``--no-deps`` and sees the project venv's third-party
packages through one ``.pth`` line. A path line in a ``.pth`` file does not process that folder's own ``.pth``
files, so the editable install's finder of the project venv is not active there: ``hilbench`` can only come
from the wheel, which the test checks.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
GENERIC = ("bench", "analysis", "drivers", "firmware_sim", "benchmarks")
#: left out of the copy the wheel is built from: build products and caches, never sources
IGNORE = shutil.ignore_patterns(".venv", ".git", "build", "dist", "*.egg-info", "__pycache__", "*.so", "*.o",
                                "_plant.c", "demo-out", "out", ".pytest_cache", ".ruff_cache", ".hypothesis")


def _run(argv: list[str], cwd: Path, env: dict[str, str], timeout: float = 600) -> subprocess.CompletedProcess:
    res = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert res.returncode == 0, f"{argv} -> {res.returncode}\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    return res


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> dict:
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    shutil.copytree(REPO, src, ignore=IGNORE)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP")}
    wheels = tmp / "wheels"
    # build requirements (setuptools, wheel, cffi) come from the project venv: no download
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-cache-dir",
          "-w", str(wheels), str(src)], tmp, env)
    (wheel,) = wheels.glob("hilbench-*.whl")
    venv = tmp / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp, env)
    py = venv / "bin" / "python"
    site = Path(_run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], tmp,
                     env).stdout.strip())
    (site / "project_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    _run([sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps", "--no-index",
          "--no-cache-dir", str(wheel)], tmp, env)
    outside = tmp / "elsewhere"
    outside.mkdir()
    env.update(QT_QPA_PLATFORM="offscreen", MPLBACKEND="Agg")
    return {"wheel": wheel, "venv": venv, "py": py, "site": site, "cwd": outside, "env": env}


def test_wheel_holds_one_namespace_and_the_package_data(installed):
    names = zipfile.ZipFile(installed["wheel"]).namelist()
    top = {n.split("/")[0] for n in names}
    assert {t for t in top if not t.endswith(".dist-info")} == {"hilbench"}, top
    for needed in ("hilbench/firmware_sim/engine/plant.c", "hilbench/firmware_sim/engine/plant.h",
                   "hilbench/firmware_sim/devices/default_sim.toml", "hilbench/firmware_sim/devices/hb_cia402.eds",
                   "hilbench/__main__.py"):
        assert needed in names, needed
    assert any(n.startswith("hilbench/firmware_sim/engine/_plant") and n.endswith(".so") for n in names)


def test_the_docs_ship_and_hilbench_docs_prints_them_from_the_wheel(installed):
    """Issue 38: from a wheel there were no docs while --help points to docs/*.md. Every docs/*.md ships (the
    figure scripts docs/make_*.py do not), `hilbench docs` lists the topics, `hilbench docs metrics` prints
    docs/metrics.md as the repository holds it, and the metadata names where the docs are."""
    names = zipfile.ZipFile(installed["wheel"]).namelist()
    for doc in sorted((REPO / "docs").glob("*.md")):
        assert f"hilbench/docs/{doc.name}" in names, doc.name
    assert not [n for n in names if n.startswith("hilbench/docs/make_")]
    exe, cwd, env = str(installed["venv"] / "bin" / "hilbench"), installed["cwd"], installed["env"]
    listed = _run([exe, "docs"], cwd, env).stdout
    assert re.search(r"^metrics +The error vocabulary", listed, re.M), listed
    assert _run([exe, "docs", "metrics"], cwd, env).stdout == (REPO / "docs" / "metrics.md").read_text()
    with zipfile.ZipFile(installed["wheel"]) as wheel:
        (meta,) = [n for n in wheel.namelist() if n.endswith(".dist-info/METADATA")]
        text = wheel.read(meta).decode()
    assert "Project-URL: Documentation, hilbench://docs" in text


def test_installed_wheel_is_what_runs_and_nothing_generic_is_importable(installed):
    import json

    probe = (
        "import importlib.util, json, sys, hilbench, hilbench.firmware_sim.engine._plant as p\n"
        f"generic = {GENERIC!r}\n"
        "print(json.dumps({'hilbench': hilbench.__file__, 'plant': p.__file__,\n"
        "  'generic': [g for g in generic if importlib.util.find_spec(g) is not None],\n"
        "  'editable': [m for m in sys.modules if 'editable' in m]}))\n"
    )
    out = json.loads(_run([str(installed["py"]), "-c", probe], installed["cwd"], installed["env"]).stdout)
    assert out["generic"] == [] and out["editable"] == []
    for key in ("hilbench", "plant"):
        assert Path(out[key]).is_relative_to(installed["site"]), out[key]  # the wheel, not the source tree


def test_installed_command_help_and_demo_outside_the_source_tree(installed):
    exe = installed["venv"] / "bin" / "hilbench"
    cwd, env = installed["cwd"], installed["env"]
    assert "usage: hilbench" in _run([str(exe), "--help"], cwd, env).stdout
    assert "usage: hilbench" in _run([str(installed["py"]), "-m", "hilbench", "--help"], cwd, env).stdout
    res = _run([str(exe), "demo", "-o", "demo-out", "--duration", "5"], cwd, env)
    runs = sorted((cwd / "demo-out").rglob("*.h5"))
    assert len(runs) >= 2 and (cwd / "demo-out" / "model.json").is_file(), res.stdout[-2000:]
    assert "done: everything is in demo-out" in res.stdout


def test_a_users_own_generic_folders_do_not_shadow_ours(installed, tmp_path):
    # Why: "A user's own analysis/ folder next to their script shadows ours (ModuleNotFoundError). The bench
    # module and command clash with a well-known PyPI package."
    for name in GENERIC:
        (tmp_path / name).mkdir()
    script = tmp_path / "my_analysis.py"
    script.write_text(
        "import analysis, bench  # the user's own, next to the script\n"
        "from hilbench.analysis.identification.regressors import held_torque\n"
        "from hilbench.common.runfile import CHANNELS\n"
        "print(held_torque([1.0, 2.0, 4.0], 'instant').tolist(), CHANNELS['torque'].unit('rotary'))\n"
    )
    for name in GENERIC:  # make the user's packages importable (their own code), not raising
        (tmp_path / name / "__init__.py").write_text("")
    out = _run([str(installed["py"]), str(script)], tmp_path, installed["env"]).stdout
    assert out.strip() == "[1.5, 3.0, 4.0] N*m"
    assert not (installed["venv"] / "bin" / "bench").exists()  # no `bench` command to clash with


def _python_blocks(doc: Path) -> list[str]:
    """The ```python blocks of a Markdown file, in order."""
    blocks, current = [], None
    for line in doc.read_text(encoding="utf-8").splitlines():
        if current is None and line.strip() == "```python":
            current = []
        elif current is not None and line.strip() == "```":
            blocks.append("\n".join(current) + "\n")
            current = None
        elif current is not None:
            current.append(line)
    return blocks


def test_every_python_example_of_the_readme_and_docs_runs_from_the_wheel(installed, tmp_path):
    """Each block, in order (the README's make the runs the docs' read), in a folder outside the source tree,
    against the installed hilbench.* names: a stale name or a changed signature fails here."""
    docs = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
    # the Parquet query snippets (pandas, polars, DuckDB) run in tests/docs/test_campaign_analysis_queries.py, on a
    # results table of their own and with those packages: not here, where the wheel's venv has neither
    blocks = [(doc, code) for doc in docs for code in _python_blocks(doc)
              if not re.search(r"^import (pandas|polars|duckdb)\b", code, flags=re.M)]
    assert len(blocks) >= 5 and all("hilbench" in code or "h5py" in code or "savemat" in code for _d, code in blocks)
    work = tmp_path / "examples"
    work.mkdir()
    for doc, code in blocks:
        if doc.name == "run-file.md" and not (work / "run.h5").exists():
            shutil.copyfile(work / "runs" / "id.h5", work / "run.h5")  # the docs' examples read "run.h5"
        res = subprocess.run([str(installed["py"]), "-c", code], cwd=work, env=installed["env"], capture_output=True,
                             text=True, timeout=600)
        assert res.returncode == 0, f"{doc.name}:\n{code}\n{res.stderr[-2000:]}"


def test_every_example_file_a_doc_names_ships_and_runs_from_the_wheel(installed, tmp_path):
    """Issue 28: docs/cli.md pointed at examples/presliding_sim.toml, which the wheel did not ship. Every
    examples/NAME the README and docs name is in the wheel, `hilbench examples -o examples` puts it where the
    docs' commands look, and the presliding command of docs/cli.md runs with it (lockstep, shorter)."""
    text = "\n".join(p.read_text(encoding="utf-8") for p in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))])
    named = set(re.findall(r"examples/([A-Za-z0-9_.-]+\.(?:toml|py))", text))
    assert "presliding_sim.toml" in named, named
    wheel = set(zipfile.ZipFile(installed["wheel"]).namelist())
    exe, env = str(installed["venv"] / "bin" / "hilbench"), installed["env"]
    out = _run([exe, "examples", "-o", "examples"], tmp_path, env).stdout
    assert "example files in examples" in out
    for name in sorted(named):
        assert f"hilbench/examples/{name}" in wheel, name
        assert (tmp_path / "examples" / name).is_file(), name
    _run([exe, "run", "presliding", "--counts-per-rev", "65536", "--amplitudes", "2", "1", "--quiet", "--device",
          "sim://?config=examples/presliding_sim.toml&pacing=lockstep", "-o", "presliding.h5"], tmp_path, env)
    assert (tmp_path / "presliding.h5").is_file()
