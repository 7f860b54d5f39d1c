"""docs/campaign-analysis.md shows how to read the results table from pandas, polars and DuckDB: each snippet runs,
as printed, on an analysed campaign when its package is installed (none is a dependency of hilbench), and its
figures are the table's as pyarrow reads it."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from hilbench.bench.campaign_analysis.engine import analyse
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign
from hilbench.common.units import schema_units

DOC = Path(__file__).resolve().parents[2] / "docs" / "campaign-analysis.md"


def snippets() -> dict[str, str]:
    """The section's python blocks, by the package each one imports first."""
    text = DOC.read_text()
    section = text[text.index("### Reading the table from pandas, polars and DuckDB"):]
    section = section[:section.index("\n## ") if "\n## " in section else len(section)]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    return {re.search(r"^import (\w+)", b, flags=re.M).group(1): b for b in blocks}


def test_the_section_has_one_snippet_per_package():
    assert set(snippets()) == {"pandas", "polars", "duckdb"}


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> Path:
    """A campaign folder `plan` (3 planned runs x 2 repeats, those of one without their position channel), analysed into
    plan/analysis as `hilbench analyse plan` writes it; returns the folder the snippets run in."""
    root = tmp_path_factory.mktemp("docs")
    write_campaign(root / "plan", SyntheticCampaign(runs=3, repeats=2, duration=1.0, seed=9), fail_runs=(2,))
    analyse([root / "plan"], root / "plan" / "analysis", serial=True, progress=False, say=lambda _line: None)
    return root


def _expected(root: Path) -> dict[str, dict[str, float]]:
    """Per planned run, from the table read with pyarrow: runs, break-away mean and sample std, NRMSE in %."""
    rows = [r for r in pq.read_table(root / "plan" / "analysis" / "results.parquet").to_pylist()
            if r["step"] == "identify" and r["status"] == "ok"]
    out = {}
    for name in sorted({r["name"] for r in rows}):
        b = np.array([r["breakaway"] for r in rows if r["name"] == name])
        e = np.array([r["validation_torque_nrmse"] for r in rows if r["name"] == name])
        out[name] = {"runs": b.size, "mean": b.mean(), "std": b.std(ddof=1) if b.size > 1 else np.nan,
                     "pct": 100 * e.mean()}
    return out


def _run(package: str, root: Path, monkeypatch, capsys) -> dict:
    if importlib.util.find_spec(package) is None:
        pytest.skip(f"{package} is not installed (pip install {package}); the docs' {package} snippet is not run")
    monkeypatch.chdir(root)
    namespace: dict = {}
    exec(compile(snippets()[package], f"docs/campaign-analysis.md ({package})", "exec"), namespace)
    namespace["printed"] = capsys.readouterr().out
    return namespace


def test_the_pandas_snippet_runs_and_gives_the_tables_figures(results, monkeypatch, capsys):
    ns = _run("pandas", results, monkeypatch, capsys)
    expected = _expected(results)
    assert sorted(ns["per_run"].index) == sorted(expected)
    for name, e in expected.items():
        assert ns["per_run"].loc[name, ("breakaway", "mean")] == pytest.approx(e["mean"], rel=1e-12)
        np.testing.assert_allclose(ns["per_run"].loc[name, ("breakaway", "std")], e["std"], rtol=1e-12)
    table = pq.read_table(results / "plan" / "analysis" / "results.parquet")
    assert ns["unit"]["breakaway"] == schema_units(table.schema)["breakaway"] == "N*m"
    assert ns["unit_linear"]["viscous"] == schema_units(table.schema, "linear")["viscous"] == "N*s/m"
    assert "break-away in N*m, viscous in N*m*s/rad (on a linear axis: N, N*s/m)" in ns["printed"]
    failed = ns["failed"]
    bad = [r for r in table.to_pylist() if r["status"] != "ok"]
    assert len(failed) == len(bad) >= 1 and all("no position channel" in e for e in failed["error"])


def test_the_polars_snippet_runs_and_gives_the_tables_figures(results, monkeypatch, capsys):
    ns = _run("polars", results, monkeypatch, capsys)
    got = {r["name"]: r for r in ns["per_run"].to_dicts()}
    for name, e in _expected(results).items():
        assert got[name]["runs"] == e["runs"] and got[name]["breakaway_mean"] == pytest.approx(e["mean"], rel=1e-12)
        assert got[name]["validation_torque_nrmse_pct"] == pytest.approx(e["pct"], rel=1e-12)


def test_the_duckdb_snippet_runs_and_gives_the_tables_figures(results, monkeypatch, capsys):
    ns = _run("duckdb", results, monkeypatch, capsys)
    got = {r[0]: r for r in ns["per_run"]}
    for name, e in _expected(results).items():
        assert got[name][1] == e["runs"] and got[name][2] == pytest.approx(e["mean"], rel=1e-12)
        assert got[name][4] == pytest.approx(e["pct"], rel=1e-12)
