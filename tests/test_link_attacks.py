"""Defects found attacking the Link show clock (issue 25's review, R1): each test names the
defect it shows, and fails until the fix is in. Fake Link peers (test_sync_timeline's), no
network, no wall-clock assertions.
"""

from __future__ import annotations

import time
from typing import Any

import pytest

from choreo.sync.clock import LinkShowClock
from choreo.sync.session import LinkSnapshot
from choreo.sync.start import LinkStart
from choreo.sync.timeline import ClockPair, Timeline
from test_sync_timeline import BEATS, FakeLink, FakeSession, OneSnapshot, _find, fake  # noqa: F401 fake is a fixture used by name


def test_a_renumbering_in_the_sample_a_tempo_change_arrives_in_is_taken_out(fake):  # noqa: F811 the fixture
    """DEFECT: LinkSession._changes skips the jump check on any sample whose tempo changed, so a
    whole-bar renumbering by Link that arrives with a tempo change stays in the beats: seen for
    real under a peer's tempo flood (the show beat went 40.53 -> 44.71, every bar still to come
    played one bar early). A jump of whole bars is a renumbering whatever the tempo did."""
    session, link, heard = fake
    with link.lock:  # one sample sees both: the tempo changed and the count moved by two bars
        now = FakeLink._now_us()
        link._origin = (now, link._beat_at(now) + 8.0)
        link._tempo = 150.0
    heard.wait_for("tempo")
    snapshot = session.snapshot()
    assert snapshot.shift == 8.0
    assert snapshot.beat_at_mono(time.monotonic()) == pytest.approx(link.beat - 8.0, abs=BEATS)


def test_a_waiting_host_that_finds_the_session_already_started_starts_on_its_bar_line():
    """DEFECT: find_start (waiting: a hosts: show, --wait-start) counts only a stopped -> playing
    transition it sees itself. A host that joined Link, then opened its ports while a peer
    started the transport (its bar line still ahead), reads `playing` already true when its
    wait begins and waits for ever, though Link told it: seen for real with two hosts and a
    peer starting 1 s after they joined. A session already playing when the wait begins is a
    start just heard: its bar line, or 'missed' if that is MISSED_S gone."""
    session = FakeSession(beat_now=3.2, playing=True)
    session.started_at = Timeline(*session.origin, session.tempo).time_at(4.0)  # 0.4 s ahead at 120 bpm
    bar, told = _find(session, LinkStart(True, None, 0.25), stop=lambda: session.looks > 40)
    assert bar == 0.0, told
    assert ("count_from_start",) in session.calls


class LinkLikeSession(FakeSession):
    """count_from_start as aalink's Link does it in a session with peers: the count cannot move
    the phase, so beat 0 goes to the NEXT time at or after the transport's start at which the
    phase is 0 (seen for real: a start 10 us after a bar line put beat 0 a bar later)."""

    def count_from_start(self) -> float:
        self.calls.append(("count_from_start",))
        phase = Timeline(*self.origin, self.tempo).beat_at(self.started_at) % self.quantum
        self.origin = (self.started_at, 0.0 if phase < 1e-9 else phase - self.quantum)
        return self.origin[1]  # the start's beat in the new count (the session measures it)


def test_a_transport_started_a_hair_after_its_bar_line_starts_the_show_on_that_bar_line():
    """DEFECT: _joined takes the first bar line at or after beat 0 of the renumbered count, and
    Link puts beat 0 on the bar line AFTER a start that is a little late (an audio buffer's
    rounding, a peer's microseconds): every host starts a whole bar after the session (Live's
    music) started. Seen for real: a peer's start 2 ms (and, one run in two, 10 us) after bar
    16 started the show at bar 20. The bar line nearest the transport's start is the show's."""
    session = LinkLikeSession(beat_now=3.0)

    def peer_plays(look: int) -> None:
        if look == 3:  # the transport starts 2 ms after the bar line just ahead (beat 4 at 120 bpm)
            session.playing = True
            session.started_at = Timeline(*session.origin, session.tempo).time_at(4.0) + 2_000.0
    session.on_snapshot = peer_plays
    bar, told = _find(session, LinkStart(True, None, 0.25), stop=lambda: session.looks > 40)
    assert bar is not None, told
    start_mono = session.pair.mono_of(session.started_at)
    assert session.snapshot().mono_of_beat(bar) == pytest.approx(start_mono, abs=0.01)  # not 2 s later


def test_a_tempo_change_just_before_the_start_keeps_the_shows_first_bar():
    """DEFECT: LinkShowClock.realign on a tempo change in the count-in moves the start to the
    NEXT bar when the start bar now falls before `earliest` (the runners' 50 ms lead). A host
    that hears a change in the last 50 ms before the start goes a whole bar on; another host
    hearing it a few ms later does not: the hosts part by a bar. Seen for real: Live's tempo
    automation (a change every 20 ms) in the count-in made two hosts' starts recede 93 and 36
    times, 3.39 s apart. The show's first bar is a fixed beat of the session (the same on every
    host): a tempo change re-places only its instant."""
    mono = time.monotonic()
    pair = ClockPair(mono_ns=round(mono * 1e9), link_us=mono * 1e6 - 250_000.0, window_ns=0)
    beat_now = 15.94  # the start bar (beat 16) is 30 ms ahead at 120 bpm
    session = OneSnapshot(LinkSnapshot(Timeline(pair.link_us, beat_now, 120.0), pair, 1, True))
    as_session: Any = session  # a LinkSession as far as the show clock looks
    show = LinkShowClock(as_session, session.now.mono_of_beat(16.0), 16.0, 4)
    # a peer's ramp: 120 -> 119 bpm now; beat 16 is still ~30 ms ahead, inside the 50 ms lead
    session.now = LinkSnapshot(Timeline(pair.link_us, beat_now, 119.0), pair, 1, True)
    show.realign(mono + 0.05, tempo_changed=True)
    assert show.first_bar == 16.0  # not 20: every host keeps the transport's bar
    assert show.zero == pytest.approx(session.now.mono_of_beat(16.0), abs=1e-6)
