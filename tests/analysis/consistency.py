"""What the consistency tests of the analysis protocol share (tests/analysis/test_protocol*.py): the tolerance, the
campaign row of one run and one step, and the campaign page's cell of a row."""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq

from hilbench.bench.campaign_analysis.engine import analyse as analyse_campaign
from hilbench.bench.campaign_analysis.steps import StepSettings

#: the same figure everywhere: relative tolerance between consumers
RTOL = 1e-6
THRESHOLDS = 16
FRACTION = 0.3
quiet = {"progress": False, "say": lambda _line: None}


def campaign_row(folder: Path, out: Path, step: str, fraction: float) -> dict:
    settings = StepSettings(thresholds=THRESHOLDS, validation_fraction=fraction,
                            compare_families=("coulomb_viscous", "maxwell_slip"))
    s = analyse_campaign([folder], out, (step,), settings, serial=True, resume=False, **quiet)
    (row,) = pq.read_table(s.table).to_pylist()
    assert row["status"] == "ok", row["error"]
    return row


def page_cell(row: dict, column: str) -> tuple[float, str]:
    """(the exact value a campaign page's step section keeps for ``column`` of ``row``, the text it shows)."""
    import re

    from hilbench.bench.campaign_analysis.page import _header, step_sections

    page = "".join(step_sections([row], {}))
    section = page[page.index(f"id='step-{row['step']}'"):]
    heads = re.findall(r"<th data-sort='1'[^>]*>([^<]*)</th>", section.split("</thead>")[0])
    cells = re.findall(r"<td[^>]*data-v='([^']*)'>([^<]*)</td>", section.split("<tbody>")[1].split("</tr>")[0])
    value, text = cells[heads.index(_header(column, column.replace("_", " ").replace("nrmse", "NRMSE"), {}))]
    return float(value), text
