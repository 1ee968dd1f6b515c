"""The show clock on a Link session: seconds run on the machine's clock, bars on the session's.

Show time 0 is the bar line the show started on (the same instant on every host of the show),
and show time runs in real seconds from there, so a cue written in seconds stays on seconds
and every review reads a Link show as any other. A cue written in bars and beats is placed on
the session's beat timeline as it stands when the runner looks (`at_beat`, a `BeatGrid`): a
tempo change by any peer moves every such cue still to come; a frame already sent stays sent.
"""

from __future__ import annotations

import time

from choreo.sync.session import LinkSession
from choreo.sync.timeline import bar_at_or_after


class LinkShowClock:
    """A ShowClock and a BeatGrid on `session`: show time 0 at monotonic `zero`, which is the
    session's continuous beat `first_bar` (a bar line), bars of `meter` beats."""

    def __init__(self, session: LinkSession, zero: float, first_bar: float, meter: int) -> None:
        self.session = session
        self.zero = zero
        self.first_bar = first_bar
        self.meter = meter

    def mono_at(self, show_s: float) -> float:
        return self.zero + show_s

    def show_at(self, mono: float) -> float:
        return mono - self.zero

    def beats_of(self, bar: int, beat: float) -> float:
        """The show's beat (0: bar 1 beat 1) of a bar and beat as a show writes them."""
        return (bar - 1) * self.meter + (beat - 1)

    def at_beat(self, bar: int, beat: float) -> float:
        """Show time at which bar `bar`, beat `beat` falls on the session's timeline now."""
        return self.session.snapshot().mono_of_beat(self.first_bar + self.beats_of(bar, beat)) - self.zero

    def show_beat(self, mono: float) -> float:
        """The show's beat at monotonic time `mono` (what the log's clock samples carry)."""
        return self.session.snapshot().beat_at_mono(mono) - self.first_bar

    def realign(self, earliest: float) -> bool:
        """Before show time 0, the session's bars moved (a peer found late and Link moved this
        host onto the session's phase, or a peer changed the tempo during the count-in): show
        time 0 goes onto the session's bar line nearest where it was, at or after monotonic
        `earliest` (the runners' lead), so the show still starts on a bar line, the same one
        on every host. True if it moved; never once the show has begun."""
        if time.monotonic() >= self.zero:
            return False
        snapshot = self.session.snapshot()
        first = bar_at_or_after(snapshot.beat_at_mono(max(self.zero - 0.5 * 60.0 / snapshot.tempo, earliest)),
                                self.meter)
        zero = snapshot.mono_of_beat(first)
        if abs(zero - self.zero) < 1e-6 and abs(first - self.first_bar) < 1e-9:
            return False
        self.zero, self.first_bar = zero, first
        return True
