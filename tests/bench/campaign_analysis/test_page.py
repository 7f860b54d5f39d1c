"""The campaign page: one self-contained HTML file, loaded in headless Chromium (no console error, the runs table
shown) and screenshotted."""

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from hilbench.bench.campaign_analysis.engine import analyse
from hilbench.bench.campaign_analysis.page import repeat_summary
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign
from hilbench.bench.cli import main

CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]


@pytest.fixture(scope="module")
def page(tmp_path_factory) -> Path:
    """The page of a campaign analysed with two steps: identify and the toy analysis registered with one line
    (tests/analysis/toy_analysis.py), so that every run has two rows in the table."""
    from hilbench.analysis import protocol

    root = tmp_path_factory.mktemp("page")
    write_campaign(root / "bench1", SyntheticCampaign(runs=6, repeats=3, duration=2.0, seed=5), fail_runs=(4,))
    protocol.register("toy", "tests.analysis.toy_analysis")
    try:  # the page, like the steps, iterates the registry: the toy stays registered until it is written
        analyse([root / "bench1"], root / "results", ("identify", "toy"), serial=True, progress=False,
                say=lambda _l: None)
        assert main(["-q", "drift", str(root / "results")]) == 0  # every default: 5 runs analysed (issue #38)
    finally:
        protocol.ANALYSES.pop("toy")
        protocol._LOADED.pop("toy", None)
    return root / "results" / "drift" / "campaign-bench1.html"


def test_page_is_self_contained_and_holds_every_run(page):
    text = page.read_text()
    assert not re.search(r"""(src|href)\s*=\s*['"](?!data:)""", text), "every image and link is inline"
    assert "http://" not in text and "https://" not in text
    assert len(re.findall(r"<tr id='r\d+' class='run", text)) == 6
    assert text.count("<img alt='run ") == 6 and "no figure" not in text  # the failed run has its file too
    assert "class='run failed'" in text and "no position channel" in text  # the record loader's one line
    for fig in ("drift-breakaway", "charts-breakaway", "drift-viscous", "charts-viscous"):
        assert f"<img alt='{fig}' src='data:image/png;base64," in text


def test_the_page_has_a_section_per_step_in_the_table_with_its_exact_figures(page):
    """hilbench drift once gave the page the identify rows alone, so no other step's section ever reached it:
    each step analysed has its section, its cells keep the table's exact figure, and the runs table one row per
    run (above: 6, not 12)."""
    import pyarrow.parquet as pq

    text = page.read_text()
    assert "id='step-identify'" in text and "id='step-toy'" in text
    rows = {r["key"]: r for r in pq.read_table(page.parent.parent / "results.parquet").to_pylist()
            if r["step"] == "toy" and r["status"] == "ok"}
    section = text[text.index("id='step-toy'"):].split("</table>")[0]
    heads = re.findall(r"<th data-sort='1'[^>]*>([^<]*)</th>", section)
    column = next(i for i, h in enumerate(heads) if h.startswith("sliding distance"))
    shown = [re.findall(r"data-v='([^']*)'", tr) for tr in re.findall(r"<tr class='step-row'>(.*?)</tr>", section)]
    assert len(shown) == len(rows) == 5
    for cells in shown:
        assert float(cells[column]) == pytest.approx(rows[cells[0]]["sliding_distance"], rel=1e-12), cells[0]


def test_repeat_summary_is_mean_and_sample_std():
    rows = [{"name": "a", "status": "ok", "breakaway": v} for v in (1.0, 2.0, 4.0)]
    rows.append({"name": "a", "status": "failed", "breakaway": None})
    (s,) = repeat_summary(rows)
    assert s["n"] == 3 and s["breakaway"][0] == pytest.approx(7 / 3)
    assert s["breakaway"][1] == pytest.approx(((1 - 7 / 3) ** 2 + (2 - 7 / 3) ** 2 + (4 - 7 / 3) ** 2) ** 0.5 / 2**0.5)


def test_page_in_headless_chromium(page, tmp_path):
    browser = shutil.which("chromium")
    if browser is None:
        pytest.skip("chromium is not installed (Debian package chromium; `make chromium` installs it as root)")
    flags = [browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}", "--enable-logging=stderr",
             "--v=0", "--virtual-time-budget=3000"]
    dom = subprocess.run([*flags, "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120)
    assert dom.returncode == 0, dom.stderr[-2000:]
    # the page's script ran (it counts the rows) and caught no error; the console logged none
    assert "6 runs shown" in dom.stdout
    assert re.search(r"<pre id=\"js-errors\"></pre>", dom.stdout)
    console = [line for line in dom.stderr.splitlines() if "CONSOLE" in line or "Uncaught" in line]
    assert console == []
    shot = tmp_path / "page.png"
    run = subprocess.run([*flags, "--window-size=1280,1400", f"--screenshot={shot}", page.as_uri()],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and shot.stat().st_size > 20_000
