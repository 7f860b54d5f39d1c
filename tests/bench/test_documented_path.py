"""Issue #38: the path the README documents, plan -> campaign -> analyse -> drift, typed as a user types it (every
default: no option the README's path does not show), on the lockstep simulator, at 4, 10, 20 and 200 runs.

The run count comes from the obvious edit of plan's TOML, `repeats = N` under a run's `protocol` line. With the
default steps (identify) the identification and chirp runs get rows, and drift follows them as two series (one
per protocol). What the docs predict on the default simulator, a motor that does not change and has no noise:

- no alarm, no change point, no outlier in the identification series (its runs differ by their seeds);
- the chirp plays no seed, so its repeats are the same run bit for bit: its series is reported "not charted: no
  spread over the baseline runs (identical values)"; no alarm;
- a series of fewer than 3 runs (the 4-run campaign: one of each) is all baseline, "not charted", and the report
  and the page are written all the same;
- the baseline is the rule's (analysis.drift.monitor.default_baseline), written out here per size: half the runs,
  at most 50, at least 3.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import time
from html.parser import HTMLParser
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from hilbench.bench.cli import main

DEVICE = "sim://?pacing=lockstep"  # the simulated bench as fast as this machine computes it (README, Scripting)
SIX = "identify,compare,residual,presliding,afrf,skeleton"
PROTOCOLS = ("identification", "stepped_sine", "chirp", "presliding")  # plan's runs, in its TOML's order


def with_repeats(text: str, repeats: dict[str, int]) -> str:
    """Plan's TOML with `repeats = N` added under the `protocol` line of each named run (the obvious edit)."""
    def add(m: re.Match) -> str:
        n = repeats.get(m.group(1), 1)
        return m.group(0) + (f"\nrepeats = {n}" if n != 1 else "")

    edited = re.sub(r'^name = "([a-z_]+)"\nprotocol = "[a-z_]+"$', add, text, flags=re.M)
    assert edited.count("\nrepeats = ") == sum(n != 1 for n in repeats.values())
    return edited


def plan_campaign(folder: Path, repeats: dict[str, int], duration: str | None, monkeypatch) -> Path:
    """`hilbench plan`, the edit, `hilbench campaign plan.toml`, in ``folder`` (the current folder, as a user's):
    returns the campaign folder (plan's default name: the TOML's stem)."""
    folder.mkdir(parents=True, exist_ok=True)
    monkeypatch.chdir(folder)
    argv = ["-q", "plan", "--device", DEVICE] + (["--duration", duration] if duration else [])
    assert main(argv) == 0
    plan = Path("plan.toml")
    assert plan.is_file() and Path("plan-probe").is_dir()
    plan.write_text(with_repeats(plan.read_text(), repeats))
    assert main(["-q", "campaign", "plan.toml"]) == 0
    return folder / "plan"


def index_keys(campaign: Path) -> list[str]:
    runs = json.loads((campaign / "index.json").read_text())["runs"]
    assert all(r["status"] == "completed" for r in runs)
    return [r["key"] for r in runs]


#: size -> (repeats per planned run, plan's --duration or None for its default, identification runs, their
#: default baseline)
SIZES = {
    4: ({}, None, 1, 1),
    10: ({"identification": 4, "chirp": 4}, "2", 4, 3),
    20: (dict.fromkeys(PROTOCOLS, 5), "2", 5, 3),
    200: (dict.fromkeys(PROTOCOLS, 50), "2", 50, 25),
}


@pytest.mark.parametrize("size", [pytest.param(n, marks=pytest.mark.slow) if n >= 200 else n for n in SIZES])
def test_plan_campaign_analyse_drift_with_every_default(size, tmp_path, monkeypatch, capsys):
    repeats, duration, n_id, baseline = SIZES[size]
    started = time.perf_counter()
    campaign = plan_campaign(tmp_path, repeats, duration, monkeypatch)
    keys = index_keys(campaign)
    assert len(keys) == size
    n_chirp = sum(k.startswith("chirp-") for k in keys)
    assert n_chirp == n_id  # the chirp has as many repeats as the identification in every size here

    assert main(["-q", "analyse", "plan"]) == 0  # default: identify, a local cluster, plan/analysis
    rows = pq.read_table(campaign / "analysis" / "results.parquet").to_pylist()
    assert sorted(r["key"] for r in rows) == sorted(k for k in keys if k.startswith(("identification-", "chirp-")))
    assert [(r["key"], r["error"]) for r in rows if r["status"] != "ok"] == []
    assert {r["step"] for r in rows} == {"identify"}

    capsys.readouterr()
    assert main(["drift", "plan/analysis"]) == 0
    said = capsys.readouterr().out
    out = campaign / "analysis" / "drift"
    report = json.loads((out / "drift.json").read_text())
    groups = {g["group"]: g for g in report["groups"]}
    assert set(groups) == {"identification", "chirp"}
    ident, chirp = groups["identification"], groups["chirp"]
    # the stated baseline, in the report and in the line printed
    assert (ident["runs"], ident["baseline"]) == (n_id, baseline)
    assert f"identification: baseline: the first {baseline} of {n_id} runs" in said
    assert report["alarms"] == []  # a motor that does not change raises nothing
    if n_id < 3:  # too few runs for a spread: all baseline, reported, not charted
        for g in (ident, chirp):
            assert g["baseline"] == g["runs"] and set(g["unmonitored"]) == {
                f"{p} [{g['group']}]" for p in ("breakaway", "viscous")}
            assert all("too few to chart" in why for why in g["unmonitored"].values())
        assert report["parameters"] == {} and sorted(p.name for p in out.glob("*.png")) == []
    else:
        assert ident["unmonitored"] == {} and ident["monitoring_from"] == f"plan/identification-{baseline + 1}"
        for p in ("breakaway", "viscous"):
            series = report["parameters"][f"{p} [identification]"]
            assert series["outliers"] == [] and series["change_points"] == []
            assert series["sigma"] > 0
        assert all("no spread over the" in why and "(identical values); 0 later run(s) differ" in why
                   for why in chirp["unmonitored"].values())
        assert sorted(p.name for p in out.glob("*.png")) == [
            "charts-breakaway-identification.png", "charts-viscous-identification.png",
            "drift-breakaway-identification.png", "drift-viscous-identification.png"]

    page = (out / "campaign-plan.html").read_text()
    for key in keys:  # every run of the campaign is named (the plan), every analysed run has its row
        assert f">{key}<" in page
    assert len(re.findall(r"<tr id='r\d+' class='run", page)) == len(rows)
    assert f"identification: {ident['baseline_rule']}" in page
    print(f"{size} runs: {time.perf_counter() - started:.1f} s end to end")  # the report's figure (pytest -s)


# ---- all six steps on a planned campaign with repeats on every run; its page in headless Chromium -----------------

REPEATS_10 = {"identification": 3, "stepped_sine": 2, "chirp": 3, "presliding": 2}  # 10 runs


@pytest.fixture(scope="module")
def campaign10(tmp_path_factory) -> Path:
    mp = pytest.MonkeyPatch()
    try:
        return plan_campaign(tmp_path_factory.mktemp("six"), REPEATS_10, "2", mp)
    finally:
        mp.undo()


#: the steps each of plan's protocols supports (docs/campaign-analysis.md, the table of steps)
STEPS_OF = {"identification": {"identify", "compare", "residual"},
            "chirp": {"identify", "compare", "residual", "skeleton"},
            "stepped_sine": {"afrf"}, "presliding": {"presliding"}}


def test_a_planned_campaign_with_repeats_on_every_run_has_no_failed_row_with_all_six_steps(campaign10, tmp_path):
    assert main(["-q", "analyse", str(campaign10), "--steps", SIX, "-o", str(tmp_path / "six")]) == 0
    rows = pq.read_table(tmp_path / "six" / "results.parquet").to_pylist()
    assert [(r["key"], r["step"], r["error"]) for r in rows if r["status"] != "ok"] == []
    expected = {(k, s) for k in index_keys(campaign10) for s in STEPS_OF[k.rsplit("-", 1)[0]]}
    assert {(r["key"], r["step"]) for r in rows} == expected
    assert len(rows) == 3 * 3 + 2 * 1 + 3 * 4 + 2 * 1  # every step of every run, every repeat


class _Dom(HTMLParser):
    """The rendered page's rows and step headings, with the attributes the probe script wrote."""

    def __init__(self) -> None:
        super().__init__()
        self.rows: list[dict] = []
        self.headings: list[dict] = []
        self._cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "tr":
            self.rows.append({**a, "cells": []})
        elif tag in ("td", "th") and self.rows:
            self._cell = []
        elif tag == "h3" and (a.get("id") or "").startswith("step-"):
            self.headings.append(a)

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.rows[-1]["cells"].append("".join(self._cell).strip())
            self._cell = None


#: appended to a copy of the page: writes what Chromium rendered into the DOM (a failed row's background colour,
#: whether a section's heading takes space on the page) so that --dump-dom carries it out
PROBE = """<script>
document.addEventListener('DOMContentLoaded', function () { setTimeout(function () {
  document.querySelectorAll('tr.failed').forEach(function (tr) {
    tr.setAttribute('data-bg', getComputedStyle(tr.cells[0]).backgroundColor); });
  document.querySelectorAll('h3[id^="step-"]').forEach(function (h) {
    h.setAttribute('data-shown', h.offsetHeight > 0 ? 'yes' : 'no'); });
}, 0); });
</script>"""


def test_the_page_in_headless_chromium_shows_every_step_and_every_failed_row_in_red(campaign10, tmp_path):
    browser = shutil.which("chromium")
    if browser is None:
        pytest.skip("chromium is not installed (Debian package chromium; `make chromium` installs it as root)")
    from tests.bench.campaign_analysis.test_page import CHROMIUM_FLAGS

    planted = tmp_path / "planted"
    shutil.copytree(campaign10, planted, ignore=shutil.ignore_patterns("analysis"))
    chirp = planted / "chirp-2.h5"  # a run file cut short (a copy interrupted)
    chirp.write_bytes(chirp.read_bytes()[: chirp.stat().st_size // 3])
    shutil.copyfile(planted / "presliding-1.h5", planted / "stepped_sine-2.h5")  # another run's file in its place
    assert main(["-q", "analyse", str(planted), "--steps", SIX]) == 0
    assert main(["-q", "drift", str(planted / "analysis")]) == 0
    page = planted / "analysis" / "drift" / "campaign-planted.html"
    probe = tmp_path / "probe.html"
    probe.write_text(page.read_text().replace("</body>", PROBE + "</body>"))
    flags = [browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}", "--enable-logging=stderr", "--v=0",
             "--virtual-time-budget=3000"]
    dom = subprocess.run([*flags, "--dump-dom", probe.as_uri()], capture_output=True, text=True, timeout=120)
    assert dom.returncode == 0, dom.stderr[-2000:]
    parsed = _Dom()
    parsed.feed(dom.stdout)

    table = {(r["key"], r["step"]): r for r in pq.read_table(planted / "analysis" / "results.parquet").to_pylist()}
    failed = {k: r for k, r in table.items() if r["status"] != "ok"}
    assert set(failed) == {("chirp-2", s) for s in STEPS_OF["chirp"]} | {("stepped_sine-2", "afrf")}
    # a section for every step run, shown
    assert {h["id"]: h.get("data-shown") for h in parsed.headings} == {
        f"step-{s}": "yes" for s in ("identify", "compare", "residual", "presliding", "afrf", "skeleton")}
    # every failed row in red with its reason: the step tables' rows and the runs table's
    red = [r for r in parsed.rows if "failed" in (r.get("class") or "").split()]
    assert red and all(r.get("data-bg") == "rgb(255, 221, 221)" for r in red)  # #fdd
    step_rows = [r for r in red if "step-row" in r["class"]]
    assert sorted(r["cells"][0] for r in step_rows) == sorted(k for k, _ in failed)
    for r in step_rows:
        reason = r["cells"][-1]
        assert r["cells"][2] == "failed" and reason
        assert reason in {failed[(r["cells"][0], s)]["error"] for s in ("identify", "compare", "residual",
                                                                       "skeleton", "afrf")
                          if (r["cells"][0], s) in failed}
    assert any("uid" in r["cells"][-1] for r in step_rows if r["cells"][0] == "stepped_sine-2")
    runs = {r["cells"][0]: r for r in red if "run" in r["class"].split()}
    assert set(runs) == {"chirp-2", "stepped_sine-2"}
    assert runs["chirp-2"]["cells"][-1].startswith("identify: ") and "afrf: " in runs["stepped_sine-2"]["cells"][-1]
    console = [line for line in dom.stderr.splitlines() if "CONSOLE" in line or "Uncaught" in line]
    assert console == []
