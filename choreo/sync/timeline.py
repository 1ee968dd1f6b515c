"""A Link session's beat against time, and Link's clock against the machine's: pure arithmetic.

Link keeps its own clock (microseconds on CLOCK_MONOTONIC_RAW on Linux, mach_absolute_time on
macOS, the performance counter on Windows), which is not the monotonic clock a run schedules
on: on Linux the two are hundreds of milliseconds apart and NTP slews one but not the other. So
the two are never tied by one fixed offset: each sample reads Link's clock between two reads of
the monotonic clock, and the freshest, tightest such pair maps one to the other.

Link shares a session's tempo and its phase within a quantum (a bar, here), not its beat
numbers: a peer that joins counts beats of its own, a whole number of bars off the others'.
Hosts of one show therefore meet on bar lines (phase 0), and each counts the show's beats from
the bar line it started on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

US_PER_MINUTE = 60e6
BAR_EPSILON = 1e-6  # beats: a bar line this near is the bar line (a sample's rounding, not a beat late)


@dataclass(frozen=True)
class Timeline:
    """The session's beat timeline as one sample saw it: `beat` at Link time `link_us`, going
    on at `tempo` beats a minute until a peer changes it (Link keeps the beat continuous
    through a tempo change: the beat at the change stays where it was)."""

    link_us: float
    beat: float
    tempo: float

    def beat_at(self, link_us: float) -> float:
        return self.beat + (link_us - self.link_us) * self.tempo / US_PER_MINUTE

    def time_at(self, beat: float) -> float:
        """Link time (us) of `beat` on this timeline."""
        return self.link_us + (beat - self.beat) * US_PER_MINUTE / self.tempo


@dataclass(frozen=True)
class ClockPair:
    """Link's clock read between two reads of the monotonic clock: `mono_ns` is their middle,
    `window_ns` how far apart they were (the pair's uncertainty, twice over)."""

    mono_ns: int
    link_us: float
    window_ns: int

    def mono_of(self, link_us: float) -> float:
        """Monotonic seconds of a Link time."""
        return (self.mono_ns + (link_us - self.link_us) * 1e3) / 1e9

    def link_of(self, mono: float) -> float:
        """Link time (us) of a monotonic instant (seconds)."""
        return self.link_us + (mono * 1e9 - self.mono_ns) / 1e3


def tighter(best: ClockPair | None, pair: ClockPair, max_age_ns: int) -> ClockPair:
    """The pair to map by: the new one if the kept one is older than `max_age_ns` (the two
    clocks drift apart as NTP slews one) or no tighter; else the kept one."""
    if best is None or pair.mono_ns - best.mono_ns > max_age_ns or pair.window_ns <= best.window_ns:
        return pair
    return best


def bar_at_or_after(beat: float, quantum: int) -> float:
    """The first bar line (a beat whose phase in the quantum is 0) at or after `beat`."""
    return math.ceil((beat - BAR_EPSILON) / quantum) * quantum


def whole_bars(jump: float, quantum: int, tolerance: float = 0.01) -> int | None:
    """A jump of the beat count by a whole number of bars (a renumbering: the phase is where it
    was) as that number; None for a jump that moved the phase."""
    bars = round(jump / quantum)
    return bars if abs(jump - bars * quantum) <= tolerance else None
