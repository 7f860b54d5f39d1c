"""The local cluster's host process (bench.campaign_analysis.cluster_host): the scheduler and the nannies run outside
the client's process, the host ends with its client however the client ends, and a cluster that cannot start is one
line."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from hilbench.bench.campaign_analysis import cluster_host
from hilbench.bench.errors import AnalyseError


def _gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    # a zombie (exited, not yet reaped by a parent that is gone too) counts as gone; so does one reaped meanwhile
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


def _descendants(pid: int) -> set[int]:
    out, todo = set(), [pid]
    while todo:
        p = todo.pop()
        try:
            children = open(f"/proc/{p}/task/{p}/children").read().split()
        except OSError:
            continue
        out.update(int(c) for c in children)
        todo += [int(c) for c in children]
    return out


def test_the_scheduler_runs_in_the_host_not_in_the_client_and_ends_with_it():
    from distributed import Client

    host = cluster_host.Host(1, None)
    address, dashboard = host.address()
    assert dashboard is None
    host.wait_up()  # the address comes as soon as the scheduler listens
    with Client(address, timeout="30s") as client:
        scheduler_pid = client.run_on_scheduler(os.getpid)
        workers = client.run(os.getpid)
    assert scheduler_pid == host.proc.pid != os.getpid()
    assert len(workers) == 1 and os.getpid() not in workers.values()
    tree = _descendants(host.proc.pid)  # the fork server, the workers (and their helpers)
    assert set(workers.values()) <= tree and len(tree) > len(workers)
    host.close()
    assert host.proc.returncode == 0
    deadline = time.monotonic() + 30
    while not all(_gone(p) for p in tree) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert all(_gone(p) for p in tree), "the fork server or a worker outlived its cluster host"


_CLIENT = """
import sys
from hilbench.bench.campaign_analysis import cluster_host
host = cluster_host.Host(1, None)
address = host.address()[0]
host.wait_up()
print(host.proc.pid, address, flush=True)
sys.stdin.read()
"""


def test_a_client_killed_with_sigkill_takes_its_cluster_with_it():
    client = subprocess.Popen([sys.executable, "-c", _CLIENT], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              text=True)
    try:
        host_pid = int(client.stdout.readline().split()[0])
        tree = _descendants(host_pid) | {host_pid}
        assert len(tree) >= 3  # the host, its fork server, a worker
        client.send_signal(signal.SIGKILL)
        client.wait(10)
        deadline = time.monotonic() + 30
        while not all(_gone(p) for p in tree) and time.monotonic() < deadline:
            time.sleep(0.1)
        left = [p for p in tree if not _gone(p)]
        assert not left, f"processes of the cluster outlived their client: {left}"
    finally:
        client.kill()
        client.wait()


_STARTING = """
import sys
from hilbench.bench.campaign_analysis import cluster_host
host = cluster_host.Host(1, None)
print(host.proc.pid, flush=True)
sys.stdin.read()
"""


def test_a_client_killed_while_its_cluster_starts_ends_the_host_at_once():
    """The host heard its client only once the cluster was up: a client killed during the start left the host
    starting a whole cluster for nobody (or orphaned for good if the start hung). It now exits as soon as its stdin
    ends, before any worker starts."""
    reference = cluster_host.Host(1, None)  # how long a whole start takes here, now
    t0 = time.monotonic()
    reference.address()
    start = time.monotonic() - t0
    reference.close()
    client = subprocess.Popen([sys.executable, "-c", _STARTING], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              text=True)
    try:
        host_pid = int(client.stdout.readline())
        client.send_signal(signal.SIGKILL)  # at once: the host is still importing (its start takes 1-2 s idle)
        client.wait(10)
        t0 = time.monotonic()
        while not _gone(host_pid) and time.monotonic() - t0 < 30:
            time.sleep(0.02)
        assert _gone(host_pid), "the cluster host outlived its client"
        took = time.monotonic() - t0
        assert took < start / 2, f"the host took {took:.2f} s to end, a whole start {start:.2f} s"
        tree = _descendants(host_pid)
        deadline = time.monotonic() + 30
        while not all(_gone(p) for p in tree) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert all(_gone(p) for p in tree)
    finally:
        client.kill()
        client.wait()


def test_a_refused_command_line_ends_the_host_it_started_early(tmp_path):
    """`hilbench analyse` starts its cluster host before it parses its options; a line it then refuses (exit 2)
    ends that host at once, also when the command runs inside a longer-lived process (the GUI, a test)."""
    from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign
    from hilbench.bench.cli.main import main

    folder = tmp_path / "c"
    write_campaign(folder, SyntheticCampaign(runs=1, duration=0.5, sample_rate=1000.0, seed=1))
    started = []
    real = cluster_host.Host

    class Spy(real):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            started.append(self)

    cluster_host.Host = Spy
    try:
        assert main(["analyse", str(folder), "--workers", "1", "--thresholds", "-5"]) == 2
    finally:
        cluster_host.Host = real
    assert len(started) == 1 and started[0].proc.poll() is not None and cluster_host._early is None


def test_a_cluster_that_cannot_start_is_one_line():
    host = cluster_host.Host(1, "not an address")
    with pytest.raises(AnalyseError, match="the local cluster did not start: ") as err:
        host.address()
    assert "\n" not in str(err.value)
    assert host.proc.wait(30) == 1


def test_an_early_host_is_taken_once_with_its_settings_and_otherwise_ended():
    cluster_host.discard()
    cluster_host.start_early(1, None)
    early = cluster_host._early
    assert cluster_host.take(1, None) is early and cluster_host._early is None
    early.close()
    cluster_host.start_early(1, None)
    other = cluster_host._early
    replaced = cluster_host.take(2, None)  # another worker count: a new host, the early one ended
    try:
        assert replaced is not other and other.proc.poll() is not None
        assert replaced.request == {"workers": 2, "dashboard": None}
    finally:
        replaced.close()
    cluster_host.start_early(1, None)
    unused = cluster_host._early
    cluster_host.discard()
    assert unused.proc.poll() is not None and cluster_host._early is None


def _slow(path: str, settings) -> dict:
    time.sleep(0.05)
    return {"samples": os.path.getsize(path)}


def test_a_cluster_host_killed_mid_analysis_is_one_line_and_the_same_command_finishes(tmp_path):
    """The local cluster's process killed (-9) while its workers analyse: the command ends with one line naming the
    cluster, not with a "worker died" row for every run of the tasks it lost (what it wrote before: rows that a
    resumed analysis then kept); the rows the workers wrote stay, and the same analysis again gives one ok row per
    run."""
    import threading

    import pyarrow.parquet as pq

    from hilbench.bench.campaign_analysis.engine import analyse
    from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign

    campaign, out = tmp_path / "c", tmp_path / "r"
    write_campaign(campaign, SyntheticCampaign(runs=24, duration=0.3, seed=5))
    killed: list[int] = []

    def kill_the_host_after_the_first_part() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not killed:
            if (out / "parts").is_dir() and any((out / "parts").glob("*.parquet")):
                for pid in _descendants(os.getpid()):
                    try:
                        line = open(f"/proc/{pid}/cmdline", "rb").read()
                    except OSError:
                        continue
                    if b"set_forkserver_preload" in line and b"forkserver import main" not in line:
                        os.kill(pid, signal.SIGKILL)
                        killed.append(pid)
                        return
            time.sleep(0.01)

    killer = threading.Thread(target=kill_the_host_after_the_first_part)
    killer.start()
    t0 = time.monotonic()
    with pytest.raises(AnalyseError) as err:
        analyse([campaign], out, workers=2, dashboard=False, progress=False, say=lambda _l: None,
                functions={"identify": _slow})
    killer.join()
    assert killed and time.monotonic() - t0 < 60
    assert str(err.value).startswith("the local cluster failed: its process ended (exit code -9)")
    assert "\n" not in str(err.value)
    kept = sum(pq.read_metadata(f).num_rows for f in (out / "parts").glob("*.parquet"))
    assert 0 < kept < 24
    again = analyse([campaign], out, workers=2, dashboard=False, progress=False, say=lambda _l: None,
                    functions={"identify": _slow})
    rows = pq.read_table(again.table).to_pylist()
    assert sorted(r["key"] for r in rows) == sorted({r["key"] for r in rows}) and len(rows) == 24
    assert all(r["status"] == "ok" for r in rows), [r["error"] for r in rows if r["status"] != "ok"]
    assert again.skipped == kept and again.analysed == 24 - kept


def test_a_cluster_that_does_not_start_in_time_says_so_in_one_line(monkeypatch):
    """The host bounds its own start (its deadline's word reaches the client as the cluster's error: the client
    submits as soon as the scheduler listens, so a start that hangs later must end the host, not the wait)."""
    monkeypatch.setattr(cluster_host, "START_TIMEOUT", 0.05)
    host = cluster_host.Host(1, None)
    t0 = time.monotonic()
    with pytest.raises(AnalyseError, match=r"the local cluster did not start: it did not start within 0.05 s$"):
        host.address()
    assert time.monotonic() - t0 < 10 and host.proc.wait(30) == 1


def test_workers_that_cannot_start_after_the_scheduler_listens_are_the_hosts_word(monkeypatch):
    """The address comes before the workers; a worker start that fails then is the host's second word, which the
    command reads when its tasks are cancelled (engine._on_cluster), and the host ends."""
    monkeypatch.setattr(cluster_host, "CONFIG", {**cluster_host.CONFIG,
                                                 "distributed.worker.multiprocessing-method": "no-such-method"})
    host = cluster_host.Host(1, None)
    address, _ = host.address()
    assert address.startswith("tcp://")
    why = host.failure(wait=60)
    assert why is not None and "no-such-method" in why and "\n" not in why
    assert host.proc.wait(30) == 1


def test_the_scheduler_unpickles_no_analysis_to_schedule_the_tasks(tmp_path):
    """Dask's scheduler unpickles every task to build its graph: the engine's chunk function and its settings used
    to import the engine, pyarrow and every analysis into the host (0.14 s of its CPU, its event loop
    blocked while the first workers waited). Tasks go as an opaque payload (bench.campaign_analysis.opaque): the
    scheduler imports that light module only, and the worker runs the task as before."""
    from distributed import Client

    from hilbench.bench.campaign_analysis import opaque
    from hilbench.bench.campaign_analysis.engine import _items, execute_chunk_timed, plan
    from hilbench.bench.campaign_analysis.steps import StepSettings
    from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign

    write_campaign(tmp_path / "c", SyntheticCampaign(runs=1, duration=2.0, sample_rate=1000.0, seed=2))
    tasks, _, _, _ = plan([tmp_path / "c"], ("identify",), StepSettings())
    args = (_items(tasks), StepSettings(), {}, str(tmp_path / "r"))

    def imported(client) -> list[str]:  # what of the analysis the scheduler's process has imported
        return client.run_on_scheduler(lambda: sorted(
            m for m in ("pyarrow", "hilbench.bench.campaign_analysis.engine",
                        "hilbench.bench.campaign_analysis.steps", "hilbench.analysis.protocol")
            if m in __import__("sys").modules))

    host = cluster_host.Host(1, None)
    try:
        address, _ = host.address()
        with Client(address, timeout="30s") as client:
            began, outcomes = client.submit(opaque.call, opaque.pack(execute_chunk_timed, *args),
                                            key="opaque").result(timeout=120)
            opaque_imports = imported(client)
            # the control: the same task as Dask's own pickle of the function and its arguments
            client.submit(execute_chunk_timed, *args, key="plain").result(timeout=120)
            plain_imports = imported(client)
    finally:
        host.close()
    assert [o[1] for o in outcomes] == ["ok"] and began > 0
    assert opaque_imports == []
    assert "hilbench.bench.campaign_analysis.engine" in plain_imports and "pyarrow" in plain_imports


def _dies_on_the_first_run(path: str, settings) -> dict:
    if path.endswith("id1-1.h5"):
        os._exit(3)  # the worker dies as on a segfault, on the first task it is given
    return _slow(path, settings)


def test_a_task_that_kills_its_worker_at_once_is_its_runs_failure_not_the_clusters():
    """The command connects while the workers start and submits once the host says they are up: tasks submitted at
    once reached the first worker while the cluster still started, and one that killed it failed the start itself
    ("Nanny failed to start worker process": the whole analysis ended with exit 2; found by the quick benchmark)."""
    import tempfile
    from pathlib import Path

    import pyarrow.parquet as pq

    from hilbench.bench.campaign_analysis.engine import analyse
    from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign

    with tempfile.TemporaryDirectory() as tmp:
        campaign = Path(tmp) / "c"
        write_campaign(campaign, SyntheticCampaign(runs=6, duration=0.3, seed=9))
        s = analyse([campaign], Path(tmp) / "r", workers=2, dashboard=False, progress=False,
                    say=lambda _l: None, functions={"identify": _dies_on_the_first_run})
        rows = {r["key"]: r for r in pq.read_table(s.table).to_pylist()}
    assert len(rows) == 6 and s.failed == 1
    assert rows["id1-1"]["status"] == "failed" and "worker died twice" in rows["id1-1"]["error"]
    assert all(r["status"] == "ok" for k, r in rows.items() if k != "id1-1")
