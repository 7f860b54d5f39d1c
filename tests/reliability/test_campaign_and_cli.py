"""#12 items 8-12 at the command line: bounds before allocation, campaign checks and one owner per folder,
one-line refusals with exit 2, and a device reporting ``max_block = 0``."""

import json
import threading
import time

import pytest

from hilbench.bench.acquisition.protocols import MAX_PROTOCOL_SAMPLES, Identification, ProtocolError
from hilbench.common.runfile import open_run
from hilbench.drivers import protocol as p
from hilbench.drivers.amplifier import Amplifier
from hilbench.drivers.errors import DriverError
from tests.reliability.cli import hilbench, one_line_error, start

HEAD = '[defaults]\ndevice = "sim://?pacing=lockstep"\n'
ONE_RUN = '[[run]]\nname = "a"\nprotocol = "chirp"\nduration = "1 s"\n'


def _check(tmp_path, text):
    path = tmp_path / "c.toml"
    path.write_text(text)
    return hilbench("campaign", path, "--check")


@pytest.mark.parametrize(("text", "expected"), [
    ("defaults = 5\n" + ONE_RUN, ":1: defaults must be a table"),
    ("run = [1, 2]\n", ":1: run must be an array of tables"),
    (HEAD + "position_min = [1, 2]\n" + ONE_RUN, ":3: run 1: position_min must be a number in rad"),
    (HEAD + "watchdog_timeout = -1\n" + ONE_RUN, ":3: run 1: watchdog_timeout = -1.0 s is out of range"),
    (HEAD + "counts_per_rev = 1.5\n" + ONE_RUN, ":3: run 1: counts_per_rev must be a whole number"),
    (HEAD + "current_limit = 1e9\n" + ONE_RUN, ":3: run 1: current_limit = 1000000000.0 A is out of range"),
    ('[defaults]\ndevice = "serial://socket://10.0.0.2:7777"\n' + ONE_RUN, ":2: run 1: serial://socket://"),
    ('[defaults]\ndevice = "serial://rfc2217://10.0.0.2:7777"\n' + ONE_RUN, "network serial ports"),
    (HEAD + '[[run]]\nname = "f"\nprotocol = "stepped_sine"\nfrequencies = [0.01]\nmeasure_periods = 2000\n'
     'sample_rate = 20000\n', f"above the bound of {MAX_PROTOCOL_SAMPLES} samples"),
], ids=["defaults=5", "run=[1,2]", "position_min=[1,2]", "watchdog=-1", "counts_per_rev=1.5",
        "current_limit=1e9", "socket://", "rfc2217://", "afrf-29.8GiB"])
def test_campaign_check_refuses(tmp_path, text, expected):
    line = one_line_error(_check(tmp_path, text))
    assert expected in line, line


def test_campaign_check_reports_memory(tmp_path):
    proc = _check(tmp_path, HEAD + ONE_RUN)
    assert proc.returncode == 0, proc.stderr
    # a 1 s chirp at the default 10 kHz: 10 000 samples x 36 B = 0.34 MiB
    assert "a-1: chirp 1.0 s (10000 samples, 0.3 MiB peak)" in proc.stdout


def test_protocol_memory_is_checked_against_what_is_available():
    proto = Identification(duration=3600, sample_rate=20000)
    assert proto.n_samples == 72_000_000 and proto.memory_bytes == 72_000_000 * 140
    with pytest.raises(ProtocolError, match=r"needs about 9.39 GiB .* only 1 GiB is available"):
        proto.check_memory(available=1 << 30)
    proto.check_memory(available=10 << 30)


@pytest.mark.parametrize("args", [
    ["run", "afrf", "--frequencies", "0.01", "--measure-periods", "2000", "--sample-rate", "20000"],
    ["run", "identify", "--current-limit", "1e9"],
    ["run", "identify", "--watchdog-timeout", "-1"],
    ["run", "identify", "--device", "serial://socket://127.0.0.1:9"],
    ["sim", "--can", "vcan0", "--interface", "bogus"],
], ids=["afrf-memory", "current-limit-1e9", "watchdog-1", "socket-url", "interface-bogus"])
def test_one_line_refusals(tmp_path, args):
    line = one_line_error(hilbench(*args, "-o", tmp_path / "x.h5") if args[0] == "run" else hilbench(*args))
    print(line)
    assert not (tmp_path / "x.h5").exists()


def test_run_has_no_inertia_option(tmp_path):
    proc = hilbench("run", "identify", "--inertia", "-1", "-o", tmp_path / "x.h5")
    assert proc.returncode == 2 and "unrecognized arguments: --inertia" in proc.stderr


@pytest.mark.usefixtures("starts_devices")  # a real-time simulator: the serial part
def test_a_model_name_over_255_bytes_is_one_line_not_a_dead_simulator(tmp_path):
    cfg = tmp_path / "sim.toml"
    cfg.write_text(f'[device]\nmodel = "{"x" * 256}"\n')
    assert "at most 255 UTF-8 bytes" in one_line_error(hilbench("sim", "--serial", "--config", cfg))
    line = one_line_error(hilbench("info", "--device", f"sim://?config={cfg}"))
    assert "simulator failed to start" in line and "255 UTF-8 bytes" in line
    big = tmp_path / "big.toml"
    big.write_text("[plant]\nelements = 100000000\n")
    assert "elements must be a whole number in 1..1024" in one_line_error(hilbench("sim", "--serial", "--config", big))


CAMPAIGN = HEAD + '[[run]]\nname = "id"\nprotocol = "identification"\nrepeats = 2\nduration = "{d} s"\n' \
                  'sample_rate = 1000\n'


@pytest.mark.usefixtures("starts_devices")  # a real-time simulator: the serial part
def test_two_resumes_on_one_folder(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(CAMPAIGN.format(d=60).replace("lockstep", "realtime"))
    out = tmp_path / "out"
    first = start("campaign", path, "-o", out, "--quiet")
    deadline = time.monotonic() + 60
    while not (out / "id-1.h5").exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    line = one_line_error(hilbench("campaign", path, "-o", out, "--resume", "--quiet"))
    assert "another campaign is playing into this folder" in line
    assert (out / "id-1.h5").exists() and not list(out.glob("*.failed-*"))
    first.terminate()
    first.communicate(timeout=30)
    # the folder is free again: a resume redoes the aborted run, and the index points at real files
    path.write_text(CAMPAIGN.format(d=0.5))
    done = hilbench("campaign", path, "-o", out, "--resume", "--quiet")
    assert done.returncode == 0, done.stderr
    index = json.loads((out / "index.json").read_text())
    for entry in index["runs"]:
        with open_run(out / entry["file"]) as run:
            assert run.status == "completed" and run.uid == entry["uid"]
    assert [p.name for p in out.glob("*.failed-*")] == ["id-1.failed-1.h5"]


class _Device:
    """A link to a device that reports ``max_block = 0``."""

    def __init__(self, max_block: int) -> None:
        self.max_block = max_block
        self.out: list[p.Message] = []
        self.sent = 0
        self.ready = threading.Condition()

    def send(self, msg: p.Message) -> None:
        self.sent += 1
        with self.ready:
            if msg.TYPE == p.MsgType.GET_IDENTITY:
                self.out.append(p.Identity("X", "1", "fw", p.PROTOCOL_VERSION, 8192, self.max_block))
            elif msg.TYPE == p.MsgType.GET_CONFIG:
                self.out.append(p.Reply(p.MsgType.GET_CONFIG, p.Result.NOT_CONFIGURED, 0))
            elif msg.TYPE in (p.MsgType.DISARM,):
                self.out.append(p.Reply(msg.TYPE, p.Result.OK, 0))
            self.ready.notify()

    def recv(self, timeout):
        with self.ready:
            if not self.out:
                self.ready.wait(timeout)
            return self.out.pop(0) if self.out else None

    def close(self) -> None:
        pass

    counters = {"frames_rx": 0, "frames_tx": 0, "crc_errors": 0, "dropped_frames": 0}


def test_a_device_reporting_max_block_0_is_refused_at_connect():
    t0 = time.monotonic()
    link = _Device(max_block=0)
    with pytest.raises(DriverError, match="max_block=0"):
        Amplifier(link, timeout=1.0)
    assert time.monotonic() - t0 < 1.0 and link.sent < 10  # refused at once, no busy loop
    Amplifier(_Device(max_block=64), timeout=1.0).close()  # a sane device connects
