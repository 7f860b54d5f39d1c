"""One self-contained HTML page per campaign: the plan, a sortable table of its runs, the mean +- std over
repeats, the drift figures, and each run's own figure one click away. No server, no network: CSS and JS are
inline and every image is a data URI, so the file can be mailed or archived as it is."""

from __future__ import annotations

import base64
import html
import io
import json
import math
import re
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from hilbench.bench.storage import outputs
from hilbench.common.metrics import UNIT, is_fraction, label, percent
from hilbench.common.units import EFFORT, rows_axis

#: (column, header) of the runs table; a parameter is shown with its standard error
RUN_COLUMNS = [("key", "run"), ("repeat", "repeat"), ("start_time", "start (UTC)"), ("status", "status"),
               ("inertia", "inertia J"), ("breakaway", "break-away torque"), ("viscous", "viscous coefficient b"),
               ("validation_torque_nrmse", label("validation")), ("verdict", "verdict"),
               ("temperature_mean", "temperature"), ("error", "reason")]
SUMMARY_PARAMETERS = ("inertia", "breakaway", "viscous", "validation_torque_nrmse")
HEADERS = dict(RUN_COLUMNS)

CSS = """
body{font-family:sans-serif;margin:1.5em;color:#222}
table{border-collapse:collapse;font-size:13px;margin:0.5em 0}
th,td{border:1px solid #ccc;padding:3px 6px;text-align:right}
th{background:#eee;cursor:pointer;user-select:none}
td.t,th.t{text-align:left}
tr.failed td{background:#fdd}
tr.fig td{background:#fafafa;text-align:left}
a.run{cursor:pointer;color:#05c;text-decoration:underline}
img{max-width:100%}
#js-errors{color:#b00}
"""

JS = """
var jsErrors = [];
window.onerror = function (msg) { jsErrors.push(String(msg));
  document.getElementById('js-errors').textContent = jsErrors.join('\\n'); };
function sortTable(th) {
  var table = th.closest('table'), body = table.tBodies[0], col = th.cellIndex;
  var asc = th.getAttribute('data-asc') !== '1';
  th.setAttribute('data-asc', asc ? '1' : '0');
  var rows = Array.prototype.filter.call(body.rows, function (r) { return !r.classList.contains('fig'); });
  rows.sort(function (a, b) {
    var x = a.cells[col].getAttribute('data-v'), y = b.cells[col].getAttribute('data-v');
    var nx = parseFloat(x), ny = parseFloat(y);
    var c = (!isNaN(nx) && !isNaN(ny)) ? nx - ny : String(x).localeCompare(String(y));
    return asc ? c : -c; });
  rows.forEach(function (r) { body.appendChild(r);
    var f = document.getElementById('fig-' + r.id); if (f) { body.appendChild(f); } });
}
function toggle(id) { var f = document.getElementById('fig-' + id);
  f.style.display = f.style.display === 'none' ? '' : 'none'; }
document.addEventListener('DOMContentLoaded', function () {
  document.querySelectorAll('th[data-sort]').forEach(function (th) {
    th.addEventListener('click', function () { sortTable(th); }); });
  document.getElementById('runs-shown').textContent =
    document.querySelectorAll('#runs tbody tr.run').length + ' runs shown';
});
"""


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=72)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def _file_png(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode()


def _fmt(v: Any, se: Any = None, col: str = "") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    if is_fraction(col) and isinstance(v, int | float):  # an error figure: text shows percent (docs/metrics.md)
        v, se = percent(v), percent(se) if isinstance(se, int | float) else se
    if isinstance(v, float):
        return f"{v:.4g}" + (f" &plusmn; {se:.2g}" if isinstance(se, float) and math.isfinite(se) else "")
    return html.escape(str(v))


def _header(col: str, head: str, units: dict[str, str], axis: str = "rotary") -> str:
    head = head.replace("torque", EFFORT[axis]) if col == "breakaway" else head
    unit = UNIT if is_fraction(col) else units.get(col, "")
    return f"{head} ({unit})" if unit and unit != "1" and col != "start_time" else head


def run_figure(path: Path) -> str | None:
    """The run's torque and position against time as a data URI (None when the file cannot be read)."""
    import matplotlib.pyplot as plt

    from hilbench.common.runfile import open_run

    try:
        with open_run(path) as run:
            t = run.channel("t")
            chans = {c: run.channel(c) for c in ("torque", "position") if c in run.channels}
            units = {c: run.units[c] for c in chans}
    except Exception:  # a damaged or missing file: the row says why; the page goes on
        return None
    fig, axes = plt.subplots(len(chans) or 1, 1, figsize=(7, 3.2), sharex=True, squeeze=False)
    for ax, (c, v) in zip(axes[:, 0], chans.items(), strict=False):
        ax.plot(t, v, lw=0.6)
        ax.set_ylabel(f"{c} ({units[c]})")
    axes[-1, 0].set_xlabel("t (s)")
    fig.tight_layout()
    uri = _png(fig)
    plt.close(fig)
    return uri


def _natural(text: str) -> list:
    """Sort key that puts id2 before id10."""
    return [(0, int(t), "") if t.isdigit() else (1, 0, t) for t in re.split(r"(\d+)", text)]


def repeat_summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Mean and sample standard deviation of each parameter over the repeats of each planned run (ok rows)."""
    groups: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        if r.get("status") == "ok":
            groups[str(r.get("name"))].append(r)
    out = []
    for name, rs in sorted(groups.items(), key=lambda g: _natural(g[0])):
        entry: dict[str, Any] = {"name": name, "n": len(rs)}
        for p in SUMMARY_PARAMETERS:
            v = np.array([r[p] for r in rs if r.get(p) is not None], dtype=float)
            entry[p] = (float(v.mean()) if v.size else math.nan, float(v.std(ddof=1)) if v.size > 1 else math.nan)
        out.append(entry)
    return out


def runs_of(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per run of the campaign from its rows of every step: the run's identify row (its parameters) when it
    has one, else its first row; ``failed`` when any of its steps failed, with each failed step's reason
    (``step: reason``), so a run whose protocol no identify step reads (stepped sine, presliding) is in the
    table too."""
    from hilbench.analysis.protocol import ANALYSES

    order = {name: i for i, name in enumerate(ANALYSES)}
    by_run: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        by_run[str(r.get("key"))].append(r)
    out = []
    for rs in by_run.values():
        own = next((r for r in rs if r.get("step") in ("identify", None)), rs[0])
        bad = sorted((r for r in rs if r.get("status") != "ok"), key=lambda r: order.get(str(r.get("step")), 99))
        if bad and all(r.get("step") for r in bad):
            own = {**own, "status": bad[0].get("status"),
                   "error": "; ".join(f"{r.get('step')}: {r.get('error')}" for r in bad)}
        out.append(own)
    return out


def step_sections(rows: list[dict[str, Any]], units: dict[str, str], axis: str = "rotary") -> list[str]:
    """One section per analysis of the registry (hilbench.analysis.protocol.ANALYSES) that has rows in the table,
    in the registry's order: its title, then a sortable table of its rows (run, repeat, status, the entry's
    columns with their units, the reason of a failure). An NRMSE reads in percent; its cell's ``data-v`` keeps the
    table's exact value (the fraction), which the sorting reads."""
    from hilbench.analysis.protocol import ANALYSES, entry

    e = html.escape
    present = {str(r.get("step")) for r in rows}
    parts = []
    for name in ANALYSES:
        if name not in present:
            continue
        analysis = entry(name)
        mine = [r for r in rows if r.get("step") == name]
        columns = [c for c in analysis.columns if any(r.get(c) is not None for r in mine)]
        parts.append(f"<h3 id='step-{e(name)}'>{e(analysis.title)} ({e(name)}): {len(mine)} rows, "
                     f"{sum(r.get('status') == 'ok' for r in mine)} ok</h3><table class='step'><thead><tr>"
                     "<th data-sort='1' class='t'>run</th><th data-sort='1'>repeat</th>"
                     "<th data-sort='1' class='t'>status</th>")
        for c in columns:
            head = c.replace("_", " ").replace("nrmse", "NRMSE")
            parts.append(f"<th data-sort='1'>{e(_header(c, head, units, axis))}</th>")
        parts.append("<th data-sort='1' class='t'>reason</th></tr></thead><tbody>")
        for r in mine:
            cls = "step-row" + (" failed" if r.get("status") != "ok" else "")
            cells = [f"<td class='t' data-v='{e(str(r.get('key')))}'>{e(str(r.get('key')))}</td>",
                     f"<td data-v='{e(str(r.get('repeat')))}'>{_fmt(r.get('repeat'))}</td>",
                     f"<td class='t' data-v='{e(str(r.get('status')))}'>{_fmt(r.get('status'))}</td>"]
            cells += [f"<td data-v='{e(repr(r.get(c)))}'>{_fmt(r.get(c), r.get(f'{c}_se'), c)}</td>"
                      for c in columns]
            cells.append(f"<td class='t'>{_fmt(r.get('error'))}</td>")
            parts.append(f"<tr class='{cls}'>{''.join(cells)}</tr>")
        parts.append("</tbody></table>")
    return parts


def campaign_page(campaign: str, rows: list[dict[str, Any]], units: dict[str, str], drift_pngs: list[Path],
                  summary: dict[str, Any] | None, axis: str = "rotary") -> str:
    """The HTML text of one campaign's page (``rows``: its rows of every step; ``axis``: the runs' axis, which names
    the break-away torque/force)."""
    every = sorted(rows, key=lambda r: (str(r.get("start_time")), str(r.get("key"))))
    rows = runs_of(every)
    folder = Path(rows[0]["folder"]) if rows and rows[0].get("folder") else None
    plan = []
    if folder is not None and (folder / "index.json").is_file():
        try:
            plan = json.loads((folder / "index.json").read_text()).get("runs", [])
        except ValueError:
            plan = []
    e = html.escape
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>campaign {e(campaign)}</title>",
             f"<style>{CSS}</style><script>{JS}</script></head><body>",
             f"<h1>Campaign {e(campaign)}</h1><pre id='js-errors'></pre>",
             f"<p>{len(rows)} analysed runs, {sum(r.get('status') == 'ok' for r in rows)} ok "
             f"({len(every)} analyses, {sum(r.get('status') == 'ok' for r in every)} ok); "
             f"folder {e(folder.name) if folder else '?'}</p>"]
    parts.append(f"<h2>Plan</h2><details><summary>{len(plan)} planned runs</summary><table><thead><tr>"
                 "<th class='t'>run</th><th class='t'>protocol</th>"
                 "<th class='t'>status</th><th class='t'>parameters</th><th class='t'>environment</th></tr>"
                 "</thead><tbody>")
    for p in plan:
        parts.append(f"<tr><td class='t'>{e(str(p.get('key')))}</td><td class='t'>{e(str(p.get('protocol')))}</td>"
                     f"<td class='t'>{e(str(p.get('status')))}</td>"
                     f"<td class='t'>{e(json.dumps(p.get('parameters', {})))}</td>"
                     f"<td class='t'>{e(json.dumps(p.get('environment', {})))}</td></tr>")
    parts.append("</tbody></table></details>")
    parts.append("<h2>Runs</h2><p>Click a column to sort, a run to show its figure. <span id='runs-shown'></span></p>"
                 "<table id='runs'><thead><tr>")
    for col, head in RUN_COLUMNS:
        cls = " class='t'" if col in ("key", "start_time", "status", "verdict", "error") else ""
        parts.append(f"<th data-sort='1'{cls}>{e(_header(col, head, units, axis))}</th>")
    parts.append("</tr></thead><tbody>")
    for i, r in enumerate(rows):
        rid = f"r{i}"
        cls = "run" + (" failed" if r.get("status") != "ok" else "")
        cells = []
        for col, _ in RUN_COLUMNS:
            v = r.get(col)
            sort_value = "" if v is None else str(v)
            text = _fmt(v, r.get(f"{col}_se"), col)
            if col == "key":
                text = f"<a class='run' onclick=\"toggle('{rid}')\">{e(str(v))}</a>"
            left = " class='t'" if col in ("key", "start_time", "status", "verdict", "error") else ""
            cells.append(f"<td{left} data-v='{e(sort_value)}'>{text}</td>")
        parts.append(f"<tr id='{rid}' class='{cls}'>{''.join(cells)}</tr>")
        uri = run_figure(Path(r["folder"]) / r["file"]) if r.get("folder") and r.get("file") else None
        body = f"<img alt='run {e(str(r.get('key')))}' src='{uri}'>" if uri else "no figure (file unreadable)"
        parts.append(f"<tr id='fig-{rid}' class='fig' style='display:none'><td colspan='{len(RUN_COLUMNS)}'>"
                     f"{body}</td></tr>")
    parts.append("</tbody></table>")
    sections = step_sections(every, units, axis)
    if sections:
        parts.append("<h2>Analyses</h2><p>One section per analysis step in the table (the analysis registry's "
                     "order); click a column to sort.</p>")
        parts += sections
    parts.append("<h2>Mean &plusmn; standard deviation over repeats</h2><details open><summary>per planned run"
                 "</summary><table><thead><tr><th class='t'>run</th>"
                 "<th>repeats</th>" + "".join(f"<th>{e(_header(p, HEADERS[p], units, axis))}</th>"
                                              for p in SUMMARY_PARAMETERS) + "</tr></thead><tbody>")
    for s in repeat_summary([r for r in every if r.get("step") in ("identify", None)]):
        parts.append(f"<tr><td class='t'>{e(s['name'])}</td><td>{s['n']}</td>" + "".join(
            f"<td>{_fmt(s[p][0], s[p][1], p)}</td>" for p in SUMMARY_PARAMETERS) + "</tr>")
    parts.append("</tbody></table></details>")
    if drift_pngs or summary is not None:
        parts.append("<h2>Drift</h2>")
        if summary is not None:
            parts.append(f"<p>{len(summary.get('alarms', []))} alarm(s) over {summary.get('runs')} runs "
                         f"(all campaigns of the results table); baseline: {len(summary.get('baseline', []))} "
                         "runs.</p><ul class='series'>")
            parts += [f"<li>{e(g.get('group', ''))}: {e(g.get('baseline_rule', ''))}</li>"
                      for g in summary.get("groups", [])]
            parts.append("</ul>")
        for p in drift_pngs:
            parts.append(f"<h3>{e(p.stem)}</h3><img alt='{e(p.stem)}' src='{_file_png(p)}'>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_pages(rows: list[dict[str, Any]], units: dict[str, dict[str, str]], drift_pngs: list[Path],
                summary: dict[str, Any] | None, out: Path) -> list[Path]:
    """``out/campaign-<name>.html`` for every campaign in ``rows``. ``units``: axis (``rotary``, ``linear``) ->
    column -> unit, as the results table's metadata reads on that axis (hilbench.common.units.schema_units); each
    page shows the units of its runs' axis."""
    by_campaign: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        by_campaign[str(r.get("campaign"))].append(r)
    paths = []
    for campaign, rs in sorted(by_campaign.items()):
        path = out / f"campaign-{campaign}.html"
        axis = rows_axis(rs)
        outputs.write_text(path, campaign_page(campaign, rs, units[axis], drift_pngs, summary, axis))
        paths.append(path)
    return paths
