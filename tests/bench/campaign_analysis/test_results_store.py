"""The results store of ``hilbench analyse`` as safe as the run file (issue 41): one writer per results folder, rows
keyed by identity (campaign uid, run uid, content hash), durable and self-healing, every input checked before work.

Each test names a way the store lost, mixed or blocked rows before; the analyses here are serial, with a fast
step where the numbers do not matter (the identification itself is tested in test_analyse.py)."""

import json
import os
import shutil
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from hilbench.bench.campaign_analysis.engine import analyse, execute_chunk
from hilbench.bench.campaign_analysis.steps import StepSettings
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign
from hilbench.bench.campaign_analysis.table import LOCK_NAME, TABLE_NAME
from hilbench.bench.cli import main
from hilbench.bench.errors import AnalyseError
from hilbench.bench.storage.folder_lock import folder_lock

pytestmark = pytest.mark.device_free


def fast(path: str, settings: StepSettings) -> dict:
    """A step of no numerical interest and no cost: the file's size as its "samples"."""
    return {"samples": os.path.getsize(path)}


FAST = {"identify": fast}


def _analyse(folders, out, **kw):
    said: list[str] = []
    s = analyse(list(folders), out, serial=True, progress=False, say=said.append, functions=FAST, **kw)
    return s, said


def _rows(out: Path) -> list[dict]:
    return pq.read_table(out / TABLE_NAME).to_pylist()


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("made") / "c"
    write_campaign(folder, SyntheticCampaign(runs=6, duration=0.3, seed=5))
    return folder


@pytest.fixture
def campaign(made, tmp_path) -> Path:
    copy = tmp_path / "c"
    shutil.copytree(made, copy)
    return copy


def _index(folder: Path) -> dict:
    return json.loads((folder / "index.json").read_text())


# -- one writer at a time ------------------------------------------------------------------------------------------

def test_a_second_analysis_of_one_results_folder_is_refused_naming_the_holder(campaign, tmp_path, capsys):
    out = tmp_path / "r"
    out.mkdir()
    with folder_lock(out, LOCK_NAME, AnalyseError, str):  # another analysis holds the folder
        t0 = time.monotonic()
        assert main(["analyse", str(campaign), "-o", str(out), "--serial"]) == 2
        assert time.monotonic() - t0 < 30
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"pid {os.getpid()}" in err and "another analysis" in err
    assert not (out / TABLE_NAME).exists()  # nothing written by the refused one


def test_a_dead_holders_lock_is_taken_over_saying_so(campaign, tmp_path):
    out = tmp_path / "r"
    out.mkdir()
    (out / LOCK_NAME).write_text("4194999\n")  # left by an analysis killed with -9: no flock on it any more
    s, said = _analyse([campaign], out)
    assert s.analysed == 6 and any("taking over the lock of pid 4194999" in line for line in said)
    assert not (out / LOCK_NAME).exists()


# -- rows keyed by identity ----------------------------------------------------------------------------------------

def test_every_campaign_gets_a_uid_on_first_use_and_keeps_it(campaign, tmp_path):
    assert "uid" not in _index(campaign)  # written as an older hilbench wrote its index
    _analyse([campaign], tmp_path / "r")
    uid = _index(campaign)["uid"]
    _analyse([campaign], tmp_path / "r2")
    assert _index(campaign)["uid"] == uid and {r["campaign_uid"] for r in _rows(tmp_path / "r")} == {uid}


def test_two_campaigns_of_one_folder_name_keep_their_own_rows(made, tmp_path):
    a, b = tmp_path / "a" / "c", tmp_path / "b" / "c"
    shutil.copytree(made, a)
    write_campaign(b, SyntheticCampaign(runs=4, duration=0.3, seed=9))
    out = tmp_path / "r"
    _analyse([a], out)
    _analyse([b], out)  # replaced a's rows before: rows were keyed by the folder's name
    rows = _rows(out)
    assert len(rows) == 10 and {r["folder"] for r in rows} == {str(a), str(b)}
    s, _ = _analyse([a, b], out)  # both at once, too (refused before: "two folders named 'c'")
    assert (s.analysed, s.skipped, len(_rows(out))) == (0, 10, 10)


def test_a_copied_and_a_renamed_campaign_reuse_their_rows(campaign, tmp_path):
    out = tmp_path / "r"
    _analyse([campaign], out)
    copy = tmp_path / "copy"
    shutil.copytree(campaign, copy)  # the same campaign (its uid), another folder
    s, _ = _analyse([campaign, copy], out)
    assert (s.analysed, len(_rows(out))) == (0, 6)  # neither analysed again nor duplicated (12 rows before)
    renamed = tmp_path / "renamed"
    copy.rename(renamed)
    s, _ = _analyse([renamed], out)
    rows = _rows(out)
    assert (s.analysed, len(rows)) == (0, 6) and {r["folder"] for r in rows} == {str(renamed)}
    assert {r["campaign"] for r in rows} == {"renamed"}  # reused rows say where the campaign is now


def test_a_swapped_run_file_is_a_failed_row_naming_both_uids(campaign, tmp_path):
    out = tmp_path / "r"
    _analyse([campaign], out)
    index = {e["key"]: e for e in _index(campaign)["runs"]}
    os.replace(campaign / "id2-1.h5", campaign / "id1-1.h5")  # run 2's file under run 1's entry
    _analyse([campaign], out)
    rows = {r["key"]: r for r in _rows(out)}
    bad = rows["id1-1"]
    assert bad["status"] == "failed" and index["id2-1"]["uid"] in bad["error"] and index["id1-1"]["uid"] in bad["error"]
    assert bad["run_id"] == index["id1-1"]["uid"] and rows["id2-1"]["status"] == "not run" and len(rows) == 6


def test_unplanned_runs_are_skipped_and_their_rows_dropped(campaign, tmp_path):
    out = tmp_path / "r"
    _analyse([campaign], out)
    doc = _index(campaign)
    for e in doc["runs"][4:]:
        e["planned"] = False  # as `campaign --resume` marks the runs a smaller plan no longer has
    (campaign / "index.json").write_text(json.dumps(doc))
    s, _ = _analyse([campaign], out)
    assert s.total == 4 and sorted(r["key"] for r in _rows(out)) == ["id1-1", "id2-1", "id3-1", "id4-1"]


# -- durable and self-healing --------------------------------------------------------------------------------------

def test_leftover_temp_files_of_a_killed_write_are_cleaned(campaign, tmp_path):
    out = tmp_path / "r"
    (out / "parts").mkdir(parents=True)
    (out / "parts" / ".abc-1.parquet.1234abcd.tmp").write_bytes(b"PAR1 half a part")
    (out / f".{TABLE_NAME}.9876fedc.tmp").write_bytes(b"PAR1")
    s, _ = _analyse([campaign], out)  # every later analyse ended in "Directory not empty" before
    assert s.analysed == 6 and len(_rows(out)) == 6
    assert not list(out.rglob("*.tmp")) and not (out / "parts").exists()


@pytest.mark.parametrize("damage", ["zero-byte", "truncated", "garbage"])
def test_an_unreadable_table_or_part_is_set_aside_and_its_rows_redone(campaign, tmp_path, damage):
    out = tmp_path / "r"
    _analyse([campaign], out)
    table = out / TABLE_NAME
    data = table.read_bytes()
    broken = {"zero-byte": b"", "truncated": data[:len(data) // 2], "garbage": b"x" * 100}[damage]
    table.write_bytes(broken)
    (out / "parts").mkdir()
    (out / "parts" / "0123-1.parquet").write_bytes(broken)
    s, said = _analyse([campaign], out, resume=False)  # --no-resume was blocked too
    assert s.analysed == 6 and len(_rows(out)) == 6
    assert sum("set aside" in line for line in said) == 2
    assert sorted(p.name for p in (out / "set-aside").iterdir()) == ["0123-1.parquet.1", f"{TABLE_NAME}.1"]
    s, said = _analyse([campaign], out)
    assert (s.analysed, s.skipped, said) == (0, 6, [f"6 of 6 analyses already in {out} (resume); 0 to run"])


# -- every input checked before work -------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["fifo", "dev-zero", "directory"])
def test_a_run_file_that_is_no_regular_file_is_a_failed_row_at_once(campaign, tmp_path, kind):
    path = campaign / "id3-1.h5"
    path.unlink()
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "dev-zero":
        path.symlink_to("/dev/zero")
    else:
        path.mkdir()
    t0 = time.monotonic()
    s, _ = _analyse([campaign], tmp_path / "r")  # hashing hung on a FIFO or /dev/zero; a directory ended it all
    assert time.monotonic() - t0 < 30
    rows = {r["key"]: r for r in _rows(tmp_path / "r")}
    assert rows["id3-1"]["status"] == "failed" and "not a regular file" in rows["id3-1"]["error"]
    assert [r["status"] for k, r in rows.items() if k != "id3-1"] == ["ok"] * 5


@pytest.mark.parametrize(("field", "value", "said"), [
    ("key", 5, "key is int, not str"), ("file", ["a"], "file is list"),
    ("uid", 1.5, "uid is float"), ("file", "../other/x.h5", "not a file name in the campaign folder"),
    ("environment", "23 C", "environment is str"), (None, "run", "runs[2] is str, not an object")])
def test_a_mistyped_index_entry_is_one_line_naming_it(campaign, tmp_path, capsys, field, value, said):
    doc = _index(campaign)
    if field is None:
        doc["runs"][2] = value
    else:
        doc["runs"][2][field] = value
    (campaign / "index.json").write_text(json.dumps(doc))
    assert main(["analyse", str(campaign), "-o", str(tmp_path / "r"), "--serial"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err and "index.json" in err, err


def test_names_of_any_length(made, tmp_path):
    long = tmp_path / ("c" * 240)  # gave "File name too long" (parts were named by campaign and run)
    shutil.copytree(made, long)
    s, _ = _analyse([long], tmp_path / "r")
    assert s.analysed == 6 and {r["campaign"] for r in _rows(tmp_path / "r")} == {long.name}


@pytest.mark.parametrize(("options", "said"), [
    (["--workers", "-1"], "--workers must be in 1..256"), (["--workers", "0"], "--workers must be in 1..256"),
    (["--workers", "1000000"], "--workers must be in 1..256"),
    (["--serial", "--workers", "2"], "--serial runs in this process"),
    (["--thresholds", "-5"], "--thresholds -5: must lie in [0, 1024]"),
    (["--thresholds", "5000"], "--thresholds 5000: must lie in [0, 1024]"),
    (["--skeleton-mass", "inf"], "--skeleton-mass must be finite and > 0"),
    (["--skeleton-mass", "nan"], "--skeleton-mass must be finite and > 0"),
    (["--skeleton-mass", "-1"], "--skeleton-mass must be finite and > 0"),
    (["--scheduler-file", "/nonexistent/s.json"], "no Dask scheduler file"),
    (["--scheduler", "tcp://127.0.0.1:1"], "cannot connect")])
def test_a_bad_option_is_one_line_and_exit_2(campaign, tmp_path, capsys, options, said):
    t0 = time.monotonic()
    assert main(["analyse", str(campaign), "-o", str(tmp_path / "r"), "--no-dashboard", *options]) == 2
    assert time.monotonic() - t0 < 30
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err, err


def _server(answer: bytes | None) -> tuple[str, threading.Event]:
    """A TCP service on localhost that sends ``answer`` on each connection (None: says nothing, holds it)."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen()
    stop = threading.Event()

    def serve():
        held = []
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except TimeoutError:
                continue
            if answer is not None:
                conn.sendall(answer)
            held.append(conn)
        for c in held:
            c.close()
        srv.close()

    threading.Thread(target=serve, daemon=True).start()
    return f"tcp://127.0.0.1:{srv.getsockname()[1]}", stop


@pytest.mark.parametrize(("answer", "said"), [
    (b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n", "does not speak Dask's protocol"),
    (None, "no answer within 2 s")])
def test_a_scheduler_address_of_another_service_is_one_line_within_the_timeout(campaign, tmp_path, capsys, answer,
                                                                                said, monkeypatch):
    from hilbench.bench.campaign_analysis import engine

    monkeypatch.setattr(engine, "CONNECT_TIMEOUT", 2.0)  # the product's 10 s, shortened: the silence is the same
    address, stop = _server(answer)  # a non-Dask service: a traceback and a 3 EiB allocation; silence: a hang
    try:
        t0 = time.monotonic()
        assert main(["analyse", str(campaign), "-o", str(tmp_path / "r"), "--scheduler", address]) == 2
        assert time.monotonic() - t0 < 30
    finally:
        stop.set()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err, err


def test_nan_temperature_is_a_missing_reading_not_a_failure(tmp_path):
    from hilbench.bench.campaign_analysis.steps import identify_step
    from hilbench.common.runfile import RunWriter

    src = tmp_path / "made"
    write_campaign(src, SyntheticCampaign(runs=1, duration=1.5, seed=3))
    from hilbench.common.runfile import open_run

    with open_run(src / "id1-1.h5") as run:
        channels = {c: np.asarray(run.channel(c)) for c in run.channels}
    for i, reading in enumerate((np.nan, 30.0)):  # every reading missing; one present among missing ones
        temp = np.full(channels["t"].size, np.nan)
        temp[::7] = reading
        path = tmp_path / f"nan{i}.h5"
        with RunWriter(path, sample_rate=1000.0, channels=tuple(channels), protocol_name="identification",
                       protocol_params={"duration": 1.5}) as w:
            w.append({**channels, "temperature": temp})
        row = identify_step(str(path), StepSettings())  # failed: "channel 'temperature' has ... non-finite"
        assert row["breakaway"] > 0
        assert (row.get("temperature_mean") is None) if i == 0 else row["temperature_mean"] == 30.0


def test_allow_incomplete_analyses_runs_that_did_not_complete(campaign, tmp_path):
    doc = _index(campaign)
    doc["runs"][1]["status"] = "aborted"
    (campaign / "index.json").write_text(json.dumps(doc))
    _analyse([campaign], tmp_path / "r")
    assert {r["key"]: r["status"] for r in _rows(tmp_path / "r")}["id2-1"] == "not run"
    _analyse([campaign], tmp_path / "r", settings=StepSettings(allow_incomplete=True))
    assert {r["key"]: r["status"] for r in _rows(tmp_path / "r")}["id2-1"] == "ok"
    assert main(["-q", "analyse", str(campaign), "-o", str(tmp_path / "cli"), "--serial",
                 "--allow-incomplete"]) == 0


def test_a_run_a_worker_cannot_open_is_a_failed_row_naming_where(campaign, tmp_path):
    item = {"path": str(campaign / "gone.h5"), "step": "identify", "uid": "u", "known": (),
            "base": {"campaign_uid": "c", "key": "gone", "run_id": "u", "step": "identify"}}
    (outcome,) = execute_chunk([item], StepSettings(), FAST, str(tmp_path / "r"))
    assert outcome[1] == "failed" and f"cannot open on host {socket.gethostname()}" in outcome[2]


def test_the_client_plans_without_opening_a_run_file(campaign, tmp_path, monkeypatch):
    """The client's work per run is a stat: hashing and reading are the workers' (16 workers are fed by one client)."""
    from hilbench.bench.campaign_analysis import engine

    opened: list[str] = []
    real_open, real_os_open = open, os.open
    monkeypatch.setattr("builtins.open", lambda f, *a, **k: (opened.append(str(f)), real_open(f, *a, **k))[1])
    monkeypatch.setattr(os, "open", lambda f, *a, **k: (opened.append(str(f)), real_os_open(f, *a, **k))[1])
    tasks, own, reused, unplanned = engine.plan([campaign], ("identify",), StepSettings())
    assert len(tasks) == 6 and not own and not reused and not unplanned
    assert not [f for f in opened if f.endswith(".h5")], opened


def test_a_read_only_older_campaign_gets_a_uid_from_its_runs(campaign, tmp_path, monkeypatch):
    from hilbench.bench.campaign_analysis.engine import campaign_uid

    doc = _index(campaign)
    # as the folder of an archive mounted read-only looks (root may write anywhere, so it is said here)
    monkeypatch.setattr(os, "access", lambda path, mode: mode != os.W_OK)
    uid = campaign_uid(campaign, doc)
    copy = tmp_path / "copy"
    shutil.copytree(campaign, copy)
    assert uid.startswith("runs-") and "uid" not in _index(campaign) and campaign_uid(copy, _index(copy)) == uid
