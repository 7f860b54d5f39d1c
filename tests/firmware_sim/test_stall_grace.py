"""StallGrace against scripted monitor wakes and host frames: the simulated drive must not fault for its own
stall, and a silent host must still trip, at most ``grace`` (plus one wake) late, however the loop is woken."""

import numpy as np
import pytest

from hilbench.firmware_sim.devices.stall_grace import StallGrace

TIMEOUT = 0.1  # s


def first_trip(wakes, heard, grace: StallGrace | None):
    """The first wake at which the monitor trips: ``heard(now)`` is the host's last frame the receiver has
    processed by ``now``; without a StallGrace every wake judges."""
    for now in wakes:
        if (grace is None or grace.may_judge(now, TIMEOUT)) and now - heard(now) > TIMEOUT:
            return now
    return None


def live_host_and_stall(now: float) -> float:
    """A host sending every 10 ms; the simulator process is descheduled from 1.0 to 1.5 s, and its receiver
    reads the frames that waited in the socket 5 ms after it runs again."""
    seen = 1.0 if 1.0 < now < 1.505 else now
    return np.floor(seen / 0.01) * 0.01


def stalled_wakes():
    return np.concatenate([np.arange(0.0, 1.0, 0.002), np.arange(1.5, 2.0, 0.002)])


def test_the_simulators_own_stall_does_not_trip_and_would_without_the_grace():
    assert first_trip(stalled_wakes(), live_host_and_stall, StallGrace()) is None
    assert first_trip(stalled_wakes(), live_host_and_stall, None) == pytest.approx(1.5)


@pytest.mark.parametrize("schedule", ["on time", "one stall", "always 25 ms late", "late every other wake"])
def test_a_silent_host_trips_at_most_grace_late(schedule):
    silent_from = 0.95  # s: the host's last frame (with one stall, its timeout ends inside the stall)

    def heard(now):
        return min(np.floor(now / 0.01) * 0.01, silent_from)

    wakes = {"on time": np.arange(0.0, 2.0, 0.002),
             "one stall": stalled_wakes(),
             "always 25 ms late": np.arange(0.0, 2.0, 0.027),
             "late every other wake": np.cumsum(np.tile([0.002, 0.03], 70))}[schedule]
    grace = StallGrace()
    tripped = first_trip(wakes, heard, grace)
    unguarded = first_trip(wakes, heard, None)
    assert tripped is not None and unguarded is not None
    # the bound: grace, plus the gap to the next wake that may judge
    gap = np.diff(wakes).max()
    assert unguarded <= tripped <= unguarded + grace.grace + gap, (tripped, unguarded)
    if schedule == "one stall":
        assert (unguarded, tripped) == pytest.approx((1.5, 1.5 + grace.grace), abs=0.0021)
