"""The bar line a show on the Link clock starts on, and who starts the session's transport.

- A show that does not wait (one host, no --wait-start): if the session plays already, the
  show starts on its next bar line; if not, this host starts the transport on the next bar line
  (with the show's tempo proposed first), and peers that follow start/stop start with it. Alone
  in the session, it starts alone as the session's first peer, and says so.
- A show that waits (--wait-start, or a show for several hosts): it starts on the first bar
  line at or after the session's transport starts (one a hair before the start, ON_THE_BAR_BEATS
  at most: an app's start a few milliseconds late is on its bar line) (Live's play button, another host's start),
  or when this host's operator starts it, which starts the transport as above. Every host that
  counts its beats from the transport's start (Link's start time is shared state) picks the
  same bar line, whenever it heard of the start. A start heard more than MISSED_S after its bar
  line is missed (the show runs on the other hosts): said in one line, and the host waits for
  the next start.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from choreo.sync.session import SAMPLE_S, LinkSession, peers_text
from choreo.sync.timeline import bar_at_or_after

START_LEAD_S = 0.3  # this host's start of the transport is announced this far ahead of its bar line
ON_THE_BAR_BEATS = 0.25  # a transport started this soon after a bar line started on it
MISSED_S = 0.5  # a start heard this long after its bar line is missed: the show runs elsewhere


@dataclass(frozen=True)
class LinkStart:
    """How a show starts on the session."""

    waits: bool  # for the session's start or the operator's (else: at once)
    tempo: float | None  # proposed when this host starts the transport (None: the session's)
    lead_s: float  # the runners' preroll: the bar line is at least this far ahead


def find_start(session: LinkSession, how: LinkStart, started: Callable[[], bool],
               stop: Callable[[], bool], tell: Callable[[str], None]) -> float | None:
    """The continuous beat of the show's first bar line; None if stopped while waiting.
    `started`: the operator started this host (a waiting show); `tell`: one line for the log."""
    snapshot = session.discover(stop)
    if not how.waits:
        return _start_here(session, how, tell)
    tell(f"waiting for the session to play ({peers_text(snapshot.peers)}, {snapshot.tempo:.2f} bpm): "
         "start it from a peer (Live's play), another host, or this host's start")
    # a session that plays as the wait begins is a start just heard (it may have started while
    # this host opened its ports, its bar line still ahead): started here, or missed, said
    was_playing = False
    while not stop():
        if started():
            return _start_here(session, how, tell)
        playing = session.snapshot().playing
        if playing and not was_playing:
            bar = _joined(session, tell)
            if bar is not None:
                return bar
        was_playing = playing
        time.sleep(SAMPLE_S)
    return None


def next_bar(session: LinkSession, lead_s: float) -> float:
    """The session's next bar line at least `lead_s` ahead, the transport left as it is (a
    --loop pass after the first)."""
    return bar_at_or_after(session.snapshot().beat_at_mono(time.monotonic() + lead_s), session.quantum)


def _start_here(session: LinkSession, how: LinkStart, tell: Callable[[str], None]) -> float:
    """Start on the next bar line at least `lead_s` ahead, starting the transport if it is not
    playing (the show's tempo proposed first)."""
    snapshot = session.snapshot()
    if snapshot.playing:
        bar = next_bar(session, how.lead_s)
        tell(f"the session plays ({peers_text(snapshot.peers)}, {snapshot.tempo:.2f} bpm): "
             f"the show starts on its next bar line")
        return bar
    if how.tempo is not None and abs(snapshot.tempo - how.tempo) > 1e-3:
        session.propose_tempo(how.tempo)
        snapshot = session.snapshot()
    bar = next_bar(session, how.lead_s + START_LEAD_S)
    start_mono = snapshot.mono_of_beat(bar)
    alone = "alone, as the session's first peer" if snapshot.peers == 0 else f"with {peers_text(snapshot.peers)}"
    tell(f"starting the session's transport {alone}, at {snapshot.tempo:.2f} bpm, on a bar line "
         f"{start_mono - time.monotonic():.2f} s ahead")
    session.start_playing(bar)
    session.count_from_start()
    return _bar_nearest(session, start_mono)


def _joined(session: LinkSession, tell: Callable[[str], None]) -> float | None:
    """The transport just started elsewhere: count beats from its start; its first bar line,
    or None (said) if that is already MISSED_S gone."""
    start = session.count_from_start()
    snapshot = session.snapshot()
    # Link's beat 0 is the first bar line at or after the start; a start a hair after a bar line
    # (an audio buffer's rounding, a peer's microseconds) is on that bar line, not the next
    first = -float(session.quantum) if start <= -session.quantum + ON_THE_BAR_BEATS else 0.0
    late = time.monotonic() - snapshot.mono_of_beat(first)
    if late > MISSED_S:
        tell(f"the session started playing {late:.1f} s before this host heard it: the show runs "
             "elsewhere; waiting for the next start (stop the session's transport and play it again)")
        return None
    tell(f"the session plays ({peers_text(snapshot.peers)}, {snapshot.tempo:.2f} bpm): "
         "the show starts on the bar line its transport started on")
    return first


def _bar_nearest(session: LinkSession, mono: float) -> float:
    """The bar line nearest monotonic `mono` in the session's count now (a renumbering moved
    the count, not the instant)."""
    beat = session.snapshot().beat_at_mono(mono)
    return round(beat / session.quantum) * session.quantum
