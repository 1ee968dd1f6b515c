"""This host's peer in an Ableton Link session, on a thread of its own, sampled.

The aalink binding gives the session's state only as "now" (beat now, tempo now, Link's clock
now) and needs an asyncio loop running beside it. So a `LinkSession` runs one loop on its own
thread, and every SAMPLE_S reads the session: Link's clock between two reads of the monotonic
clock (a `ClockPair`), the beat at Link's clock (a `Timeline`), the tempo, the peers, whether
the transport plays. The latest sample is a frozen `LinkSnapshot` that any thread reads without
a lock; a runner maps a beat to a monotonic deadline with it.

What changes between samples is told to the session's listeners as a `LinkEvent` (a peer
changed the tempo, peers joined or left, the transport started or stopped, the beat count
jumped), on the Link thread: a listener only queues (the recorder) or wakes (the runners).

Link numbers beats locally. A jump of the count by whole bars (this host renumbered, or
rejoined) keeps the phase, and is taken out of the snapshot's beats, which stay continuous: a
show's bar 9 is still bar 9. A jump that moves the phase (the session moved under a peer's
clock jump) is followed: the cues still to come move with the session's beat.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import timedelta
from typing import Protocol

from choreo.errors import ChoreoError, UsageError
from choreo.sync.timeline import ClockPair, Timeline, tighter, whole_bars

SAMPLE_S = 0.01  # how often the session is read: a tempo change reaches the runners within this
PAIR_AGE_NS = 500_000_000  # a clock pair this old is replaced even by a looser one (NTP slews one clock)
OPEN_TIMEOUT_S = 5.0  # joining never takes this long: past it, something is wrong with the binding
CALL_TIMEOUT_S = 2.0
FINE_QUANTUM = 1 / 64  # beats: the quantum the transport's start time is read with (8 ms at 120 bpm)
READ_TRIES = 3  # reads of the session a sample tries for a tight one
TIGHT_READ_US = 200.0  # a read of the beat between two reads of Link's clock this tight is taken at once
DISCOVERY_S = 1.0  # Link finds the peers already in a session within this of joining (seen: 0.3-0.5 s)
SETTLE_S = 0.3  # ...and goes on finding them one by one: the count is taken once none came for this long
DISCOVERY_MAX_S = 3.0  # however many keep coming, a show decides how to start by then
REANNOUNCE_S = 5.0  # a peer found this soon after this host started the transport is told of the start again
JUMP_BEATS = 0.02  # a beat count off its prediction by more than this (a tempo change aside) jumped
DEFAULT_TEMPO = 120.0  # what a peer alone proposes when the show names no tempo (Link's own default)
INSTALL_HINT = "pip install 'choreo[link]'"


class LinkUnavailable(UsageError):
    """The Link binding (aalink) is not installed."""


class LinkPeer(Protocol):
    """What choreo uses of aalink's `Link`."""

    enabled: bool
    quantum: float
    start_stop_sync_enabled: bool
    tempo: float

    @property
    def beat(self) -> float: ...

    @property
    def time(self) -> timedelta: ...

    @property
    def num_peers(self) -> int: ...

    @property
    def playing(self) -> bool: ...

    def set_is_playing_and_request_beat_at_time(self, playing: bool, at: timedelta, beat: float) -> None: ...

    def request_beat_at_start_playing_time(self, beat: float) -> None: ...


@dataclass(frozen=True)
class LinkSnapshot:
    """The session as one sample saw it. `timeline` counts continuous beats: the session's own
    count less `shift` (the whole bars it was renumbered by since this host joined)."""

    timeline: Timeline
    pair: ClockPair
    peers: int
    playing: bool
    shift: float = 0.0
    window_us: float = 0.0  # how long the beat's read took: its time is known within half of it

    @property
    def tempo(self) -> float:
        return self.timeline.tempo

    def mono_of_beat(self, beat: float) -> float:
        """Monotonic seconds at which continuous `beat` falls (on this sample's tempo)."""
        return self.pair.mono_of(self.timeline.time_at(beat))

    def beat_at_mono(self, mono: float) -> float:
        return self.timeline.beat_at(self.pair.link_of(mono))

    def link_us_at_mono(self, mono: float) -> int:
        return round(self.pair.link_of(mono))


@dataclass(frozen=True)
class LinkEvent:
    """A change seen between two samples: `kind` is one of the log's LINK_EVENTS."""

    kind: str
    snapshot: LinkSnapshot
    message: str


LinkListener = Callable[[LinkEvent], None]


def peers_text(count: int) -> str:
    """Other peers in a session, as every line that names them says it."""
    return "no other peers" if count == 0 else "1 peer" if count == 1 else f"{count} peers"


def _us(delta: timedelta) -> float:
    return delta / timedelta(microseconds=1)


def make_aalink(tempo: float) -> LinkPeer:
    """aalink's Link (inside the session's running loop, as aalink requires)."""
    try:
        from aalink import Link  # an optional extra: imported only for a show on the Link clock
    except ImportError as exc:
        raise LinkUnavailable(f"the Link clock needs the aalink package ({exc}): {INSTALL_HINT}") from None
    peer: LinkPeer = Link(tempo)
    return peer


class LinkSession:
    """This host's Link peer, joined on `open` and left on `close` (whoever opens it closes it)."""

    def __init__(self, quantum: int, tempo: float | None = None, *, sample_s: float = SAMPLE_S,
                 make_link: Callable[[float], LinkPeer] = make_aalink) -> None:
        self.quantum = quantum
        self._tempo = tempo or DEFAULT_TEMPO
        self._sample_s = sample_s
        self._make_link = make_link
        self._listeners: list[LinkListener] = []
        self._listeners_lock = threading.Lock()
        self._snapshot: LinkSnapshot | None = None
        self._ready = threading.Event()
        self._closing = threading.Event()
        self._failure: BaseException | None = None
        self._lost: str | None = None  # why the Link thread ended while the session was open
        self.listener_failures: list[Exception] = []  # listeners that raised (set aside, see `_tell`)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._link: LinkPeer | None = None
        self._pair: ClockPair | None = None
        self._joined = 0.0  # monotonic time this host joined
        self._started: tuple[float, timedelta] | None = None  # this host's start of the transport: when, at (Link)

    # -- opening and closing -----------------------------------------------------------------

    def open(self) -> LinkSession:
        """Join the session: the Link thread runs and has taken its first sample."""
        self._joined = time.monotonic()
        self._thread = threading.Thread(target=self._thread_main, name="choreo-link", daemon=True)
        self._thread.start()
        if not self._ready.wait(OPEN_TIMEOUT_S):
            self.close()
            raise ChoreoError(f"Link: no answer from the aalink binding in {OPEN_TIMEOUT_S:g} s")
        if self._failure is not None:
            failure, self._failure = self._failure, None
            self.close()
            if isinstance(failure, ChoreoError):
                raise failure
            raise ChoreoError(f"Link: could not join a session: {failure}")
        return self

    def close(self) -> None:
        """Leave the session (the thread disables the peer and ends)."""
        self._closing.set()
        if self._thread is not None:
            self._thread.join(OPEN_TIMEOUT_S)
            self._thread = None

    def __enter__(self) -> LinkSession:
        return self.open()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- reading -----------------------------------------------------------------------------

    def snapshot(self) -> LinkSnapshot:
        """The latest sample (at most SAMPLE_S old); ChoreoError if the Link thread has died
        (a show must not go on on a frozen session without a word)."""
        snapshot = self._snapshot
        assert snapshot is not None, "open the session first"
        if self._lost is not None:
            raise ChoreoError(f"Link: this host lost the session ({self._lost}): the show cannot follow its beat")
        return snapshot

    def discover(self, stop: Callable[[], bool] = lambda: False) -> LinkSnapshot:
        """The session once the peers already in it are found: Link finds them some tenths of a
        second after joining, one by one, so a host that decided before would start a transport
        the peers found later never hear of, on a phase the session then moves. Waits DISCOVERY_S
        after joining, and then until no new peer has come for SETTLE_S (at most DISCOVERY_MAX_S
        after joining), or a stop."""
        count, since = self.snapshot().peers, time.monotonic()
        while not stop():
            now = time.monotonic()
            peers = self.snapshot().peers
            if peers != count:
                count, since = peers, now
            joined_for = now - self._joined
            if joined_for >= DISCOVERY_MAX_S or (joined_for >= DISCOVERY_S and now - since >= SETTLE_S):
                break
            time.sleep(self._sample_s)
        return self.snapshot()

    def subscribe(self, listener: LinkListener) -> Callable[[], None]:
        """`listener` hears each LinkEvent (on the Link thread) until the returned undo."""
        with self._listeners_lock:
            self._listeners.append(listener)

        def undo() -> None:
            with self._listeners_lock:
                if listener in self._listeners:
                    self._listeners.remove(listener)
        return undo

    # -- asking the session ------------------------------------------------------------------

    def propose_tempo(self, bpm: float) -> None:
        """Set the session's tempo (every peer's)."""
        def propose(link: LinkPeer) -> None:
            link.tempo = bpm
        self._call(propose)

    def start_playing(self, beat: float) -> None:
        """Start the session's transport on continuous `beat` (a bar line ahead): peers that
        follow start/stop (Live with Start Stop Sync on, other choreo hosts) start there too.
        A peer found within REANNOUNCE_S after is told again (Link tells a peer it finds later
        nothing of a start made before)."""
        def start(link: LinkPeer) -> None:
            snapshot = self.snapshot()
            at_us = snapshot.timeline.time_at(beat)
            self._started = (time.monotonic(), timedelta(microseconds=at_us))
            link.set_is_playing_and_request_beat_at_time(True, self._started[1], beat + snapshot.shift)
        self._call(start)

    def stop_playing(self) -> bool:
        """Stop the transport if this host started it and it plays (a show stopped in its
        count-in); True if it did. A transport another peer started is never stopped here."""
        if self._started is None or not self.snapshot().playing:
            return False

        def stop(link: LinkPeer) -> None:
            link.set_is_playing_and_request_beat_at_time(False, link.time, float(link.beat))
        self._call(stop)
        self._started = None
        return True

    def count_from_start(self) -> float:
        """Renumber this host's beats so that beat 0 is the first bar line at or after the
        session's start (its transport's start time, shared state): every host that does so
        counts the same. The start itself, as a beat of the new count (in (-quantum, 0]).

        Link maps beat 0 to the first time at or after the start whose phase in the quantum is
        0, and tells no start time: asked first with a quantum of FINE_QUANTUM beats, it puts
        beat 0 within that of the start, which is read off, then asked again with the bar."""
        found: list[float] = []

        def count(link: LinkPeer) -> None:
            link.quantum = FINE_QUANTUM
            link.request_beat_at_start_playing_time(0.0)
            start_us = self._beat_time(link, 0.0)
            link.quantum = self.quantum
            link.request_beat_at_start_playing_time(0.0)
            found.append(-(self._beat_time(link, 0.0) - start_us) * float(link.tempo) / 60e6)
        self._call(count, renumbered=True)
        return found[0]

    @classmethod
    def _beat_time(cls, link: LinkPeer, beat: float) -> float:
        """Link time (us) of `beat` in this host's count, read now (as a sample reads it)."""
        _, beat_us, now, _ = cls._read(link)
        return Timeline(beat_us, now, float(link.tempo)).time_at(beat)

    def _call(self, action: Callable[[LinkPeer], None], renumbered: bool = False) -> None:
        """`action` on the Link thread, then a fresh sample there (this host changed the
        session: the next snapshot must show it); `renumbered`: this host renumbered its beats
        on purpose, so the count starts over with no shift."""
        loop = self._loop
        if loop is None or self._closing.is_set():
            raise ChoreoError("Link: the session is closed")

        async def run() -> None:
            assert self._link is not None
            action(self._link)
            self._sample(self._link, fresh=renumbered)
        asyncio.run_coroutine_threadsafe(run(), loop).result(CALL_TIMEOUT_S)

    # -- the Link thread ---------------------------------------------------------------------

    def _thread_main(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:  # noqa: B902 reported to open() or by snapshot(), never lost on a thread
            if self._ready.is_set():
                self._lost = f"{type(exc).__name__}: {exc}"[:200]
            self._failure = exc
            self._ready.set()

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        link = self._make_link(self._tempo)
        self._link = link
        link.quantum = self.quantum
        link.start_stop_sync_enabled = True
        link.enabled = True
        try:
            self._sample(link)
            self._ready.set()
            while not self._closing.is_set():
                await asyncio.sleep(self._sample_s)
                self._sample(link)
        finally:
            link.enabled = False
            self._loop = None

    def _sample(self, link: LinkPeer, fresh: bool = False) -> None:
        """Read the session; publish the snapshot, then tell the listeners what changed (a
        listener reading the session as it hears of a change reads the change). `fresh`: this
        host renumbered its beats on purpose: the count starts over, with no shift, no jump."""
        before = None if fresh else self._snapshot
        pair, beat_us, beat, window_us = self._read(link)
        self._pair = tighter(self._pair, pair, PAIR_AGE_NS)
        shift = before.shift if before is not None else 0.0
        now = LinkSnapshot(Timeline(beat_us, beat - shift, float(link.tempo)), self._pair, int(link.num_peers),
                           bool(link.playing), shift, window_us)
        events: list[tuple[str, str]] = []
        if before is not None:
            now, events = self._changes(before, now)
        self._snapshot = now
        if before is not None and now.peers > before.peers and now.playing:
            self._announce_again(link, now)
        for kind, message in events:
            self._tell(LinkEvent(kind, now, message))

    def _announce_again(self, link: LinkPeer, now: LinkSnapshot) -> None:
        """A peer found soon after this host started the transport (still playing) hears of the
        start: its time as it was, at the beat this host's count now gives it (the count may have
        been renumbered since: the same beat again is no jump)."""
        started = self._started
        if started is not None and time.monotonic() - started[0] < REANNOUNCE_S:
            at_us = started[1] / timedelta(microseconds=1)
            link.set_is_playing_and_request_beat_at_time(True, started[1], now.timeline.beat_at(at_us) + now.shift)

    @staticmethod
    def _read(link: LinkPeer) -> tuple[ClockPair, float, float, float]:
        """Link's clock between two monotonic reads, and the beat between two reads of Link's
        clock: the tightest of a few tries (a thread put off between two reads on a loaded
        machine would misplace the beat by half the delay). (pair, Link time of the beat, the
        beat, the window it was read in, us)."""
        best: tuple[ClockPair, float, float, float] | None = None
        for _ in range(READ_TRIES):
            m1 = time.monotonic_ns()
            t1 = _us(link.time)
            m2 = time.monotonic_ns()
            beat = link.beat
            t2 = _us(link.time)
            if best is None or t2 - t1 < best[3]:
                best = (ClockPair((m1 + m2) // 2, t1, m2 - m1), (t1 + t2) / 2, beat, t2 - t1)
            if t2 - t1 <= TIGHT_READ_US:
                break
        assert best is not None
        return best

    def _changes(self, before: LinkSnapshot, now: LinkSnapshot) -> tuple[LinkSnapshot, list[tuple[str, str]]]:
        """What changed since `before`, and the snapshot with a whole-bar renumbering taken out
        of its beats (`_jump`)."""
        events: list[tuple[str, str]] = []
        tempo_changed = abs(now.tempo - before.tempo) > 1e-6
        now, jumped = self._jump(before, now, tempo_changed)
        if jumped is not None:
            events.append(("jump", jumped))
        if tempo_changed:
            events.append(("tempo", f"the session's tempo went from {before.tempo:.2f} to {now.tempo:.2f} bpm"))
        if now.peers != before.peers:
            events.append(("peers", f"Link peers: {before.peers} -> {now.peers}"))
        if now.playing != before.playing:
            events.append(("playing", "the session's transport plays") if now.playing
                          else ("stopped", "the session's transport stopped"))
        return now, events

    def _jump(self, before: LinkSnapshot, now: LinkSnapshot, tempo_changed: bool) -> tuple[LinkSnapshot, str | None]:
        """The snapshot with a whole-bar renumbering taken out, and what jumped (None: nothing).
        In the sample a tempo change arrives in, only a jump of half a bar or more counts (a
        renumbering that came with it); less is Link re-phasing to the new tempo."""
        jump = now.timeline.beat - before.timeline.beat_at(now.timeline.link_us)
        # each sample's beat is placed within half its read window
        slack = JUMP_BEATS + (now.window_us + before.window_us) / 2 * now.tempo / 60e6
        if tempo_changed:
            bars: int | None = round(jump / self.quantum) if abs(jump) >= self.quantum / 2 else None
        elif abs(jump) > slack:
            bars = whole_bars(jump, self.quantum)
            if not bars:
                return now, f"the session's beat jumped by {jump:+.3f} beats: cues in bars follow it"
        else:
            bars = None
        if not bars:
            return now, None
        renumbered = replace(now, timeline=replace(now.timeline, beat=now.timeline.beat - bars * self.quantum),
                             shift=now.shift + bars * self.quantum)
        return renumbered, f"Link renumbered this host's beats by {bars} bars (the phase kept)"

    def _tell(self, event: LinkEvent) -> None:
        """Each listener hears the event; one that fails is set aside: unsubscribed, its error
        kept in `listener_failures` (one a listener, however many events peers send), never the
        sampling: a show keeps following the session."""
        with self._listeners_lock:
            listeners = list(self._listeners)
        for listener in listeners:
            try:
                listener(event)
            except Exception as exc:  # noqa: BLE001 a listener's bug must not take this host off Link mid-show
                with self._listeners_lock:
                    if listener in self._listeners:
                        self._listeners.remove(listener)
                self.listener_failures.append(exc)

