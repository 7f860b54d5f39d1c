"""CiA 402 definitions and host-clocked timing figures, without I/O."""

import numpy as np
import pytest

from hilbench.drivers import cia402 as c
from hilbench.drivers.device import Capabilities, refusal
from hilbench.drivers.host_cycle import JITTER_LIMIT, timing_summary

pytestmark = pytest.mark.drives

# The statusword table of CiA 402 (bits 0-3, 5, 6), written out independently of cia402._STATUS_PATTERNS:
# (bits that must be 1, bits that must be 0, state)
TABLE = [
    (0x0000, 0x004F, c.State.NOT_READY),
    (0x0040, 0x000F, c.State.SWITCH_ON_DISABLED),
    (0x0021, 0x004E, c.State.READY),
    (0x0023, 0x004C, c.State.SWITCHED_ON),
    (0x0027, 0x0048, c.State.OPERATION_ENABLED),
    (0x0007, 0x0068, c.State.QUICK_STOP),
    (0x000F, 0x0040, c.State.FAULT_REACTION),
    (0x0008, 0x0047, c.State.FAULT),
]


def test_every_statusword_decodes_as_the_table_says():
    for word in range(1 << 16):
        want = [s for ones, zeros, s in TABLE if word & ones == ones and word & zeros == 0]
        assert c.state_of(word) is (want[0] if want else None), hex(word)


def test_state_machine_walk_and_fault_reset():
    s = c.State.SWITCH_ON_DISABLED
    for cmd, want in ((c.Command.SHUTDOWN, c.State.READY), (c.Command.SWITCH_ON, c.State.SWITCHED_ON),
                      (c.Command.ENABLE_OPERATION, c.State.OPERATION_ENABLED),
                      (c.Command.SWITCH_ON, c.State.SWITCHED_ON), (c.Command.ENABLE_OPERATION,
                                                                   c.State.OPERATION_ENABLED),
                      (c.Command.QUICK_STOP, c.State.QUICK_STOP)):
        s = c.next_state(s, cmd)
        assert s is want
    assert c.next_state(c.State.FAULT, c.Command.ENABLE_OPERATION) is c.State.FAULT
    assert c.next_state(c.State.FAULT, c.Command.FAULT_RESET) is c.State.SWITCH_ON_DISABLED
    # the command values decode back to themselves
    for cmd in c.Command:
        assert c.command_of(int(cmd)) is cmd
    # a statusword the drive reports for each state decodes to that state
    for state, bits in c.STATUS_BITS.items():
        assert c.state_of(bits | c.REMOTE | c.VOLTAGE_ENABLED * (state is not c.State.FAULT)) is state


def test_torque_per_mille_round_trip_and_limits():
    rated = 0.5  # N*m
    torque = np.array([0.0, 0.0005, -0.2, 3.2])
    pm = c.torque_to_permille(torque, rated)
    np.testing.assert_array_equal(pm, [0, 1, -400, 6400])
    np.testing.assert_allclose(c.permille_to_torque(pm, rated), torque, atol=rated / 2000)
    with pytest.raises(ValueError, match="32.767"):
        c.torque_to_permille(np.array([17.0]), rated)
    assert c.max_torque_permille(20.0, 0.2, 0.5) == 8000  # 4 N*m of 0.5 N*m
    assert c.max_torque_permille(1e9, 0.2, 0.5) == 65535


def test_emcy_texts():
    assert c.emcy_text(0x2310) == "continuous over-current (device output side)"
    assert c.emcy_text(0x8130) == "life guard error or heartbeat error"
    assert "temperature" in c.emcy_text(0x4399)
    assert c.emcy_text(0xFF42) == "device specific"


def test_refusal_is_one_line_naming_mode_and_rate():
    caps = Capabilities({"current": (1000, 2000)})
    assert refusal("drive", caps, "current", 1000) is None
    assert refusal("drive", caps, "velocity", 1000) == "drive cannot run velocity mode (it offers current at 1000, " \
                                                       "2000 Hz)"
    why = refusal("drive", caps, "current", 10000)
    assert "10000 Hz" in why and "--sample-rate 1000" in why and "\n" not in why


def test_timing_summary_closed_forms():
    rate, period, n = 1000.0, 1e-3, 10_000
    due = np.arange(n) * period
    # perfect cycle: every figure is the period, nothing missed or late
    s = timing_summary(due + 0.5, due + 0.5, rate)
    assert (s.p50, s.max, s.missed, s.late) == (pytest.approx(period), pytest.approx(period), 0, 0)
    assert s.fit and "fit for identification" in s.line()
    # one trigger 3.4 periods late, the next ones catch up back to back: round(4.4) - 1 = 3 slots empty
    sent = due.copy()
    sent[5000:5004] = due[5000] + 3.4 * period  # cycles 5000..5003 go out together
    s = timing_summary(sent, due, rate)
    assert s.missed == 3
    assert s.late == 4  # the last of them, cycle 5003, was due at +3 periods: 0.4 periods late, > 0.25
    assert s.max == pytest.approx(4.4 * period)
    # uniform jitter of +-30 % of the period: |d - T| reaches 0.6 T, far beyond the 10 % limit
    rng = np.random.default_rng(0)
    sent = due + rng.uniform(-0.3, 0.3, n) * period
    s = timing_summary(sent, due, rate)
    assert s.jitter_p99 > JITTER_LIMIT * period and not s.fit
    assert "UNFIT" in s.line() and len(s.line().encode()) <= 256  # fits a run-file event
