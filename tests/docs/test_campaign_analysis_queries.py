"""docs/campaign-analysis.md shows how to read the results table from pandas, polars and DuckDB: each snippet runs,
as printed, on an analysed campaign (the test extra `docs-query` installs the three packages; none is a dependency
of hilbench, and a snippet whose package is missing skips with one line), and the figures it holds and prints are
the table's as pyarrow alone computes them (pyarrow.compute: the oracle shares no code with the three readers)."""

from __future__ import annotations

import ast
import importlib.util
import math
import re
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
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
    """A campaign folder `plan` of 5 runs, repeats of 2 planned runs and a third run alone (id1-1, id1-2, id2-1,
    id2-2, id3-1; id2-1 without its position channel, so id2 and id3 have one ok run each: a sample std of one run
    is NaN), analysed into plan/analysis as `hilbench analyse plan` writes it; returns the folder the snippets run
    in."""
    root = tmp_path_factory.mktemp("docs")
    write_campaign(root / "plan", SyntheticCampaign(runs=5, repeats=2, duration=1.0, seed=9), fail_runs=(2,))
    analyse([root / "plan"], root / "plan" / "analysis", serial=True, progress=False, say=lambda _line: None)
    return root


def _expected(root: Path) -> dict[str, dict[str, float]]:
    """Per planned run, from the table read and aggregated with pyarrow alone: runs, break-away and viscous mean and
    sample std (NaN for one run), validation NRMSE mean in %."""
    t = pq.read_table(root / "plan" / "analysis" / "results.parquet")
    ok = t.filter(pc.and_(pc.equal(t["step"], "identify"), pc.equal(t["status"], "ok")))
    sample = pc.VarianceOptions(ddof=1)
    agg = ok.group_by("name").aggregate([
        ("breakaway", "count"), ("breakaway", "mean"), ("breakaway", "stddev", sample),
        ("viscous", "mean"), ("viscous", "stddev", sample), ("validation_torque_nrmse", "mean")]).to_pylist()
    nan = float("nan")
    return {a["name"]: {"runs": a["breakaway_count"], "mean": a["breakaway_mean"],
                        "std": nan if a["breakaway_stddev"] is None else a["breakaway_stddev"],
                        "viscous_mean": a["viscous_mean"],
                        "viscous_std": nan if a["viscous_stddev"] is None else a["viscous_stddev"],
                        "pct": 100 * a["validation_torque_nrmse_mean"]} for a in agg}


#: a number as pandas and polars print a float (6 decimals, polars drops trailing zeros), or NaN / null
NUMBER = r"-?\d+(?:\.\d+)?(?:e[-+]?\d+)?|NaN|null"
#: half a unit in the 6th decimal: the most a printed float may differ from the figure it shows
PRINTED = 5e-7 + 1e-12


def _printed_row(printed: str, name: str, separator: str = r"\s+") -> list[float]:
    """The numbers printed on the line of planned run ``name`` of a printed table (NaN for NaN or null)."""
    line = next(ln for ln in printed.splitlines() if re.match(rf"^\W*{re.escape(name)}\b", ln))
    cells = re.split(separator, line.strip(" │"))[1:]
    return [float("nan") if c.strip() in ("NaN", "null") else float(c) for c in cells
            if re.fullmatch(NUMBER, c.strip())]


def _run(package: str, root: Path, monkeypatch, capsys) -> dict:
    if importlib.util.find_spec(package) is None:
        pytest.skip(f"{package} is not installed (pip install {package}); the docs' {package} snippet is not run")
    monkeypatch.chdir(root)
    namespace: dict = {}
    exec(compile(snippets()[package], f"docs/campaign-analysis.md ({package})", "exec"), namespace)
    namespace["printed"] = capsys.readouterr().out
    return namespace


def _close(printed: list[float], exact: list[float]) -> bool:
    """Printed figures against the oracle's to the printed precision (NaN where the oracle has NaN)."""
    return len(printed) == len(exact) and all(math.isnan(p) if math.isnan(x) else abs(p - x) <= PRINTED
                                              for p, x in zip(printed, exact, strict=True))


def test_the_pandas_snippet_runs_and_gives_the_tables_figures(results, monkeypatch, capsys):
    ns = _run("pandas", results, monkeypatch, capsys)
    expected = _expected(results)
    assert sorted(ns["per_run"].index) == sorted(expected) == ["id1", "id2", "id3"]
    for name, e in expected.items():
        assert ns["per_run"].loc[name, ("breakaway", "mean")] == pytest.approx(e["mean"], rel=1e-12)
        np.testing.assert_allclose(ns["per_run"].loc[name, ("breakaway", "std")], e["std"], rtol=1e-12)
        np.testing.assert_allclose(ns["per_run"].loc[name, ("viscous", "std")], e["viscous_std"], rtol=1e-12)
        shown = [e["mean"], e["std"], e["viscous_mean"], e["viscous_std"]]
        assert _close(_printed_row(ns["printed"], name), shown), (name, ns["printed"])
    table = pq.read_table(results / "plan" / "analysis" / "results.parquet")
    assert ns["unit"]["breakaway"] == schema_units(table.schema)["breakaway"] == "N*m"
    assert ns["unit_linear"]["viscous"] == schema_units(table.schema, "linear")["viscous"] == "N*s/m"
    assert "break-away in N*m, viscous in N*m*s/rad (on a linear axis: N, N*s/m)" in ns["printed"]
    ok = table.filter(pc.and_(pc.equal(table["step"], "identify"), pc.equal(table["status"], "ok")))
    nrmse = ok["validation_torque_nrmse"]
    assert (f"validation torque NRMSE: {100 * pc.mean(nrmse).as_py():.3g} % mean, "
            f"{100 * pc.max(nrmse).as_py():.3g} % worst") in ns["printed"]
    failed = ns["failed"]
    bad = [r for r in table.to_pylist() if r["status"] != "ok"]
    assert len(failed) == len(bad) >= 1 and all("no position channel" in e for e in failed["error"])
    assert all(re.search(rf"^\s*{r['key']} {r['step']} {r['status']} ", ns["printed"], flags=re.M) for r in bad)


def test_the_polars_snippet_runs_and_gives_the_tables_figures(results, monkeypatch, capsys):
    ns = _run("polars", results, monkeypatch, capsys)
    got = {r["name"]: r for r in ns["per_run"].to_dicts()}
    expected = _expected(results)
    assert sorted(got) == sorted(expected)
    for name, e in expected.items():
        assert got[name]["runs"] == e["runs"] and got[name]["breakaway_mean"] == pytest.approx(e["mean"], rel=1e-12)
        np.testing.assert_allclose(np.float64(got[name]["breakaway_std"] or np.nan), e["std"], rtol=1e-12)
        assert got[name]["validation_torque_nrmse_pct"] == pytest.approx(e["pct"], rel=1e-12)
        shown = [e["runs"], e["mean"], e["std"], e["pct"]]
        assert _close(_printed_row(ns["printed"], name, r"\s*[┆│|]\s*"), shown), (name, ns["printed"])


def test_the_duckdb_snippet_runs_and_gives_the_tables_figures(results, monkeypatch, capsys):
    ns = _run("duckdb", results, monkeypatch, capsys)
    got = {r[0]: r for r in ns["per_run"]}
    expected = _expected(results)
    assert sorted(got) == sorted(expected)
    for name, e in expected.items():
        assert got[name][1] == e["runs"] and got[name][2] == pytest.approx(e["mean"], rel=1e-12)
        np.testing.assert_allclose(np.float64(np.nan if got[name][3] is None else got[name][3]), e["std"],
                                   rtol=1e-12)
        assert got[name][4] == pytest.approx(e["pct"], rel=1e-12)
    # it prints the rows' Python repr: every figure in full, the same as those checked above
    assert ast.literal_eval(ns["printed"].strip()) == ns["per_run"]
