"""Protocol runner end to end on the simulated device: logging, shutdown, pause/resume, abort, Ctrl-C,
SIGKILL."""

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from hilbench.bench.acquisition.protocols import Identification, ProtocolError, SteppedSine
from hilbench.bench.acquisition.runner import Bench, DeviceSettings, RunControl
from hilbench.common.runfile import open_run
from hilbench.drivers import protocol as wire
from tests.reliability.cli import run_events, wait_for_samples

LOCKSTEP = "sim://?pacing=lockstep"


@pytest.fixture(scope="module")
def bench():
    with Bench.open(LOCKSTEP) as b:
        yield b


def test_identification_run_logs_every_sample(bench, tmp_path):
    proto = Identification(duration=1.0, amplitude=4.0, seed=3)
    events = []
    result = bench.run(proto, tmp_path / "id.h5", operator="tester", progress=events.append)
    assert result.status == "completed"
    with open_run(result.path) as run:
        assert run.status == "completed"
        idx = run.channel("sample_index")
        np.testing.assert_array_equal(idx, np.arange(10_000))
        np.testing.assert_allclose(run.t, idx / 10_000)
        # the commanded current is the protocol's setpoint array, sent as float32
        np.testing.assert_array_equal(run.channel("current_cmd"), proto.setpoints().astype(np.float32))
        assert run.unit("torque") == "N*m" and run.unit("position") == "rad"
        assert run.protocol_name == "identification"
        assert run.protocol_params["amplitude"] == 4.0 and run.protocol_params["units"]["amplitude"] == "A"
        assert run.calibration["torque_constant"] == 0.2 and run.meta["operator"] == "tester"
        assert run.device["model"]
    assert events[-1].done == events[-1].total == 10_000
    assert bench.amplifier.status().state == wire.State.DISARMED  # shutdown disarmed


def test_progress_contract_done_grows_to_total_in_every_segment(bench, tmp_path):
    """Issue 28: the scripting API reports progress. Every call has total = the protocol's samples, done grows
    strictly, the last call of a completed run is done == total, and the blocks' lengths add up to done."""
    proto = SteppedSine(frequencies=(20.0, 40.0), amplitudes=(1.0, 2.0), settle_periods=2, measure_periods=4)
    calls = []
    result = bench.run(proto, tmp_path / "s.h5", progress=lambda p: calls.append((p.done, p.total, p.t.size,
                                                                                  p.segment, p.n_segments)))
    assert result.status == "completed" and len(calls) > 4
    done, total, block, segment, n_segments = (np.array(c) for c in zip(*calls, strict=True))
    assert np.all(total == proto.n_samples) and np.all(np.diff(done) > 0)
    assert done[-1] == proto.n_samples == result.samples
    np.testing.assert_array_equal(np.cumsum(block), done)
    assert np.all(np.diff(segment) >= 0) and segment[-1] == n_segments[0] - 1 == 3


class _SaysWhenPaused(RunControl):
    """A RunControl that says when the run has stopped at the pause (the runner waits in wait_while_paused)."""

    def __init__(self) -> None:
        super().__init__()
        self.waiting = threading.Event()

    def wait_while_paused(self, keepalive, period: float = 0.05) -> None:
        self.waiting.set()
        super().wait_while_paused(keepalive, period)


def test_pause_and_resume_between_stepped_sine_steps(bench, tmp_path):
    proto = SteppedSine(frequencies=(20.0, 40.0), amplitudes=(1.0,), settle_periods=2, measure_periods=4)
    control = _SaysWhenPaused()

    def resume_once_paused() -> None:
        # the pause takes effect at the step's end: resume 0.3 s after the run stopped there (a timer started with
        # the pause could resume before a loaded machine reached the step's end: then there was no pause at all)
        if control.waiting.wait(60):
            time.sleep(0.3)
        control.resume()

    resumer = threading.Thread(target=resume_once_paused, daemon=True)

    def on_progress(p):
        if p.segment == 0 and resumer.ident is None:
            control.pause()
            resumer.start()

    result = bench.run(proto, tmp_path / "ss.h5", progress=on_progress, control=control)
    resumer.join(timeout=60)
    assert result.status == "completed"
    with open_run(result.path) as run:
        kinds = [e.decode() if isinstance(e, bytes) else e for e in run.events["kind"]]
        assert kinds.count("pause") == 1 and kinds.count("resume") == 1
        assert run.channel("sample_index").size == proto.setpoints().size


def test_abort_marks_the_file_and_disarms(bench, tmp_path):
    control = RunControl()
    proto = Identification(duration=5.0, amplitude=3.0)
    result = bench.run(proto, tmp_path / "ab.h5", control=control,
                       progress=lambda p: control.abort() if p.done > 5000 else None)
    assert result.status == "aborted"
    assert bench.amplifier.status().state == wire.State.DISARMED
    with open_run(result.path) as run:
        assert run.status == "aborted"
        assert 5000 < run.channel("t").size < 50_000
        # the result counts what the file holds (it said 0 for every aborted run), and the event says why
        assert result.samples == run.n_samples
        assert run.events["message"][-1].startswith("aborted by operator after ")


def test_an_abort_with_a_reason_records_it(bench, tmp_path):
    control = RunControl()
    result = bench.run(Identification(duration=5.0, amplitude=3.0), tmp_path / "ab.h5", control=control,
                       progress=lambda p: control.abort("E-STOP: test") if p.done > 5000 else None)
    control.abort("a later abort does not replace the first reason")
    with open_run(result.path) as run:
        assert result.status == "aborted" and 5000 < result.samples == run.n_samples
        assert run.events["message"][-1] == f"E-STOP: test after {result.samples} of 50000 samples"


def test_host_refuses_out_of_range_parameters_before_anything_moves(bench, tmp_path):
    with pytest.raises(ProtocolError, match="sample_rate"):
        Identification(sample_rate=3000)
    with pytest.raises(ProtocolError, match="amplitude"):
        Identification(amplitude=float("nan"))
    small = Bench(bench.amplifier, LOCKSTEP, DeviceSettings(current_limit=1.0))
    with pytest.raises(ValueError, match="exceeds"):
        small.run(Identification(duration=0.5, amplitude=4.0), tmp_path / "x.h5")
    assert not (tmp_path / "x.h5").exists()


def _start_cli_run(tmp_path, duration=30):
    """A CLI run on ``sim://`` (real time) that has flushed at least 1 s of samples; returns the process, the run
    file and the samples flushed so far.

    The device's watchdog is 5 s, not the default 0.5 s: these tests end a run by a signal, and a loaded machine
    that descheduled the CLI for 0.5 s ended it first, rightly, with a WATCHDOG fault (the SIGKILL test then found
    an 'aborted' file, the Ctrl-C test no file with 1 s logged). tests/reliability/test_drive_watchdogs.py checks
    the watchdog itself."""
    out = tmp_path / "cli.h5"
    # an operator's Ctrl-C reaches a foreground process, whose SIGINT is at its default; a test suite started
    # in the background of a script inherits SIGINT ignored, and so would the CLI (Python keeps it ignored)
    proc = subprocess.Popen([sys.executable, "-m", "hilbench.bench.cli", "run", "identify", "--duration", str(duration),
                             "--watchdog-timeout", "5", "--quiet", "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        # the bound is for a start that hangs: on a loaded machine the CLI and the simulator start in 3-15 s
        return proc, out, wait_for_samples(out, 10_000, timeout=60, proc=proc)  # at least 1 s logged
    except BaseException:
        proc.kill()
        proc.communicate()
        raise


@pytest.mark.usefixtures("starts_devices")  # a real-time simulator: the serial part
def test_ctrl_c_leaves_an_aborted_file_and_a_nonzero_exit(tmp_path):
    proc, out, _ = _start_cli_run(tmp_path)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)  # 3-8 s alone; two full runs at load 7-9 took over 20 s
    assert proc.returncode != 0, (stdout, stderr)
    assert "aborted" in stdout + stderr
    with open_run(out) as run:
        assert run.status == "aborted"
        kinds = [e.decode() if isinstance(e, bytes) else e for e in run.events["kind"]]
        assert "abort" in kinds


@pytest.mark.usefixtures("starts_devices")  # a real-time simulator: the serial part
def test_sigkill_leaves_a_crashed_file_with_every_flushed_sample(tmp_path):
    proc, out, seen = _start_cli_run(tmp_path)
    sims = _children(proc.pid)
    assert sims, "sim:// should run the simulator as a child process"
    # kill it between two flushes, once a flush has come after the one seen (a sleep here raced the run's end)
    flushed = wait_for_samples(out, seen + 1, proc=proc)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    # the simulator child loses its host: its watchdog disarms it; the file must open with bench
    cp = subprocess.run([sys.executable, "-m", "hilbench.bench.cli", "show", str(out), "--repair"],
                        capture_output=True, text=True, timeout=60)
    assert cp.returncode == 0, cp.stderr
    with open_run(out) as run:
        assert run.status == "crashed", run_events(out)
        n = run.channel("sample_index").size
        assert n >= flushed  # every sample flushed before the kill is kept
        np.testing.assert_array_equal(run.channel("sample_index"), np.arange(n))  # no gaps, no duplicates
    # the orphaned simulator exits by itself once its host is gone (--parent-pid)
    deadline = time.monotonic() + 15
    while any(os.path.exists(f"/proc/{pid}") for pid in sims) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not any(os.path.exists(f"/proc/{pid}") for pid in sims)


def _children(pid: int) -> list[int]:
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    if int(f.read().rsplit(")", 1)[1].split()[1]) == pid:
                        out.append(int(entry))
            except OSError:
                continue
    return out


def test_a_ctrl_c_lost_as_an_exception_still_aborts_through_the_flag():
    """signals_as_interrupt(control=...): SIGINT raises KeyboardInterrupt and sets the abort flag. If code the run
    calls swallows the exception (C code that clears a pending error), the run loop still sees the flag."""
    from hilbench.bench.acquisition.runner import RunControl, signals_as_interrupt

    outer = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a foreground process
    try:
        control = RunControl()
        with signals_as_interrupt(control=control):
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(1)  # the handler runs here
            except KeyboardInterrupt:
                pass  # the exception is lost...
        assert control.aborted  # ...the flag is not
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored on exit
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # started in the background of a script: stays ignored
        with signals_as_interrupt(control=RunControl()):
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, outer)
