"""One monotonic clock for a run, anchored once to the wall clock.

Log times must be wall-clock nanoseconds (Foxglove shows them as dates) but must never jump
when NTP adjusts the system time mid-show, so every timestamp is the monotonic clock plus one
offset taken at the start. Cue timing uses the same monotonic clock.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

# The last stretch before a cue is spun, not slept: sleep() on a loaded machine overshoots by
# up to a millisecond or more, and a cue's first byte must leave within 1 ms of its time.
SPIN_S = 0.002
# Background work (writing the log) runs only before a sleep with at least this much to spare.
IDLE_S = 0.01


@dataclass
class RunClock:
    """Monotonic seconds for scheduling, anchored wall-clock nanoseconds for the log."""

    mono_anchor_ns: int = field(default_factory=time.monotonic_ns)
    wall_anchor_ns: int = field(default_factory=time.time_ns)

    @staticmethod
    def mono() -> float:
        return time.monotonic()

    def wall_ns(self, mono_ns: int | None = None) -> int:
        """Wall-clock nanoseconds of a monotonic instant (now if not given)."""
        if mono_ns is None:
            mono_ns = time.monotonic_ns()
        return self.wall_anchor_ns + mono_ns - self.mono_anchor_ns

    def to_wall_ns(self, mono_s: float) -> int:
        return self.wall_anchor_ns + round(mono_s * 1e9) - self.mono_anchor_ns

    def sleep_until(self, deadline: float, should_stop: Callable[[], bool] = lambda: False,
                    slice_s: float = 0.05, on_idle: Callable[[], None] | None = None) -> bool:
        """Sleep until a monotonic deadline, spinning the last SPIN_S; False if told to stop.

        Sleeps in slices so that a stop request (Ctrl-C) is seen within `slice_s`. Before each
        slice with more than IDLE_S to spare, `on_idle` runs: the time to write the log.
        """
        while True:
            if should_stop():
                return False
            left = deadline - time.monotonic()
            if left <= 0:
                return True
            if left > SPIN_S:
                if on_idle is not None and left > IDLE_S:
                    on_idle()
                    left = deadline - time.monotonic()
                    if left <= SPIN_S:
                        continue
                time.sleep(min(left - SPIN_S, slice_s))
            # else: spin until the deadline
