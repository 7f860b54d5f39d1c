"""Chaos: ``hilbench analyse`` killed with -9 at random points, two analyses at once, a swapped run file, a copied and a
renamed campaign, a leftover temp file and a truncated table, all on one results folder. Every run ends with exactly
one current row, nothing analysed is lost, nothing hangs.

The analyses are forked from this process (no interpreter start-up: 40 kills take seconds) and run serially with a
step that takes a few milliseconds and reports the file's size (the numbers of the identification are not the
point here; test_analyse.py checks them)."""

import json
import os
import shutil
import signal
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from hilbench.bench.campaign_analysis.engine import analyse
from hilbench.bench.campaign_analysis.steps import StepSettings
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign
from hilbench.bench.campaign_analysis.table import SLOT, TABLE_NAME
from hilbench.bench.errors import AnalyseError

pytestmark = pytest.mark.device_free


def slow(path: str, settings: StepSettings) -> dict:
    time.sleep(0.01)
    return {"samples": os.path.getsize(path)}


def _run(folders: list[Path], out: Path, thresholds: int = 32) -> None:
    analyse(folders, out, ("identify",), StepSettings(thresholds=thresholds), serial=True, progress=False,
            say=lambda _line: None, functions={"identify": slow})


def _fork(folders: list[Path], out: Path, thresholds: int = 32) -> int:
    pid = os.fork()
    if pid == 0:  # the child: one analysis, then out without running the parent's exit handlers
        code = 0
        try:
            _run(folders, out, thresholds)
        except AnalyseError:
            code = 2
        except BaseException:  # noqa: BLE001 -- any other end is a failure the parent sees
            code = 1
        os._exit(code)
    return pid


def _wait(pid: int, timeout: float = 60) -> int | None:
    """The child's exit code, or None when it was killed by a signal; fails the test on a hang."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status) if os.WIFEXITED(status) else None
        time.sleep(0.005)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    pytest.fail("an analysis hung")


def _current(out: Path) -> list[dict]:
    return pq.read_table(out / TABLE_NAME).to_pylist()


def _one_row_per_slot(rows: list[dict]) -> None:
    slots = [tuple(r[k] for k in SLOT) for r in rows]
    assert len(slots) == len(set(slots)), "two rows of one run and step"


@pytest.fixture
def campaign(tmp_path) -> Path:
    folder = tmp_path / "c"
    write_campaign(folder, SyntheticCampaign(runs=6, duration=0.3, seed=17))
    return folder


def test_two_analyses_at_once_one_refused_no_row_lost(campaign, tmp_path):
    out = tmp_path / "r"
    pids = [_fork([campaign], out), _fork([campaign], out)]
    codes = sorted(_wait(p) for p in pids)
    assert codes == [0, 2]  # the second is refused in one line (the first holds the folder's lock)
    rows = _current(out)
    assert len(rows) == 6 and {r["status"] for r in rows} == {"ok"}


def test_kill_9_at_random_points_and_every_hostile_change_end_with_one_current_row_per_run(campaign, tmp_path):
    rng = np.random.default_rng(41)
    out = tmp_path / "r"
    t0 = time.monotonic()
    assert _wait(_fork([campaign], tmp_path / "timing")) == 0
    span = time.monotonic() - t0  # one whole analysis: kills land anywhere in it
    folders = [campaign]
    index = {e["key"]: e for e in json.loads((campaign / "index.json").read_text())["runs"]}
    kills = 0
    for attempt in range(100):  # 40 tries at least, and on until 30 of them were kills (a load change shifts them)
        if attempt >= 40 and kills >= 30:
            break
        if attempt == 8:  # swap two run files: their rows must become failed rows, not each other's numbers
            os.replace(campaign / "id1-1.h5", tmp_path / "swap.h5")
            os.replace(campaign / "id2-1.h5", campaign / "id1-1.h5")
            os.replace(tmp_path / "swap.h5", campaign / "id2-1.h5")
        elif attempt == 16:  # a copy of the campaign analysed beside it: its rows reused, not doubled
            shutil.copytree(campaign, tmp_path / "copy")
            folders = [campaign, tmp_path / "copy"]
        elif attempt == 22:
            (tmp_path / "copy").rename(tmp_path / "renamed")
            folders = [campaign, tmp_path / "renamed"]
        elif attempt == 28:  # a temp file as a killed write leaves it
            (out / f".{TABLE_NAME}.0badc0de.tmp").write_bytes(b"PAR1")
        elif attempt == 34 and (out / TABLE_NAME).exists():
            table = out / TABLE_NAME
            table.write_bytes(table.read_bytes()[:100])
        # the setting changes every other try, so that each has its runs to (re)analyse and the kill lands in work
        pids = [_fork(folders, out, 32 - attempt // 2 % 2) for _ in range(2 if attempt % 3 == 0 else 1)]
        for pid in pids:
            time.sleep(rng.uniform(0, 0.8 * span / len(pids)))
            os.kill(pid, signal.SIGKILL)
        for pid in pids:
            code = _wait(pid)
            kills += code is None
            assert code in (None, 0, 2)  # killed, done, or refused while the other held the lock
        if (out / TABLE_NAME).exists() and attempt != 34:  # a table there is a whole one (or the one we cut)
            _one_row_per_slot(_current(out))
    assert kills >= 30
    _run(folders, out)  # the last one runs to the end
    rows = _current(out)
    _one_row_per_slot(rows)
    by_key = {r["key"]: r for r in rows}
    assert len(rows) == 6 and set(by_key) == set(index)
    for key in ("id1-1", "id2-1"):  # swapped: failed, naming the uids
        assert by_key[key]["status"] == "failed" and index[key]["uid"] in by_key[key]["error"]
    for key in set(index) - {"id1-1", "id2-1"}:
        assert by_key[key]["status"] == "ok" and by_key[key]["samples"] == os.path.getsize(campaign / f"{key}.h5")
    assert not list(out.rglob("*.tmp")) and not (out / "parts").exists()
    # nothing lost: a fresh analysis of the same folders gives the same rows
    fresh = tmp_path / "fresh"
    _run(folders, fresh)
    strip = ("file_stat", "folder", "campaign")
    assert sorted(({k: v for k, v in r.items() if k not in strip} for r in _current(fresh)), key=str) == sorted(
        ({k: v for k, v in r.items() if k not in strip} for r in rows), key=str)
