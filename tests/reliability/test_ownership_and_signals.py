"""#12 item 5 (one owner per device port), item 12 (SIGTERM/SIGHUP like Ctrl-C; ``hilbench fault``)."""

import signal

import pytest

from hilbench.common.runfile import lock_path, open_run
from hilbench.drivers import protocol as p
from hilbench.drivers.device_url import open_device
from hilbench.drivers.errors import PortBusyError
from tests.reliability.cli import hilbench, one_line_error, start, wait_for_samples
from tests.reliability.wire import Wire

pytestmark = pytest.mark.usefixtures("starts_devices")  # starts a device: the serial realtime part of make test


def test_a_second_program_on_the_port_is_refused_and_the_run_completes(simulator, tmp_path):
    _, pty = simulator(pacing="realtime")
    out = tmp_path / "run.h5"
    run = start("run", "identify", "--device", f"serial://{pty}", "--sample-rate", "1000", "--duration", "5",
                "--quiet", "-o", out)
    wait_for_samples(out, 1000)
    line = one_line_error(hilbench("info", "--device", f"serial://{pty}"))
    assert "in use by another program" in line, line
    for _ in range(3):  # what `fault clear` and another `run` would do first: open the device
        with pytest.raises(PortBusyError, match="in use by another program"):
            open_device(f"serial://{pty}")
    assert run.poll() is None, "the run ended before the second program tried (machine too loaded)"
    stdout, stderr = run.communicate(timeout=60)
    assert run.returncode == 0, stderr
    with open_run(out) as r:
        assert r.status == "completed" and r.n_samples == 5000
        assert [e for e in r.events if e["kind"] in ("abort", "fault")] == []
    assert hilbench("info", "--device", f"serial://{pty}").returncode == 0  # free again


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_sigterm_and_sighup_end_a_run_like_ctrl_c(tmp_path, signum):
    out = tmp_path / "run.h5"
    run = start("run", "identify", "--device", "sim://", "--sample-rate", "1000", "--duration", "30", "--quiet",
                "-o", out)
    wait_for_samples(out, 1000)
    run.send_signal(signum)
    stdout, stderr = run.communicate(timeout=30)
    name = signal.Signals(signum).name
    assert run.returncode == 130, stderr
    assert f"interrupted ({name}); device disarmed" in stdout
    with open_run(out) as r:
        assert r.status == "aborted" and 1000 <= r.n_samples < 30000
        assert r.events["kind"][-1] == "abort" and name in r.events["message"][-1]
    assert not (tmp_path / lock_path("run.h5")).exists()


def test_fault_show_and_clear(simulator):
    _, pty = simulator(pacing="lockstep")
    wire = Wire(pty)
    wire.request(p.GetIdentity())
    wire.request(p.Config(sample_rate=1000, current_limit=3.0, torque_constant=0.2, counts_per_rev=4096))
    assert wire.request(p.EStop()).result == p.Result.OK
    wire.close()
    shown = hilbench("fault", "show", "--device", f"serial://{pty}")
    assert shown.returncode == 0 and shown.stdout.startswith("faults: ESTOP"), shown
    cleared = hilbench("fault", "clear", "--device", f"serial://{pty}")
    assert cleared.returncode == 0, cleared.stderr
    assert cleared.stdout.splitlines() == ["faults: ESTOP (first at sample 0)", "cleared; faults now: none"]
    wire = Wire(pty)
    wire.request(p.GetIdentity())
    assert wire.status().faults == 0
    assert wire.request(p.Arm()).result == p.Result.OK
    wire.close()
