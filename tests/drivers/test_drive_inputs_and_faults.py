"""Issue #30 items 5, 9, 10 and 11 on the off-the-shelf drive path.

5. A run that ends short is never ``completed``: an ODrive that vanished mid-run gave exit 0, ``completed``,
   171 of 6000 samples.
9. ``info`` and ``fault show|clear`` work on every device kind (they crashed on CiA 402 and ODrive), and messages
   name CLI commands, not Python methods.
10. Bad drive descriptions are refused in one line before anything is sent (an EDS declaring 0x6077 REAL32 gave
    a bare AssertionError after the drive was armed; ``tvl_endpoint=-1`` a struct.error after commands went out).
11. ``hilbench sim`` refuses bad nodes, interfaces and channels in one line, exit 2.
"""

from __future__ import annotations

import threading
import uuid

import can
import canopen
import h5py
import numpy as np
import pytest

from hilbench.bench.acquisition.protocols import Identification
from hilbench.bench.acquisition.runner import Bench, DeviceSettings
from hilbench.common.runfile.schema import DeviceIdentity
from hilbench.drivers import cia402 as c
from hilbench.drivers import protocol as p
from hilbench.drivers.canopen_drive import CanopenDrive
from hilbench.drivers.device import Capabilities, CycleSamples, Device
from hilbench.drivers.device_url import check_device_url, open_device
from hilbench.drivers.errors import ConfigError, DeviceTimeoutError, DeviceURLError, SampleLossError
from hilbench.drivers.odrive_drive import OdriveDrive
from hilbench.firmware_sim.devices.cia402_drive import EDS_PATH, SimCia402Drive
from hilbench.firmware_sim.devices.odrive_sim import TVL_ENDPOINT, SimOdrive
from hilbench.firmware_sim.devices.sim_config import load_sim_config
from tests.reliability.cli import hilbench, one_line_error

pytestmark = [pytest.mark.drives, pytest.mark.usefixtures("starts_devices")]  # starts a device
# ---------------------------------------------------------------- item 5
def test_an_odrive_that_vanishes_mid_run_is_never_completed(tmp_path):
    channel = uuid.uuid4().hex[:8]
    bus = can.Bus(interface="virtual", channel=channel)
    sim = SimOdrive(bus, 3, load_sim_config(), watchdog_timeout=1.0)
    host = OdriveDrive("virtual", channel, 3, TVL_ENDPOINT, timeout=0.5)
    out = tmp_path / "run.h5"
    bench = Bench(host, f"odrive://virtual/{channel}", DeviceSettings(counts_per_rev=1 << 20, watchdog_timeout=1.0))
    killer = threading.Thread(target=sim.close)  # the axis loses power 1 s into the run: its frames stop

    def progress(prog) -> None:
        if prog.done >= 1000 and not killer.is_alive() and killer.ident is None:
            killer.start()

    try:
        with pytest.raises(DeviceTimeoutError, match=r"stopped sending its cyclic messages at sample \d+ of 6000"):
            bench.run(Identification(duration=6.0, amplitude=2.0, sample_rate=1000), out, progress=progress)
    finally:
        if killer.ident is not None:
            killer.join()
        else:
            sim.close()
        host.close()
        bus.shutdown()
    with h5py.File(out) as f:
        assert f.attrs["status"] == "aborted"
        n = f["samples/t"].size
        errors = [e["message"] for e in f["events"][:] if e["kind"] in (b"error", "error")]
    assert 0 < n < 6000 and errors, (n, errors)


class ShortDevice(Device):
    """A device whose stream ends early without saying why (the runner's own check, whatever the driver)."""

    clock = "host"
    capabilities = Capabilities({"current": (1000,)})

    def info(self) -> DeviceIdentity:
        return DeviceIdentity(model="short")

    def configure(self, config) -> None:
        self.config = config

    def arm(self) -> None:
        pass

    def disarm(self) -> None:
        pass

    def estop(self) -> None:
        pass

    def close(self) -> None:
        pass

    def stream(self, setpoints):
        n = len(setpoints) // 3
        z = np.zeros(n)
        yield CycleSamples(np.arange(n), z, z.astype(np.int64), z, z, z, z, z, z, 1000)


@pytest.mark.device_free  # no device: the parallel part
def test_the_runner_never_calls_a_short_stream_completed(tmp_path):
    bench = Bench(ShortDevice(), "short://")
    with pytest.raises(SampleLossError, match="returned 1000 of the 3000 samples of step 0"):
        bench.run(Identification(duration=3.0, amplitude=1.0, sample_rate=1000), tmp_path / "s.h5")
    with h5py.File(tmp_path / "s.h5") as f:
        assert f.attrs["status"] == "aborted" and f["samples/t"].size == 1000


# ---------------------------------------------------------------- item 9
def test_fault_show_and_clear_on_a_faulted_cia402_drive_name_codes_and_cli_commands():
    channel = f"f-{uuid.uuid4().hex[:8]}"
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    sim = SimCia402Drive(network, 3, load_sim_config(), clock="sync", sync_timeout=1.0)
    try:
        sim.fault(0x8250, 0x10)  # what a lost host leaves: SYNC lost
        host = CanopenDrive("virtual", channel, 3, str(EDS_PATH), timeout=1.0)
        try:
            assert host.faults() == ["0x603F error code 0x8250 RPDO timeout (error register 0x11)"]
            assert host.history() == ["0x1003 error history (1, newest first): 0x8250 RPDO timeout"]
            assert host.state() == "fault (statusword 0x0208)"
            host.configure(p.Config(sample_rate=1000, current_limit=20.0, torque_constant=0.2,
                                    counts_per_rev=1 << 20))
            with pytest.raises(Exception, match="clear it with `hilbench fault clear --device URL` first"):
                host.arm()
            host.clear_faults()  # the fault-reset edge
            assert host.faults() == [] and sim.state is c.State.SWITCH_ON_DISABLED
            host.arm()
            assert sim.state is c.State.OPERATION_ENABLED and sim.target_pm == 0  # zero torque before enable
        finally:
            host.close()
        # close leaves it as found: heartbeat consumer off, NMT pre-operational
        assert sim.node.nmt.state == "PRE-OPERATIONAL" and sim._host_hb is None
    finally:
        sim.close()
        network.disconnect()


def test_info_and_fault_on_an_odrive_through_the_base_class():
    channel = uuid.uuid4().hex[:8]
    bus = can.Bus(interface="virtual", channel=channel)
    sim = SimOdrive(bus, 2, load_sim_config(), watchdog_timeout=1.0)
    try:
        sim._trip(0x800)
        host = OdriveDrive("virtual", channel, 2, TVL_ENDPOINT, timeout=1.0)
        try:
            host._wait_heartbeat(lambda: host.axis_error != 0, "the error")
            assert host.state() == "idle (axis state 1)"
            assert host.faults() == ["ODrive axis error 0x00000800: watchdog timer expired"]
            assert host.history() == []
            host.clear_faults()
            assert host.faults() == [] and sim.error == 0
        finally:
            host.close()
    finally:
        sim.close()
        bus.shutdown()


@pytest.mark.device_free  # no device: the parallel part
def test_no_message_names_a_python_method():
    import pathlib
    import re

    root = pathlib.Path(__file__).resolve().parents[2] / "drivers"
    offenders = [f"{path.name}: {m.group(0)}" for path in root.glob("*.py")
                 for m in re.finditer(r'f?"[^"\n]*call \w+\(\)[^"\n]*"', path.read_text())]
    assert offenders == []


# ---------------------------------------------------------------- item 10
@pytest.mark.device_free  # no device: the parallel part
@pytest.mark.parametrize("data_type, name", [("0x0008", "REAL32"), ("0x0015", "INTEGER64")])
def test_an_eds_with_a_wrong_pdo_type_is_refused_before_anything_is_sent(tmp_path, data_type, name):
    text = EDS_PATH.read_text()
    start = text.index("[6077]")
    section = text[start:text.index("\n\n", start)]
    eds = tmp_path / "bad.eds"
    eds.write_text(text.replace(section, section.replace("DataType=0x0003", f"DataType={data_type}")))
    channel = uuid.uuid4().hex[:8]
    listener = can.Bus(interface="virtual", channel=channel)
    try:
        with pytest.raises(ConfigError) as err:
            open_device(f"canopen://virtual/{channel}?node=3&eds={eds}")
        assert listener.recv(0.2) is None  # not one frame went out
    finally:
        listener.shutdown()
    assert str(err.value) == (f"EDS {eds} declares 0x6077 (Torque actual value) as {name}; CiA 402 and this host's "
                              f"PDO mapping take it as INTEGER16")


@pytest.mark.device_free  # no device: the parallel part
@pytest.mark.parametrize("endpoint", ["-1", "65536", "70000"])
def test_a_tvl_endpoint_out_of_range_is_one_line(endpoint):
    channel = uuid.uuid4().hex[:8]
    listener = can.Bus(interface="virtual", channel=channel)
    try:
        with pytest.raises(DeviceURLError, match=r"tvl_endpoint must be 0..65535"):
            open_device(f"odrive://virtual/{channel}?node=1&tvl_endpoint={endpoint}")
        assert listener.recv(0.2) is None
    finally:
        listener.shutdown()


@pytest.mark.device_free  # no device: the parallel part
def test_canopen_node_127_is_the_hosts_heartbeat_id():
    check_device_url(f"canopen://virtual/x?node=126&eds={EDS_PATH}")
    with pytest.raises(DeviceURLError, match=r"node must be 1..126 \(127 is the host's own heartbeat id\)"):
        open_device(f"canopen://virtual/x?node=127&eds={EDS_PATH}")


# ---------------------------------------------------------------- item 11
@pytest.mark.parametrize("args, words", [
    (["--canopen", "vcan0", "--node", "0"], "--node must be 1..126 for --canopen, got 0"),
    (["--canopen", "239.1.2.3", "--interface", "udp_multicast", "--node", "200"], "--node must be 1..126"),
    (["--odrive", "239.1.2.3", "--interface", "udp_multicast", "--node", "100"], "--node must be 0..63"),
    (["--odrive", "1.2.3.4", "--interface", "udp_multicast"], "needs a multicast group address"),
    (["--canopen", "vcan0", "--interface", "nonsense"], "is not a python-can interface"),
    (["--can", "vcan0", "--node", "16"], "--node must be 1..15 for --can"),
])
@pytest.mark.device_free  # refused before any device starts (hilbench sim would exec one: the guard would see it)
def test_bad_sim_arguments_are_one_line_exit_2(args, words, capsys):
    line = one_line_error(hilbench("sim", *args, timeout=60))
    assert line.startswith("hilbench sim: error: ") and words in line, line
    # the simulator's own entry point (python -m hilbench.firmware_sim runs sys.exit(main())), in this process:
    # a simulator process, even one that only refuses its arguments, counts as a device started
    from hilbench.firmware_sim.__main__ import main as firmware_main

    assert firmware_main(list(args)) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1 and "Traceback" not in err, err


@pytest.mark.device_free  # no device: the parallel part
def test_sim_passes_the_drive_behaviours_to_the_simulated_drive():
    from hilbench.bench.cli import build_parser
    from hilbench.bench.cli.commands.sim import firmware_argv
    from hilbench.firmware_sim.__main__ import build_parser as firmware_parser

    args = build_parser().parse_args(["sim", "--canopen", "239.1.2.3", "--interface", "udp_multicast",
                                      "--order", "sample-then-apply", "--enable-latency", "2"])
    argv = firmware_argv(args)
    assert "--order=sample-then-apply" in argv and "--enable-latency=2" in argv
    parsed = firmware_parser().parse_args(argv[3:])  # after python -m hilbench.firmware_sim
    assert parsed.order == "sample-then-apply" and parsed.enable_latency == 2 and parsed.canopen == "239.1.2.3"


# ---------------------------------------------------------------- item 3, between streams and on a shared bus
def test_an_owner_between_streams_keeps_its_drive_and_another_hosts_heartbeat_does_not_claim_a_fresh_one():
    from hilbench.drivers.errors import PortBusyError

    channel = f"o-{uuid.uuid4().hex[:8]}"
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    owned = SimCia402Drive(network, 3, load_sim_config(), clock="sync", sync_timeout=1.0)
    fresh = SimCia402Drive(network, 4, load_sim_config(), clock="sync", sync_timeout=1.0)
    try:
        owner = CanopenDrive("virtual", channel, 3, str(EDS_PATH), timeout=1.0)
        try:
            owner.configure(p.Config(sample_rate=1000, current_limit=20.0, torque_constant=0.2,
                                     counts_per_rev=1 << 20, watchdog_timeout=1.0))
            owner.arm()  # armed, between streams: no SYNC, no PDO, only heartbeats
            with pytest.raises(PortBusyError, match=r"a host heartbeat \(0x77F\) on the bus; the drive is NMT "
                                                    r"operational"):
                CanopenDrive("virtual", channel, 3, str(EDS_PATH), timeout=1.0)
            assert owned.state is c.State.OPERATION_ENABLED  # the refused host disturbed nothing
            other = CanopenDrive("virtual", channel, 4, str(EDS_PATH), timeout=1.0)  # same bus, its own drive
            other.close()
        finally:
            owner.close()
        CanopenDrive("virtual", channel, 3, str(EDS_PATH), timeout=1.0).close()  # free once the owner closed
    finally:
        owned.close()
        fresh.close()
        network.disconnect()


def test_an_armed_odrive_between_streams_is_refused_to_a_second_host():
    from hilbench.drivers.errors import PortBusyError

    channel = uuid.uuid4().hex[:8]
    bus = can.Bus(interface="virtual", channel=channel)
    sim = SimOdrive(bus, 2, load_sim_config(), watchdog_timeout=1.0)
    try:
        owner = OdriveDrive("virtual", channel, 2, TVL_ENDPOINT, timeout=1.0)
        try:
            owner.configure(p.Config(sample_rate=1000, current_limit=20.0, torque_constant=0.2,
                                     counts_per_rev=1 << 20, watchdog_timeout=1.0))
            owner.arm()  # closed loop, the watchdog fed with zero torque every 20 ms
            with pytest.raises(PortBusyError, match=r"the axis is in closed loop control and another host sends it "
                                                    r"SET_INPUT_TORQUE\); nothing was sent to it"):
                OdriveDrive("virtual", channel, 2, TVL_ENDPOINT, timeout=1.0)
            assert sim.state == 8 and sim.error == 0  # undisturbed
        finally:
            owner.close()
        OdriveDrive("virtual", channel, 2, TVL_ENDPOINT, timeout=1.0).close()  # idle again: free
    finally:
        sim.close()
        bus.shutdown()
