"""What the consistency tests of the analysis protocol share (tests/analysis/test_protocol*.py): the tolerance, the
campaign row of one run and one step, and the campaign page's cell of a row."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from hilbench.bench.campaign_analysis.engine import analyse as analyse_campaign
from hilbench.bench.campaign_analysis.steps import StepSettings

#: the same figure everywhere: relative tolerance between consumers
RTOL = 1e-6
THRESHOLDS = 16
FRACTION = 0.3
quiet = {"progress": False, "say": lambda _line: None}


def one_run_campaign(folder: Path, file: str, protocol_name: str, key: str = "a") -> None:
    """``folder`` (made here if missing) as a campaign of one completed run ``file`` of protocol ``protocol_name``."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "index.json").write_text(json.dumps({"runs": [{"key": key, "file": file, "status": "completed",
                                                             "protocol": protocol_name}]}))


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


#: the device sample rates every consistency test runs at (Hz), and the pytest ids of those and the host-clocked case
RATES = (2000.0, 10000.0, 20000.0)
CLOCKS = [(rate, False) for rate in RATES] + [(RATES[0], True)]
CLOCK_IDS = ["2kHz", "10kHz", "20kHz", "host-clocked"]


def clocked(channels: tuple[str, ...], data: dict, fs: float, host: bool) -> tuple[tuple[str, ...], dict, dict]:
    """(channels, data, RunWriter keywords) of a run as a device-clocked device writes it (unchanged), or as a
    host-clocked drive writes it (``host``): the same samples taken at host times jittered by +-0.2 sample
    (a ``host_time`` channel and ``sample_times = host_time``), which the one loader resamples onto the grid."""
    if not host:
        return channels, data, {}
    n = len(next(iter(data.values())))
    jitter = np.random.default_rng(7).uniform(-0.2, 0.2, n) / fs
    return ((*channels, "host_time"), {**data, "host_time": 50.0 + np.arange(n) / fs + jitter},
            {"device": {"protocol": "CiA 402 over CANopen", "sample_times": "host_time"}})
