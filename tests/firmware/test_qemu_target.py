"""Processor in the loop: the firmware core and the plant cross-compiled for a Cortex-M4F, run by QEMU
(mps2-an386) behind a pseudo-terminal. The bench runs an identification protocol on it and on the host
simulator (the same core through cffi); the run files' samples are equal to the wire's float32."""

import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from hilbench.bench.acquisition.protocols import Identification
from hilbench.bench.acquisition.runner import Bench, DeviceSettings
from hilbench.drivers.device_url import open_device
from tests.firmware import qemu_target

pytestmark = [pytest.mark.target, pytest.mark.usefixtures("starts_devices")]  # starts a device
@pytest.fixture(scope="module")
def lockstep_image():
    why = qemu_target.missing_tools()
    if why:
        pytest.skip(f"emulated target: {why}")
    return qemu_target.build_image("lockstep")


def samples_of(path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as f:
        return {name: f["samples"][name][()] for name in f["samples"]}


def test_identification_on_the_emulated_m4_equals_the_host_run(lockstep_image, tmp_path):
    # 1.5 s at 1 kHz around the break-away current: sticking and sliding, a few thousand samples
    protocol = Identification(duration=1.5, amplitude=16.0, period=0.5, cutoff=40.0, seed=4, sample_rate=1000)
    # the emulated UART moves one byte per QEMU main-loop pass: a heartbeat can wait behind a block for
    # longer than the bench's 0.5 s on a loaded machine; the watchdog is not what this test compares
    settings = DeviceSettings(counts_per_rev=4096, watchdog_timeout=5.0)
    runs = {}
    with qemu_target.running_qemu(lockstep_image) as (_, pty):
        # one start, one connection: no restart hides a dead link (docs/firmware.md, "UART")
        for name, url in (("qemu", f"serial://{pty}"), ("host", "sim://?pacing=lockstep")):
            with Bench(open_device(url, timeout=5.0), url, settings) as bench:
                if name == "qemu":
                    assert bench.identity()["firmware"].endswith("mps2-an386")
                result = bench.run(protocol, tmp_path / f"{name}.h5")
            assert result.status == "completed", result.message
            runs[name] = samples_of(result.path)
    qemu_run, host_run = runs["qemu"], runs["host"]
    assert set(qemu_run) == set(host_run) and len(host_run["sample_index"]) == 1500
    for channel, values in host_run.items():
        assert np.array_equal(qemu_run[channel], values), channel  # tolerance zero
    assert np.ptp(host_run["counts"]) > 50  # the motor turned: not a comparison of a motor at rest


def _gone(pid: int, within: float = 5.0) -> bool:
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


def test_qemu_never_outlives_its_host(lockstep_image):
    # every exit path: a block that raises, and a host killed with SIGKILL (no cleanup code runs)
    with pytest.raises(RuntimeError, match="the block failed"):
        with qemu_target.running_qemu(lockstep_image) as (proc, _):
            pid = proc.pid
            raise RuntimeError("the block failed")
    assert _gone(pid)
    code = ("import sys, time\nfrom tests.firmware import qemu_target\n"
            f"proc, pty = qemu_target.start_qemu({str(lockstep_image)!r})\n"
            "print(proc.pid, flush=True)\ntime.sleep(60)\n")
    host = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, cwd=qemu_target.ROOT)
    try:
        qemu_pid = int(host.stdout.readline())
        os.kill(qemu_pid, 0)  # running
    finally:
        host.send_signal(signal.SIGKILL)
        host.wait()
        host.stdout.close()
    assert _gone(qemu_pid), f"QEMU {qemu_pid} survived its SIGKILLed host"


def test_board_port_builds_and_fits_the_f446re(lockstep_image):
    elf = qemu_target.build_image("nucleo-f446re")
    sizes = qemu_target.size(elf)
    # STM32F446RE: 512 KiB flash, 128 KiB RAM of which the linker script keeps >= 4 KiB for the stack
    assert 0 < sizes["flash"] <= 512 * 1024 and 0 < sizes["ram"] <= 124 * 1024, sizes
    qemu = qemu_target.size(lockstep_image)
    assert qemu["flash"] > sizes["flash"]  # the QEMU image also carries the plant and its libm
