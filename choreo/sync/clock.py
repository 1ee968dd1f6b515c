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
    """A ShowClock and a BeatGrid on `session`: the show's start (show time `origin_s`, the
    show's beat `origin_beats`: 0 and 0 for a whole show, --from's step otherwise) plays at
    monotonic `start`, on the session's continuous beat `start_beat`, bars of `meter` beats.

    Where the show stands on the session is one tuple (show time 0's monotonic time, the
    session's beat of the show's beat 0), replaced whole: runners on other threads read it
    while a late change of the session moves the start (`realign`)."""

    def __init__(self, session: LinkSession, start: float, start_beat: float, meter: int,
                 origin_s: float = 0.0, origin_beats: float = 0.0) -> None:
        self.session = session
        self.meter = meter
        self.origin_s = origin_s
        self.origin_beats = origin_beats
        self._place = (start - origin_s, start_beat - origin_beats)

    @property
    def zero(self) -> float:
        """Monotonic time of show time 0."""
        return self._place[0]

    @property
    def first_bar(self) -> float:
        """The session's continuous beat of the show's beat 0 (bar 1 beat 1)."""
        return self._place[1]

    def mono_at(self, show_s: float) -> float:
        return self._place[0] + show_s

    def show_at(self, mono: float) -> float:
        return mono - self._place[0]

    def beats_of(self, bar: int, beat: float) -> float:
        """The show's beat (0: bar 1 beat 1) of a bar and beat as a show writes them."""
        return (bar - 1) * self.meter + (beat - 1)

    def at_beat(self, bar: int, beat: float) -> float:
        """Show time at which bar `bar`, beat `beat` falls on the session's timeline now."""
        zero, first_bar = self._place
        return self.session.snapshot().mono_of_beat(first_bar + self.beats_of(bar, beat)) - zero

    def show_beat(self, mono: float) -> float:
        """The show's beat at monotonic time `mono` (what the log's clock samples carry)."""
        return self.session.snapshot().beat_at_mono(mono) - self._place[1]

    def realign(self, earliest: float, tempo_changed: bool = False) -> bool:
        """Before the show's start, the session's bars moved: the start goes back onto them, on
        every host alike. A tempo change (during the count-in) keeps the session's beat the show
        was to start on, now sooner or later (sooner than the runners' lead: its first cue a
        little late, never a bar later); a jump of the phase (a peer found late, and Link moved
        this host onto the session's phase) takes the beat of the same phase nearest where the
        start was, at or after monotonic `earliest` (the runners' lead), else the next bar's.
        True if it moved; never once the show has begun."""
        zero, first_bar = self._place
        start = zero + self.origin_s
        if time.monotonic() >= start:
            return False
        snapshot = self.session.snapshot()
        start_beat = first_bar + self.origin_beats
        phase = start_beat % self.meter
        if not tempo_changed:
            near = snapshot.beat_at_mono(start)
            start_beat = round((near - phase) / self.meter) * self.meter + phase
            if snapshot.mono_of_beat(start_beat) < earliest:
                start_beat = bar_at_or_after(snapshot.beat_at_mono(earliest) - phase, self.meter) + phase
        # a tempo change keeps the beat whatever: a ramp (a change every 20 ms) moving the start
        # on by a bar whenever it came near would make each host's start recede, each its own way
        moved = (snapshot.mono_of_beat(start_beat) - self.origin_s, start_beat - self.origin_beats)
        if abs(moved[0] - zero) < 1e-6 and abs(moved[1] - first_bar) < 1e-9:
            return False
        self._place = moved
        return True
