"""choreo.sync without a network: the pure arithmetic (Timeline, ClockPair, tighter, bar lines,
whole bars), a LinkSession sampling a fake Link peer (the events it tells, a whole-bar
renumbering taken out of its beats, a phase jump followed), find_start's decisions on a fake
session, and the show clock on a session (seconds kept, bars on the tempo as it is now). The
real session is tests/test_link_clock.py's.
"""

from __future__ import annotations

import sys
import threading
import time
from datetime import timedelta
from typing import Any

import pytest

from choreo.errors import ChoreoError
from choreo.sync import session as session_module
from choreo.sync.clock import LinkShowClock
from choreo.sync.session import INSTALL_HINT, LinkEvent, LinkSession, LinkSnapshot, LinkUnavailable, make_aalink
from choreo.sync.start import MISSED_S, START_LEAD_S, LinkStart, find_start
from choreo.sync.timeline import ClockPair, Timeline, bar_at_or_after, tighter, whole_bars
from runlog import wait_for

WAIT_S = 5.0  # a state the session's thread reaches within this (it samples every few ms)
BEATS = 0.05  # two readings of one beat timeline at one instant agree this closely (the session's clock
# pair is read around Link's clock, a window a loaded machine widens)


# -- the arithmetic ---------------------------------------------------------------------------

def test_a_timeline_maps_beats_and_link_time_both_ways_at_its_tempo():
    timeline = Timeline(link_us=1_000_000.0, beat=8.0, tempo=120.0)
    assert timeline.beat_at(1_500_000.0) == pytest.approx(9.0)  # half a second: one beat at 120
    assert timeline.beat_at(0.0) == pytest.approx(6.0)
    assert timeline.time_at(12.0) == pytest.approx(3_000_000.0)
    for beat in (-3.25, 0.0, 8.0, 101.5):
        assert timeline.beat_at(timeline.time_at(beat)) == pytest.approx(beat)


def test_a_clock_pair_maps_link_time_and_monotonic_seconds_by_its_one_reading():
    pair = ClockPair(mono_ns=10_000_000_000, link_us=9_750_000.0, window_ns=2_000)  # Link 250 ms behind
    assert pair.mono_of(9_750_000.0) == pytest.approx(10.0)
    assert pair.mono_of(10_750_000.0) == pytest.approx(11.0)
    assert pair.link_of(12.5) == pytest.approx(12_250_000.0)
    assert pair.link_of(pair.mono_of(123_456.0)) == pytest.approx(123_456.0)


def test_the_tighter_pair_is_kept_until_it_is_too_old():
    kept = ClockPair(1_000, 0.0, 500)
    assert tighter(None, kept, 100) is kept
    looser = ClockPair(1_050, 0.0, 900)
    assert tighter(kept, looser, 100) is kept  # fresh enough, and looser: the kept one maps
    tighter_one = ClockPair(1_060, 0.0, 400)
    assert tighter(kept, tighter_one, 100) is tighter_one
    as_tight = ClockPair(1_070, 0.0, 500)
    assert tighter(kept, as_tight, 100) is as_tight  # as tight and newer
    stale = ClockPair(1_200, 0.0, 9_000)
    assert tighter(kept, stale, 100) is stale  # the kept one is 200 ns old: the clocks drift


@pytest.mark.parametrize(("beat", "quantum", "bar"), [
    (0.0, 4, 0.0), (4.0, 4, 4.0), (4.0000001, 4, 4.0), (3.9999999, 4, 4.0), (4.1, 4, 8.0), (0.5, 4, 4.0),
    (-0.5, 4, 0.0), (-4.5, 4, -4.0), (-8.0, 4, -8.0), (7.0, 3, 9.0), (6.0, 3, 6.0), (2.5, 1, 3.0),
])
def test_the_bar_line_at_or_after_a_beat_is_by_phase(beat, quantum, bar):
    assert bar_at_or_after(beat, quantum) == bar


@pytest.mark.parametrize(("jump", "quantum", "bars"), [
    (8.0, 4, 2), (8.005, 4, 2), (-4.0, 4, -1), (-3.995, 4, -1), (12.0, 3, 4), (0.004, 4, 0),
    (1.5, 4, None), (7.9, 4, None), (2.0, 4, None), (-0.03, 4, None),
])
def test_a_jump_by_whole_bars_is_a_renumbering_and_any_other_moved_the_phase(jump, quantum, bars):
    assert whole_bars(jump, quantum) == bars


# -- a session on a fake Link peer ------------------------------------------------------------

class FakeLink:
    """aalink's Link as the session uses it: a beat timeline on a clock running 250 ms behind
    the monotonic one (as CLOCK_MONOTONIC_RAW is on a Linux machine), changed by the test."""

    OFFSET_US = -250_000.0

    def __init__(self, tempo: float) -> None:
        self.lock = threading.Lock()
        self.enabled = False
        self.quantum = 0.0
        self.start_stop_sync_enabled = False
        self._tempo = tempo
        self._origin = (self._now_us(), 0.0)  # (Link time, beat) the timeline passes through
        self._peers = 0
        self._playing = False
        self.calls: list[tuple] = []

    @staticmethod
    def _now_us() -> float:
        return time.monotonic_ns() / 1e3 + FakeLink.OFFSET_US

    def _beat_at(self, link_us: float) -> float:
        origin_us, origin_beat = self._origin
        return origin_beat + (link_us - origin_us) * self._tempo / 60e6

    @property
    def tempo(self) -> float:
        return self._tempo

    @tempo.setter
    def tempo(self, bpm: float) -> None:
        with self.lock:  # the beat stays where it is at the change, as Link keeps it
            now = self._now_us()
            self._origin = (now, self._beat_at(now))
            self._tempo = bpm
        self.calls.append(("tempo", bpm))

    @property
    def beat(self) -> float:
        with self.lock:
            return self._beat_at(self._now_us())

    def beat_at_mono(self, mono: float) -> float:
        """The beat at monotonic time `mono`: compared with the session's reading of the same
        instant (the beat now, read a moment after the session's, is as far off as the test's
        thread was put off between the two: a time slice of a loaded machine, 20 ms a beat at
        150 bpm, more than BEATS)."""
        with self.lock:
            return self._beat_at(mono * 1e6 + self.OFFSET_US)

    @property
    def time(self) -> timedelta:
        return timedelta(microseconds=self._now_us())

    @property
    def num_peers(self) -> int:
        return self._peers

    @property
    def playing(self) -> bool:
        return self._playing

    def set_is_playing_and_request_beat_at_time(self, playing: bool, at: timedelta, beat: float) -> None:
        self.calls.append(("play", playing, at / timedelta(microseconds=1), beat))
        self._playing = playing

    def request_beat_at_start_playing_time(self, beat: float) -> None:
        self.calls.append(("count_from_start", beat))

    # what other peers do to the session
    def move_beats(self, beats: float) -> None:
        with self.lock:
            origin_us, origin_beat = self._origin
            self._origin = (origin_us, origin_beat + beats)

    def peers(self, count: int) -> None:
        self._peers = count

    def plays(self, playing: bool) -> None:
        self._playing = playing


class Heard:
    """The events a session told, and what `session.snapshot()` said as each was told (what
    a listener reading the session, as the run's clock sampler does, sees)."""

    def __init__(self, session: LinkSession) -> None:
        self.session = session
        self.events: list[LinkEvent] = []
        self.seen: list[LinkSnapshot] = []
        self.cond = threading.Condition()

    def __call__(self, event: LinkEvent) -> None:
        with self.cond:
            self.events.append(event)
            self.seen.append(self.session.snapshot())
            self.cond.notify_all()

    def wait_for(self, kind: str, saying: str = "") -> LinkEvent:
        """The first event of `kind` whose message holds `saying` (a loaded machine's late
        sample can come out as a small jump of its own first)."""
        def match(event: LinkEvent) -> bool:
            return event.kind == kind and saying in event.message
        with self.cond:
            assert self.cond.wait_for(lambda: any(match(e) for e in self.events), WAIT_S), self.events
            return next(e for e in self.events if match(e))


@pytest.fixture
def fake():
    links: list[FakeLink] = []

    def make(tempo: float) -> FakeLink:
        links.append(FakeLink(tempo))
        return links[-1]

    with LinkSession(4, 100.0, sample_s=0.002, make_link=make) as session:
        heard = Heard(session)
        session.subscribe(heard)
        yield session, links[0], heard
    assert not links[0].enabled  # left the session on close


def test_a_session_joins_with_its_tempo_quantum_and_start_stop_sync(fake):
    session, link, _heard = fake
    assert link.enabled and link.quantum == 4 and link.start_stop_sync_enabled
    snapshot = session.snapshot()
    assert snapshot.tempo == 100.0 and snapshot.peers == 0 and not snapshot.playing and snapshot.shift == 0.0
    # the snapshot maps the monotonic clock to the session's beat through Link's own clock
    now = time.monotonic()
    assert snapshot.beat_at_mono(now) == pytest.approx(link.beat_at_mono(now), abs=BEATS)
    assert snapshot.link_us_at_mono(now) == pytest.approx(now * 1e6 + FakeLink.OFFSET_US, abs=50_000)
    assert snapshot.mono_of_beat(snapshot.beat_at_mono(now + 1.0)) == pytest.approx(now + 1.0, abs=1e-6)


def test_a_peers_tempo_is_a_tempo_event_and_the_beats_stay_continuous(fake):
    session, link, heard = fake
    link.tempo = 150.0
    event = heard.wait_for("tempo")
    assert event.snapshot.tempo == 150.0 and "from 100.00 to 150.00 bpm" in event.message
    mono = time.monotonic()
    assert session.snapshot().beat_at_mono(mono) == pytest.approx(link.beat_at_mono(mono), abs=BEATS)


def test_a_listener_reading_the_session_as_it_hears_an_event_reads_the_change(fake):
    """The run's clock sampler reads session.snapshot() when it hears an event: the sample of
    a tempo change must carry the new tempo, and of a peer leaving, the peers left."""
    _session, link, heard = fake
    link.tempo = 150.0
    heard.wait_for("tempo")
    link.peers(2)
    heard.wait_for("peers")
    seen = dict(zip([e.kind for e in heard.events], heard.seen, strict=True))
    assert seen["tempo"].tempo == 150.0
    assert seen["peers"].peers == 2


def test_peers_and_the_transport_are_events(fake):
    session, link, heard = fake
    link.peers(2)
    assert heard.wait_for("peers").message == "Link peers: 0 -> 2"
    link.plays(True)
    assert heard.wait_for("playing").snapshot.playing
    link.plays(False)
    assert not heard.wait_for("stopped").snapshot.playing
    assert session.snapshot().peers == 2


def test_a_renumbering_by_whole_bars_is_taken_out_of_the_beats(fake):
    session, link, heard = fake
    before = session.snapshot()
    link.move_beats(8.0)  # Link renumbered this host's count by two bars: the phase is where it was
    heard.wait_for("jump", "by 2 bars")
    now = session.snapshot()
    assert now.shift == 8.0
    mono = time.monotonic()
    assert now.beat_at_mono(mono) == pytest.approx(before.beat_at_mono(mono), abs=BEATS)  # still bar 9 as before
    assert now.beat_at_mono(mono) + now.shift == pytest.approx(link.beat_at_mono(mono), abs=BEATS)


def test_a_jump_that_moves_the_phase_is_followed(fake):
    session, link, heard = fake
    before = session.snapshot()
    link.move_beats(1.5)
    heard.wait_for("jump", "jumped by +1.5")
    now = session.snapshot()
    mono = time.monotonic()
    assert now.shift == 0.0
    assert now.beat_at_mono(mono) == pytest.approx(before.beat_at_mono(mono) + 1.5, abs=BEATS)


def test_start_playing_asks_link_for_the_beat_at_its_time_in_links_count(fake):
    session, link, heard = fake
    link.move_beats(8.0)  # a shift of two bars to give back
    heard.wait_for("jump", "by 2 bars")
    snapshot = session.snapshot()
    bar = bar_at_or_after(snapshot.beat_at_mono(time.monotonic() + 1.0), 4)
    session.start_playing(bar)
    [play] = [call for call in link.calls if call[0] == "play"]
    assert play[1] is True and play[3] == bar + 8.0
    assert play[2] == pytest.approx(snapshot.timeline.time_at(bar), abs=1.0)
    session.count_from_start()
    assert ("count_from_start", 0.0) in link.calls
    assert session.snapshot().shift == 0.0  # counted over on purpose: no shift
    session.propose_tempo(90.0)
    assert ("tempo", 90.0) in link.calls and session.snapshot().tempo == 90.0


class FoundOneByOne:
    """`discover`'s stop callback, which it calls before each look at the session: Link finding
    the peers already there one by one, each one sampled by the session before `discover` looks,
    the next at its next look. Timers 0.15 s apart did this once, and a loaded machine fired the
    second past SETTLE_S after the first was seen: `discover` rightly settled on one peer."""

    def __init__(self, session: LinkSession, link: FakeLink, *counts: int) -> None:
        self.session, self.link, self.counts = session, link, list(counts)

    def __call__(self) -> bool:
        if self.counts:
            count = self.counts.pop(0)
            self.link.peers(count)
            assert wait_for(lambda: self.session.snapshot().peers == count, WAIT_S, every=0.001)
        return False


def test_discovery_waits_for_the_peers_already_in_the_session(fake, monkeypatch):
    """Link finds the peers already there some tenths of a second after joining: discover()
    waits for one (so a start is never decided alone by mistake), up to DISCOVERY_S."""
    session, link, heard = fake
    monkeypatch.setattr(session_module, "DISCOVERY_S", 0.2)
    monkeypatch.setattr(session_module, "SETTLE_S", 0.4)
    monkeypatch.setattr(session_module, "DISCOVERY_MAX_S", 60.0)  # a wait that would fail the suite's time
    # found one by one: the count settles on the second, not the first discover saw
    assert session.discover(stop=FoundOneByOne(session, link, 1, 2)).peers == 2
    link.peers(1)
    heard.wait_for("peers", "2 -> 1")
    link.peers(0)
    heard.wait_for("peers", "1 -> 0")
    monkeypatch.setattr(session_module, "DISCOVERY_S", 0.0)
    monkeypatch.setattr(session_module, "SETTLE_S", 0.0)
    assert session.discover().peers == 0  # alone: past DISCOVERY_S, it says so
    monkeypatch.setattr(session_module, "DISCOVERY_S", 60.0)
    assert session.discover(stop=lambda: True).peers == 0  # a stop ends the wait


def test_a_session_closed_takes_no_more_calls():
    session = LinkSession(4, make_link=FakeLink).open()
    session.close()
    with pytest.raises(ChoreoError, match="closed"):
        session.propose_tempo(100.0)


def test_without_aalink_the_link_clock_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "aalink", None)  # import aalink raises ImportError
    with pytest.raises(LinkUnavailable, match=r"pip install 'choreo\[link\]'") as raised:
        make_aalink(120.0)
    assert INSTALL_HINT in str(raised.value) and "\n" not in str(raised.value)
    with pytest.raises(LinkUnavailable):
        LinkSession(4, 120.0).open()  # the binding's failure comes out of open, the thread gone


# -- find_start on a fake session -------------------------------------------------------------

class FakeSession:
    """What find_start uses of a LinkSession: a timeline it sets, and the calls it got."""

    quantum = 4

    def __init__(self, beat_now: float, tempo: float = 120.0, peers: int = 1, playing: bool = False) -> None:
        self.tempo = tempo
        self.peers = peers
        self.playing = playing
        self.pair = ClockPair(time.monotonic_ns(), 5_000_000.0, 0)
        self.origin = (self.pair.link_of(time.monotonic()), beat_now)  # Link time, beat
        self.calls: list[tuple] = []
        self.on_snapshot = lambda count: None  # what other peers do at the n-th look
        self.looks = 0

    def snapshot(self) -> LinkSnapshot:
        self.looks += 1
        self.on_snapshot(self.looks)
        return LinkSnapshot(Timeline(*self.origin, self.tempo), self.pair, self.peers, self.playing)

    def discover(self, stop=lambda: False) -> LinkSnapshot:
        """Peers already in the session are found at once here."""
        return self.snapshot()

    def propose_tempo(self, bpm: float) -> None:
        self.calls.append(("tempo", bpm))
        link_us = self.pair.link_of(time.monotonic())
        self.origin = (link_us, Timeline(*self.origin, self.tempo).beat_at(link_us))
        self.tempo = bpm

    def start_playing(self, beat: float) -> None:
        self.calls.append(("play", beat))
        self.started_at = Timeline(*self.origin, self.tempo).time_at(beat)
        self.playing = True

    def count_from_start(self) -> float:
        """Link's renumbering: the transport's start is beat 0 (its bar line); the start's beat."""
        self.calls.append(("count_from_start",))
        self.origin = (self.started_at, 0.0)
        return 0.0


def _find(session: FakeSession, how: LinkStart, started=lambda: False, stop=lambda: False):
    """find_start's bar line and the lines it told."""
    told: list[str] = []
    fake: Any = session  # a LinkSession as far as find_start looks
    return find_start(fake, how, started, stop, told.append), told


def test_a_show_that_does_not_wait_starts_on_the_playing_sessions_next_bar_line():
    session = FakeSession(beat_now=5.2, playing=True)
    bar, told = _find(session, LinkStart(False, 140.0, 0.25))
    assert bar == 8.0  # 5.2 + half a beat of lead at 120 bpm -> the bar line at 8
    assert session.calls == []  # the session's tempo and transport are left alone
    assert told == ["the session plays (1 peer, 120.00 bpm): the show starts on its next bar line"]


def test_a_show_that_does_not_wait_starts_a_stopped_session_at_its_tempo_on_a_bar_line_ahead():
    session = FakeSession(beat_now=1.0, peers=2)
    bar, told = _find(session, LinkStart(False, 150.0, 0.25))
    assert session.calls[0] == ("tempo", 150.0)
    play = session.calls[1]
    assert play[0] == "play" and play[1] % 4 == 0
    ahead_s = (play[1] - 1.0) * 60 / 150.0
    assert ahead_s >= 0.25 + START_LEAD_S - 0.05  # at least the lead ahead (the beat moved on a little)
    assert session.calls[2] == ("count_from_start",)
    assert bar == 0.0  # counted from the transport's start: its bar line is beat 0
    [line] = told
    assert line.startswith("starting the session's transport with 2 peers, at 150.00 bpm, on a bar line")


def test_alone_a_show_starts_the_transport_as_the_sessions_first_peer():
    session = FakeSession(beat_now=0.0, peers=0)
    bar, told = _find(session, LinkStart(False, None, 0.25))
    assert [call[0] for call in session.calls] == ["play", "count_from_start"]  # no tempo proposed
    assert bar == 0.0
    assert "alone, as the session's first peer" in told[0]


def test_a_waiting_show_stopped_before_the_session_plays_has_no_start():
    session = FakeSession(beat_now=0.0, peers=0)
    looks = iter(range(5))
    bar, told = _find(session, LinkStart(True, None, 0.25), stop=lambda: next(looks, 4) >= 3)
    assert bar is None and session.calls == []
    assert told == ["waiting for the session to play (no other peers, 120.00 bpm): start it from a peer "
                    "(Live's play), another host, or this host's start"]


def test_a_waiting_show_starts_on_the_bar_line_the_sessions_transport_started_on():
    session = FakeSession(beat_now=0.0)

    def peer_plays(look: int) -> None:
        if look == 3:  # another peer starts the transport on a bar line just ahead
            session.playing = True
            session.started_at = Timeline(*session.origin, session.tempo).time_at(4.0)
    session.on_snapshot = peer_plays
    bar, told = _find(session, LinkStart(True, None, 0.25))
    assert bar == 0.0 and session.calls == [("count_from_start",)]
    assert told[-1] == ("the session plays (1 peer, 120.00 bpm): "
                        "the show starts on the bar line its transport started on")


def test_a_session_already_playing_as_the_wait_begins_is_a_start_just_heard():
    """The transport started while this host opened its ports, after it joined (R1: both hosts
    waited for ever for a start they had already heard): its bar line still ahead, the show
    starts there."""
    session = FakeSession(beat_now=0.0, playing=True)
    session.started_at = Timeline(*session.origin, session.tempo).time_at(4.0)  # the next bar line
    bar, told = _find(session, LinkStart(True, None, 0.25))
    assert bar == 0.0 and session.calls == [("count_from_start",)]
    assert told[-1].endswith("the show starts on the bar line its transport started on")


def test_a_start_heard_too_late_is_missed_and_the_show_waits_for_the_next():
    session = FakeSession(beat_now=0.0)
    stopping = threading.Event()

    def peer_played_long_ago(look: int) -> None:
        if look == 3:
            session.playing = True
            session.started_at = session.pair.link_of(time.monotonic() - MISSED_S - 1.0)
        if look > 6:
            stopping.set()
    session.on_snapshot = peer_played_long_ago
    bar, told = _find(session, LinkStart(True, None, 0.25), stop=stopping.is_set)
    assert bar is None
    assert any("before this host heard it: the show runs elsewhere; waiting for the next start" in line
               for line in told), told


def test_a_waiting_show_started_by_its_operator_starts_the_transport_itself():
    session = FakeSession(beat_now=2.0)
    bar, told = _find(session, LinkStart(True, 120.0, 0.25), started=lambda: True)
    assert [call[0] for call in session.calls] == ["play", "count_from_start"]
    assert bar == 0.0 and told[-1].startswith("starting the session's transport with 1 peer")



# -- the show clock on a session --------------------------------------------------------------

class OneSnapshot:
    """A session whose snapshot the test sets."""

    def __init__(self, snapshot: LinkSnapshot) -> None:
        self.now = snapshot

    def snapshot(self) -> LinkSnapshot:
        return self.now


def test_the_show_clock_keeps_seconds_and_places_bars_on_the_sessions_tempo_as_it_is_now():
    pair = ClockPair(mono_ns=100_000_000_000, link_us=99_750_000.0, window_ns=0)  # Link 250 ms behind
    session = OneSnapshot(LinkSnapshot(Timeline(99_750_000.0, 16.0, 120.0), pair, 1, True))
    fake: Any = session
    show = LinkShowClock(fake, start=100.0, start_beat=16.0, meter=4)  # the show starts on beat 16, at 100 s
    assert show.beats_of(1, 1) == 0 and show.beats_of(2, 1) == 4 and show.beats_of(3, 2.5) == 9.5
    assert show.at_beat(1, 1) == pytest.approx(0.0) and show.at_beat(2, 1) == pytest.approx(2.0)
    assert show.at_beat(1, 2.5) == pytest.approx(0.75)
    assert show.show_beat(101.0) == pytest.approx(2.0)
    # a peer sets 60 bpm at show time 1 s (beat 2 of the show): bars still to come move, seconds do not
    session.now = LinkSnapshot(Timeline(100_750_000.0, 18.0, 60.0), pair, 1, True)
    assert show.at_beat(2, 1) == pytest.approx(3.0)  # two beats more at a second each
    assert show.at_beat(3, 1) == pytest.approx(7.0)
    assert show.show_beat(104.0) == pytest.approx(5.0)
    assert show.mono_at(2.5) == 102.5 and show.show_at(102.5) == 2.5


def test_a_start_off_beat_one_keeps_every_later_bar_on_a_bar_of_the_session():
    """--from a step at bar 3 beat 2 (show beat 9) starts on beat 2 of a session bar (session
    beat 17 = bar line 16 + 1): the show's bar 4 is then the session's bar line 20, not beat 4."""
    pair = ClockPair(mono_ns=100_000_000_000, link_us=99_750_000.0, window_ns=0)
    session = OneSnapshot(LinkSnapshot(Timeline(99_750_000.0, 17.0, 120.0), pair, 1, True))
    fake: Any = session
    show = LinkShowClock(fake, start=100.0, start_beat=17.0, meter=4, origin_s=4.5, origin_beats=9.0)
    assert show.first_bar == 8.0 and (show.first_bar + show.beats_of(4, 1)) % 4 == 0
    assert show.mono_at(4.5) == pytest.approx(100.0)  # the --from step's own time plays at the start
    assert show.at_beat(4, 1) == pytest.approx(4.5 + 1.5)  # three beats after bar 3 beat 2, at 120 bpm


def test_a_change_of_the_session_before_the_start_moves_the_start_onto_the_same_phase():
    """A peer changes the tempo during the count-in: the start moves to where the session now
    puts the same bar line (realign), on every host alike; once the show has begun, never."""
    now = time.monotonic()
    pair = ClockPair(mono_ns=round(now * 1e9), link_us=1_000_000.0, window_ns=0)
    session = OneSnapshot(LinkSnapshot(Timeline(1_000_000.0, 0.0, 120.0), pair, 1, True))
    fake: Any = session
    show = LinkShowClock(fake, start=now + 2.0, start_beat=4.0, meter=4)  # bar line 4, two seconds ahead
    session.now = LinkSnapshot(Timeline(1_000_000.0, 0.0, 240.0), pair, 1, True)  # twice as fast from now
    assert show.realign(now + 0.05, tempo_changed=True)
    assert show.first_bar == 4.0 and show.zero == pytest.approx(now + 1.0)  # the same bar line, sooner
    assert not show.realign(now + 0.05, tempo_changed=True)  # nothing moved since
    # a jump of the phase by a beat and a half: the bar line of the new phase nearest the start
    session.now = LinkSnapshot(Timeline(1_000_000.0, 1.5, 240.0), pair, 1, True)
    assert show.realign(now + 0.05)
    assert show.first_bar == 4.0 and show.zero == pytest.approx(now + 0.625)  # beat 4 (5.5 was the start's)
    begun = LinkShowClock(fake, start=now - 1.0, start_beat=0.0, meter=4)
    assert not begun.realign(now + 0.05)


def test_a_listener_that_fails_is_set_aside_and_the_session_is_still_followed(fake):
    """A listener's bug on the Link thread must not take this host off the session mid-show."""
    session, link, heard = fake

    def broken(event: LinkEvent) -> None:
        raise RuntimeError("a listener's bug")
    session.subscribe(broken)
    link.peers(1)
    heard.wait_for("peers", "0 -> 1")
    link.tempo = 140.0
    heard.wait_for("tempo", "to 140.00")  # still sampled and told after the failure
    assert session.snapshot().tempo == 140.0
    for bpm in (141.0, 142.0, 143.0):  # a peer's every change: the failed listener is not asked again
        link.tempo = bpm
        heard.wait_for("tempo", f"to {bpm:.2f}")
    assert len(session.listener_failures) == 1


def test_a_session_whose_thread_died_says_so_rather_than_freezing(fake, monkeypatch):
    """The Link thread ends on an error mid-show: the next read of the session is a ChoreoError
    naming it (a show on a frozen snapshot would drift off the session without a word)."""
    session, link, _heard = fake

    def failing() -> timedelta:
        raise OSError("the binding failed")
    monkeypatch.setattr(FakeLink, "time", property(lambda self: failing()))
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        try:
            session.snapshot()
        except ChoreoError as exc:
            assert "lost the session" in str(exc) and "the binding failed" in str(exc)
            return
        time.sleep(0.01)
    raise AssertionError("the session went on as if nothing had happened")


def test_a_start_is_told_again_to_a_peer_found_after_it_while_the_transport_plays(fake):
    """Link tells a peer it finds later nothing of a start made before: the host that started
    the transport tells it again, at the beat its count gives the start now (no jump), and
    not once the transport has stopped (that would start it again for everyone)."""
    session, link, heard = fake
    snapshot = session.snapshot()
    bar = bar_at_or_after(snapshot.beat_at_mono(time.monotonic() + 0.5), 4)
    session.start_playing(bar)
    session.count_from_start()
    plays = lambda: [call for call in link.calls if call[0] == "play"]  # noqa: E731 a short look, read twice
    first = plays()[0]
    link.peers(1)
    heard.wait_for("peers", "0 -> 1")
    again = plays()[1]
    assert again[1] is True and again[2] == first[2]  # the same start time
    assert again[3] == pytest.approx(session.snapshot().timeline.beat_at(first[2]), abs=1e-6)
    link.plays(False)
    heard.wait_for("stopped")
    link.peers(2)
    heard.wait_for("peers", "1 -> 2")
    assert len(plays()) == 2  # stopped: not started again


def test_a_show_stopped_in_its_count_in_stops_only_the_transport_it_started(fake):
    """R1: Ctrl-C before show time 0 left the transport this host started playing (a Live with
    Start Stop Sync played on for a show that never began). One another peer started stays."""
    session, link, heard = fake
    link.plays(True)  # another peer's transport
    heard.wait_for("playing")
    assert not session.stop_playing() and link.playing
    link.plays(False)
    heard.wait_for("stopped")
    bar = bar_at_or_after(session.snapshot().beat_at_mono(time.monotonic() + 1.0), 4)
    session.start_playing(bar)
    assert session.snapshot().playing
    assert session.stop_playing() and not link.playing
    assert [call[1] for call in link.calls if call[0] == "play"] == [True, False]
    assert not session.stop_playing()  # once
