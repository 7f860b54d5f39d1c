"""``hilbench analyse --scheduler tcp://...`` and ``--scheduler-file``: a Dask scheduler and a worker started as
their own processes (``dask scheduler``, ``dask worker``) on localhost, as on a lab's cluster; the table they
produce equals the serial one."""

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from hilbench.bench.campaign_analysis.engine import analyse
from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign
from hilbench.bench.cli import main
from hilbench.drivers.device_url import stop_simulator

pytestmark = pytest.mark.device_free

DASK = Path(sys.executable).with_name("dask")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def remote(tmp_path_factory):
    """(address, scheduler file) of a scheduler and one worker of one thread, each its own process."""
    if not DASK.exists():
        pytest.skip(f"no dask command beside {sys.executable} (package distributed)")
    tmp = tmp_path_factory.mktemp("dask")
    port, file = _free_port(), tmp / "scheduler.json"
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}  # the workers import hilbench
    procs = [subprocess.Popen([str(DASK), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--scheduler-file", str(file), "--no-dashboard"], env=env, cwd=tmp,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        procs.append(subprocess.Popen([str(DASK), "worker", address, "--nworkers", "1", "--nthreads", "1",
                                       "--no-dashboard"], env=env, cwd=tmp, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address, timeout="60s") as client:
            client.wait_for_workers(1, timeout=60)
        yield address, file
    finally:
        for p in reversed(procs):  # only the processes this fixture started: terminate, reap (kill if stuck)
            stop_simulator(p)


@pytest.fixture(scope="module")
def campaign(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("campaign") / "c"
    write_campaign(folder, SyntheticCampaign(runs=5, duration=1.5, seed=12), fail_runs=(3,))
    return folder


def test_remote_scheduler_by_address_and_by_file_gives_the_serial_table(campaign, remote, tmp_path):
    address, file = remote
    serial = pq.read_table(analyse([campaign], tmp_path / "serial", serial=True, progress=False,
                                   say=lambda _line: None).table)
    assert serial.column("status").to_pylist().count("failed") == 1  # the run without its position channel
    for name, option in (("by-address", ["--scheduler", address]), ("by-file", ["--scheduler-file", str(file)])):
        out = tmp_path / name
        assert main(["-q", "analyse", str(campaign), "-o", str(out), "--no-dashboard", *option]) == 0
        assert pq.read_table(out / "results.parquet").equals(serial), name


def test_a_run_the_worker_cannot_open_is_a_failed_row_naming_the_worker(campaign, remote, tmp_path):
    from distributed import Client

    from hilbench.bench.campaign_analysis.engine import _check_writable, execute_chunk
    from hilbench.bench.campaign_analysis.steps import StepSettings

    address, _ = remote
    item = {"path": str(campaign / "only-on-the-client.h5"), "step": "identify", "uid": "u", "known": (),
            "base": {"campaign_uid": "c", "key": "k", "run_id": "u", "step": "identify"}}
    with Client(address, timeout="30s") as client:
        (worker,) = client.scheduler_info()["workers"]
        (outcome,) = client.submit(execute_chunk, [item], StepSettings(), {}, str(tmp_path / "r"), pure=False).result()
        assert outcome[1] == "failed" and f"cannot open on worker {worker}" in outcome[2]
        # a worker that cannot write the results folder: the analysis asks each before any task (one line)
        said = client.run(_check_writable, "/proc/hilbench-results")
        assert said[worker].startswith(f"worker {worker} cannot write the results folder /proc/hilbench-results")
        assert client.run(_check_writable, str(tmp_path)) == {worker: None}
