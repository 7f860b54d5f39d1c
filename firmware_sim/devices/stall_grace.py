"""Silence timeouts judged in a simulated drive's monitor loop without faulting for the simulator's own stalls.

A drive hears its bus in an interrupt, so a host frame is seen when it arrives. A simulated drive hears it
when its receiving thread runs. When the simulator process is descheduled for longer than a timeout, frames
the host sent meanwhile wait unread in the socket. A monitor that wakes first would then trip on a host that
never went silent.

After a stall of the monitor loop, silences are not judged for ``grace`` seconds, the time the receiver gets
to catch up. A new window opens only ``grace + timeout`` after the last one, so however the loop is
scheduled, a silent host still trips, at most ``grace`` late.
"""

from __future__ import annotations

import math


class StallGrace:
    """Decides, at each wake of a monitor loop, whether silence timeouts may be judged now.

    Args:
        stall: a wake later than this after the previous one means the process was descheduled, s.
        grace: how long judging waits after such a stall, s.
    """

    def __init__(self, stall: float = 0.02, grace: float = 0.05) -> None:
        self.stall, self.grace = stall, grace
        self.last = math.nan
        self.opened = -math.inf

    def may_judge(self, now: float, timeout: float) -> bool:
        """Call at every wake with the monotonic time ``now`` (s) and the shortest silence timeout being judged
        (s); True when the silences may be judged at ``now``."""
        late = now - self.last > self.stall  # False on the first wake (nan)
        self.last = now
        if late and now - self.opened > self.grace + timeout:
            self.opened = now
        return now - self.opened >= self.grace
