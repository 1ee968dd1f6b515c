"""Log times (wall-clock ns) to show time, as every review reads them: the one definition of
a show's duration, its holds and pauses, its wall time and every moment's show time.

A show's zero is not in the metadata (the run's `start_ns` is taken when the run is prepared,
before the ports open), but the log says where the show clock stood from the moment it started:
the run takes a `/choreo/clock` sample then, and every step start carries its show time. The
first of these fixes the zero to the microsecond. It comes after the frames sent when the port
opened (an hth4-2.2 link's ACK check and config read), so `ShowTimes.of` reads ahead to it
before a review places any frame: those frames fall before zero, at negative show times, in the
order they were sent. Only a log with neither (a run stopped before its show started) falls back
on the metadata's start.

Show time does not always move with the wall clock: it stands still while a GO cue waits
(`held`) and while the operator pauses (`paused`), and on the music's clock it drifts with the
sound card. `ShowTimes.of` reads every clock sample before a review places anything (a second,
clock-only read of the log), so a frame or a command during a hold is placed at the show time
the clock stood at, not where the clock would have been had it run on:
- a sample's `state` says when the clock stopped and went on (the run writes one at each change);
- an older log's samples have no state: on the machine's clock (which never drifts) a sample
  behind the time the one before predicts, and not before it, marks a hold that ended there,
  as long as it was short of the prediction (a new --loop pass goes back before it: no hold);
- a sample the mapping so far does not predict (to a millisecond) starts a new piece (a hold's
  end, a loop's next pass, the music's drift), so the pieces are few and memory stays bounded.
A sample earlier than the one before it (a damaged or hostile log) is counted and passed over:
inserting it would cost a reviewer time growing with the square of the samples.

Two more turns of the clock are the reviews' to know:
- a --loop pass starts the show clock again at the section's start: a sample behind the one
  before it in show time (which no hold, pause or drift makes: the music never goes back, and
  --loop runs on the machine's clock) is a new pass, and the show time it went back is counted
  (`rewound_s`), so that the time the clock ran and the drawing's axis go on across the passes;
- on the music's clock, a resume does not move show time at once: the song is heard again a
  chunk and the sound card's buffer later (~10-35 ms), and only then does show time go on (the
  run writes its resume sample, true, with show time still where it paused). The pause ends
  where the first sample after it says show time began to move again (its show time less the
  pause's, back from its log time): so that gap is pause, not drift, in every review.

On an Ableton Link session (samples of source `link`) show time runs in real seconds from the
show's first bar line, but a cue written in bars and beats falls where the session's beat
timeline put it, and a peer's tempo change moves it: `LinkTimes` keeps what the samples say of
the session (its tempos, peers, transport, jumps) and places a beat on show time by them. Within
a tempo the beat runs straight, so a few samples a tempo are enough: one every LINK_THIN_S,
the last, and each change's (memory bounded by the show's length and its changes, not its samples).

Besides show time, a review may draw on `elapsed`: show time with the time the clock stood
still put back in. It moves with the wall clock (less the music's drift), so a motion that ran
through a hold has its real length there, and with no hold it is show time itself.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from itertools import accumulate
from collections.abc import Mapping
from dataclasses import dataclass

from choreo.clock import HELD, PAUSED, RUNNING
from choreo.log.format import (CLOCK_TOPIC, STEP_TOPIC, ClockRecord, CommandRecord, Result, StepRecord, cue_name,
                               parse)
from choreo.log.reader import LogReader
from choreo.show.model import LINK

BREAK_S = 0.001  # a clock sample this far from the mapping's prediction starts a new piece
# How far `ShowTimes.of` reads ahead for the show clock's start: what comes before it is what a
# run sends and says before its show starts (a few frames and log lines a robot), so a log with
# more has no start to find and the reading ahead costs a bounded time.
LOOKAHEAD_MESSAGES = 10_000
MACHINE = "machine"  # the clock source that holds at a GO cue and never drifts
LINK_THIN_S = 5.0  # Link samples on one line closer than this to the one kept before: the last is kept
LINK_CHANGES = 1000  # the session's changes kept one by one (each counted)


def fixed(value: float, places: int = 3, width: int = 0, sign: bool = False) -> str:
    """A time (or any figure) as every review prints it, `places` decimals, right-aligned in
    `width`: never `-0.000`. A merged host's shift, or a frame a few ns before show zero, rounds
    to zero with a minus that reads as a time before the show."""
    text = f"{value:{'+' if sign else ''}.{places}f}"
    if text.startswith("-") and not text.strip("-0."):
        text = ("+" if sign else "") + text[1:]
    return text.rjust(width)


def rounded(value: float, places: int) -> float:
    """`round`, never -0.0 (what an export writes: `-0.0` in CSV and JSON reads as before the show)."""
    return round(value, places) + 0.0


def _planned(step: StepRecord) -> float:
    """A step's planned time, as where a run began: the first step's is 0 (a lead-in is no part)."""
    return max(0.0, float(step.estimated_s)) if step.index else 0.0


def show_zero_ns(reader: LogReader) -> int | None:
    """The run's start as the metadata gives it (wall-clock ns), before a step says better."""
    return reader.info.start_ns


@dataclass(frozen=True)
class Stand:
    """A time the show clock stood still: held at a GO cue, or paused by the operator."""

    kind: str  # held | paused
    show_s: float  # where show time stood
    start_ns: int  # log time it stopped
    end_ns: int | None  # log time it went on (None: it never did, the log ends held or paused)

    def seconds(self, end_ns: int | None) -> float:
        """How long it stood (an open one: up to `end_ns`, the log's last message)."""
        end = self.end_ns if self.end_ns is not None else end_ns
        return max(0.0, ((end if end is not None else self.start_ns) - self.start_ns) / 1e9)


class ShowTimes:
    """Wall-clock log times to show-clock seconds; see the module's docstring."""

    def __init__(self, zero_ns: int | None) -> None:
        self.zero_ns = zero_ns
        self.anchored = False  # the zero comes from the show clock (a sample or a step), not the metadata
        self.complete = False  # every clock sample is read (`of`): later samples change nothing
        self.disordered = 0  # clock samples earlier than the one before them, passed over
        self.start_s = 0.0  # the show time the run began at: 0, or --from's step's (see `anchor`)
        self._rewind_ns: list[int] = []  # where a --loop pass went back (log time)
        self._rewound: list[float] = []  # and the show time gone back up to there (running sums)
        self._restart: int | None = None  # a music pause just resumed: its stand, until show time moves
        self.stands: list[Stand] = []
        self._break_ns: list[int] = []  # where a piece begins (log time)
        self._break_s: list[float] = []  # and the show time there
        self._last: tuple[int, float] | None = None  # the last sample: log time, show time
        self._stood: list[float] = [0.0]  # time stood still before each stand began (prefix sums)
        # `elapsed_of_show`'s table, made once: (end_ns, stands' show times in order, time stood up to each)
        self._by_show: tuple[int | None, list[float], list[float]] | None = None
        self.link: LinkTimes | None = None  # the Link session, if samples of source link came

    @classmethod
    def of(cls, reader: LogReader) -> ShowTimes:
        """The log's show times, anchored and with every clock sample read before any frame is
        placed (see the module's docstring). A sample that is not a clock sample is ValueError,
        KeyError or TypeError, as from `parse`, raised as the reader's one line."""
        times = cls(show_zero_ns(reader))
        times.anchor(reader)
        times.read_clock(reader)
        return times

    def anchor(self, reader: LogReader) -> None:
        """Read ahead to the show clock's first sample or step start and fix the zero by it, and
        on to the first step start: where the run began (`start_s`): 0 for a show from its first
        step; --from's (or --loop's) step's planned time for one begun later; a step skipped
        before the first start is where the run began too (the first cue skipped: the clock ran
        from 0 to the second cue, and that is run time). The show clock starts
        a moment before (a lead-in, a show for several robots starting its threads): no part of it.

        A message that does not parse, or holds no number, is left for the review's own pass
        to report."""
        messages = reader.messages()
        skipped = math.inf  # the earliest planned time of a step skipped before the first start
        try:
            for count, (topic, log_time, data) in enumerate(messages):
                if count >= LOOKAHEAD_MESSAGES:
                    return
                if topic != CLOCK_TOPIC and topic != STEP_TOPIC:
                    continue
                try:
                    record = parse(topic, data)
                except (KeyError, TypeError, ValueError, AttributeError):
                    continue
                if isinstance(record, StepRecord):
                    self.see_step(log_time, record)
                    if record.event == "skip":
                        skipped = min(skipped, _planned(record))
                    elif record.event == "start" and self.anchored:
                        self.start_s = min(skipped, _planned(record))
                        return
                elif isinstance(record, ClockRecord):
                    self.see_start(log_time, record.show_s)
        finally:
            messages.close()

    def read_clock(self, reader: LogReader) -> None:
        """Every clock sample, in one pass over the clock topic (the reader skips the others).
        A sample that does not parse is passed over here: the review's own pass reports it as
        the one line it makes of any message that is not choreo's."""
        for _, log_time, data in reader.messages((CLOCK_TOPIC,)):
            try:
                sample = parse(CLOCK_TOPIC, data)
                if isinstance(sample, ClockRecord):
                    self.see_clock(log_time, sample)
            except (KeyError, TypeError, ValueError, AttributeError):
                continue
        self.complete = True

    def see_step(self, log_time: int, step: StepRecord) -> None:
        if step.event == "start":
            self.see_start(log_time, step.actual_s)

    def see_start(self, log_time: int, show_s: float) -> None:
        """A step started at `show_s` on the show clock: the first show time that is a number
        (a damaged record's is not), of a step or a clock sample, fixes the zero."""
        if self.anchored or not isinstance(show_s, (int, float)) or not math.isfinite(show_s * 1e9):
            return
        self.zero_ns = log_time - round(show_s * 1e9)
        self.anchored = True

    def see_clock(self, log_time: int, sample: ClockRecord) -> None:
        """A /choreo/clock sample: where show time really stood at `log_time`."""
        if self.complete:
            return
        if self._last is not None and log_time < self._last[0]:
            self.disordered += 1
            return
        self.see_start(log_time, sample.show_s)
        if sample.source == LINK:
            if self.link is None:
                self.link = LinkTimes()
            self.link.see(sample)
        if self._restart is not None:
            self._restarted(log_time, sample)
        if self._last is not None and sample.show_s < self._last[1] - BREAK_S:
            self._rewind(log_time, sample.show_s)
        predicted = self._piece_seconds(log_time) if (self._break_ns or self.zero_ns is not None) else None
        self._see_state(log_time, sample, predicted)
        if predicted is None or abs(predicted - sample.show_s) > BREAK_S:
            self._break_ns.append(log_time)
            self._break_s.append(sample.show_s)
        self._last = (log_time, sample.show_s)

    def _see_state(self, log_time: int, sample: ClockRecord, predicted: float | None) -> None:
        """A stand begins or ends here: as the sample's state says, or (an older log's
        machine clock) as a sample behind the prediction, and not before the last, tells."""
        open_stand = self.stands[-1] if self.stands and self.stands[-1].end_ns is None else None
        state = sample.state
        if state is None:
            if open_stand is not None:
                self._close(log_time)
            behind = (predicted - sample.show_s) if predicted is not None else 0.0
            last_s = self._last[1] if self._last is not None else -math.inf
            if sample.source == MACHINE and behind > BREAK_S and sample.show_s >= last_s - BREAK_S:
                start = log_time - round(behind * 1e9)
                self._open(Stand(HELD, sample.show_s, max(start, self._last[0] if self._last else start), log_time))
            return
        if open_stand is not None and open_stand.kind != state:
            self._close(log_time)
            if state == RUNNING and sample.source != MACHINE and sample.show_s == open_stand.show_s:
                self._restart = len(self.stands) - 1  # the music goes on a little later (module docstring)
            open_stand = None
        if state != RUNNING and open_stand is None:
            self._open(Stand(state, sample.show_s, log_time, None))

    def _open(self, stand: Stand) -> None:
        before = self.stands[-1].seconds(stand.start_ns) if self.stands else 0.0
        if self.stands:
            self._stood.append(self._stood[-1] + before)
        self.stands.append(stand)

    def _close(self, log_time: int) -> None:
        last = self.stands[-1]
        self.stands[-1] = Stand(last.kind, last.show_s, last.start_ns, log_time)

    def _restarted(self, log_time: int, sample: ClockRecord) -> None:
        """The first sample after a music pause's resume: the pause ends where show time began
        to move again, and the piece the resume began starts there (see the module's docstring).
        A sample still at the pause's show time moves the end up to it and waits for the next."""
        at = self._restart
        assert at is not None
        stand = self.stands[at]
        moved_s = sample.show_s - stand.show_s
        if stand.end_ns is None or moved_s < 0 or at != len(self.stands) - 1:
            self._restart = None
            return
        moved = log_time - round(moved_s * 1e9)
        if moved_s > 0:
            self._restart = None
        if not stand.end_ns < moved <= log_time:
            return
        if self._break_ns and self._break_ns[-1] == stand.end_ns and self._break_s[-1] == stand.show_s:
            self._break_ns[-1] = moved  # the resume's piece: from where show time moved
        self.stands[at] = Stand(stand.kind, stand.show_s, stand.start_ns, moved)

    def _rewind(self, log_time: int, show_s: float) -> None:
        """A --loop pass began: the clock went back from where it was to `show_s`."""
        back = (self.seconds(log_time) or 0.0) - show_s
        if back > 0:
            self._rewind_ns.append(log_time)
            self._rewound.append((self._rewound[-1] if self._rewound else 0.0) + back)

    def rewound_s(self, log_time: int | None = None) -> float:
        """The show time --loop passes went back up to `log_time` (None: in all; 0: no loop)."""
        at = bisect_right(self._rewind_ns, log_time) - 1 if log_time is not None else len(self._rewound) - 1
        return self._rewound[at] if at >= 0 else 0.0

    def passes(self, log_time: int | None = None) -> int:
        """How many --loop passes began up to `log_time` (None: in all; 1: the show ran once)."""
        return 1 + (bisect_right(self._rewind_ns, log_time) if log_time is not None else len(self._rewind_ns))

    def stand_at(self, log_time: int) -> int:
        """The index of the last stand begun at or before `log_time` (-1: none)."""
        low, high = 0, len(self.stands)
        while low < high:
            mid = (low + high) // 2
            if self.stands[mid].start_ns <= log_time:
                low = mid + 1
            else:
                high = mid
        return low - 1

    def seconds(self, log_time: int | None) -> float | None:
        """Show time at `log_time`: where the clock stood, during a stand."""
        if log_time is None:
            return None
        at = self.stand_at(log_time)
        if at >= 0:
            stand = self.stands[at]
            if stand.end_ns is None or log_time < stand.end_ns:
                return stand.show_s
        return self._piece_seconds(log_time)

    def _piece_seconds(self, log_time: int) -> float:
        """Show time by the pieces alone: as if the clock ran on from the last sample."""
        piece = bisect_right(self._break_ns, log_time) - 1
        if piece >= 0:
            return self._break_s[piece] + (log_time - self._break_ns[piece]) / 1e9
        if self.zero_ns is None:
            self.zero_ns = log_time  # no metadata, no step, no sample: the first message is zero
        return (log_time - self.zero_ns) / 1e9

    def stood_s(self, log_time: int | None) -> float:
        """How long the clock had stood still (held or paused) up to `log_time`."""
        if log_time is None:
            return 0.0
        at = self.stand_at(log_time)
        if at < 0:
            return 0.0
        stand = self.stands[at]
        until = log_time if stand.end_ns is None else min(log_time, stand.end_ns)
        return self._stood[at] + max(0, until - stand.start_ns) / 1e9

    def elapsed(self, log_time: int | None) -> float | None:
        """Show time with the time stood still, and what --loop's passes went back, put back in:
        the axis a timeline draws on (it only goes forward)."""
        show_s = self.seconds(log_time)
        return None if show_s is None else show_s + self.stood_s(log_time) + self.rewound_s(log_time)

    def elapsed_of_show(self, show_s: float, end_ns: int | None = None) -> float:
        """Where a show time falls on the `elapsed` axis: after the stands at show times up to
        it (a planned time that no log time places: a play the run never reached); `end_ns`:
        the log's end, where a stand that never ended ends."""
        if self._by_show is None or self._by_show[0] != end_ns:
            ordered = sorted(self.stands, key=lambda stand: stand.show_s)
            stood = list(accumulate((stand.seconds(end_ns) for stand in ordered), initial=0.0))
            self._by_show = (end_ns, [stand.show_s for stand in ordered], stood)
        _, shows, stood = self._by_show
        return show_s + stood[bisect_right(shows, show_s)]


@dataclass(frozen=True)
class SessionChange:
    """A change of the Link session, where a clock sample marks it on the show clock."""

    show_s: float
    kind: str  # tempo | peers | stopped | playing | jump
    text: str  # `tempo 120.00 -> 150.00 bpm`, `peers 2 -> 1`, `transport stopped`

    def to_json(self) -> dict:
        return {"show_s": round(self.show_s, 3), "kind": self.kind, "text": self.text}


_SESSION_TEXT = {"stopped": "transport stopped", "playing": "transport playing again", "jump": "beat timeline jumped"}


def _number(value: object) -> float | None:
    """A sample's number (a log's field may be absent or, where no type is checked, anything)."""
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


class LinkTimes:
    """The Link session over a run, as its /choreo/clock samples tell it: the tempo and each
    change of it, the peers seen, the transport's stops, the timeline's jumps, and where a show
    beat fell on the show clock (`show_of_beat`: what a cue in bars was planned at, on Link)."""

    def __init__(self) -> None:
        self.samples = 0
        self.tempos: list[tuple[float, float]] = []  # (show s, bpm): the first, then each change
        self.changes: list[SessionChange] = []  # the first LINK_CHANGES, in show order
        self.counts: dict[str, int] = {}  # kind -> how many changes of it
        self.peers: tuple[int, int] | None = None  # the fewest and most other peers seen
        self.joined = self.left = 0
        self._peers: int | None = None
        self._tempo: float | None = None
        self._heard: float | None = None  # a tempo event's sample, before a sample carried the new tempo
        # the beat map: samples kept (show s, beat, tempo), in beat order
        self._shows: list[float] = []
        self._beats: list[float] = []
        self._tempos: list[float] = []

    def see(self, sample: ClockRecord) -> None:
        self.samples += 1
        show_s, tempo, beat = sample.show_s, _number(sample.tempo), _number(sample.beat)
        tempo = tempo if tempo is not None and 1 <= tempo <= 10_000 else None  # Link's: 20 to 999 bpm
        if sample.event == "tempo" and self._heard is None:
            self._heard = show_s
        self._see_tempo(show_s, tempo)
        peers = sample.peers
        if isinstance(peers, int) and not isinstance(peers, bool) and peers >= 0:
            self._see_peers(show_s, peers)
        if sample.event in _SESSION_TEXT:
            self._change(show_s, str(sample.event), _SESSION_TEXT[str(sample.event)])
        if beat is not None and tempo is not None:
            self._map(show_s, beat, tempo)

    def _change(self, show_s: float, kind: str, text: str) -> None:
        self.counts[kind] = self.counts.get(kind, 0) + 1
        if len(self.changes) < LINK_CHANGES:
            self.changes.append(SessionChange(show_s, kind, text))

    def _see_tempo(self, show_s: float, tempo: float | None) -> None:
        if tempo is None:
            return
        if self._tempo is None or abs(tempo - self._tempo) > 1e-6:
            at = show_s if self._heard is None else self._heard  # heard there, if a tempo event said so
            if self._tempo is not None:
                self._change(at, "tempo", f"tempo {fixed(self._tempo, 2)} -> {fixed(tempo, 2)} bpm")
            if len(self.tempos) < LINK_CHANGES:
                self.tempos.append((at, tempo))
            self._heard = None
        self._tempo = tempo

    def _see_peers(self, show_s: float, peers: int) -> None:
        low, high = self.peers if self.peers is not None else (peers, peers)
        self.peers = (min(low, peers), max(high, peers))
        if self._peers is not None and peers != self._peers:
            self.joined += max(0, peers - self._peers)
            self.left += max(0, self._peers - peers)
            self._change(show_s, "peers", f"peers {self._peers} -> {peers}")
        self._peers = peers

    def _map(self, show_s: float, beat: float, tempo: float) -> None:
        """Keep the sample for `show_of_beat`: a run of samples on one straight line (one tempo,
        no jump) keeps one a LINK_THIN_S and its last; a beat behind the last (a --loop pass, a
        jump back) starts the map again (the cues still to come are placed on what followed)."""
        beats, shows, tempos = self._beats, self._shows, self._tempos
        if beats and beat < beats[-1]:
            for kept in (shows, beats, tempos):
                kept.clear()
        n = len(beats)
        if n >= 2 and tempos[n - 2] == tempos[n - 1] == tempo and shows[n - 1] - shows[n - 2] < LINK_THIN_S \
                and abs(shows[n - 2] + (beat - beats[n - 2]) * 60.0 / tempo - show_s) <= BREAK_S:
            shows[n - 1], beats[n - 1] = show_s, beat
            return
        shows.append(show_s)
        beats.append(beat)
        tempos.append(tempo)

    def show_of_beat(self, beat: float) -> float | None:
        """The show time the session put show beat `beat` at (0: bar 1 beat 1), None without a
        sample. Between two samples on one line, by the nearer; across a tempo change, by the
        line of the tempo the beat fell in (the two lines meet where the tempo changed: a
        change's own sample may still carry the tempo before it); past the last, at its tempo."""
        near = self._near(beat, by_show=False)
        return None if near is None else self._shows[near] + (beat - self._beats[near]) * 60.0 / self._tempos[near]

    def beat_of_show(self, show_s: float) -> float | None:
        """The show beat the session was at, at show time `show_s` (`show_of_beat`'s inverse)."""
        near = self._near(show_s, by_show=True)
        return None if near is None else self._beats[near] + (show_s - self._shows[near]) * self._tempos[near] / 60.0

    def _near(self, value: float, by_show: bool) -> int | None:
        """The kept sample whose line places `value` (a beat, or a show time `by_show`)."""
        beats, shows = self._beats, self._shows
        along = shows if by_show else beats
        if not along:
            return None
        i = bisect_right(along, value) - 1
        if i < 0 or i == len(along) - 1:
            return max(i, 0)
        k_i, k_j = 60.0 / self._tempos[i], 60.0 / self._tempos[i + 1]
        if abs(shows[i] + (beats[i + 1] - beats[i]) * k_i - shows[i + 1]) <= BREAK_S or k_i == k_j:
            return i if value - along[i] <= along[i + 1] - value else i + 1
        meet = (shows[i + 1] - shows[i] + beats[i] * k_i - beats[i + 1] * k_j) / (k_i - k_j)  # a beat
        if by_show:
            meet = shows[i] + (meet - beats[i]) * k_i
        return i if value <= meet else i + 1

    def show_of_bar(self, bar: int, beat: float, meter: int) -> float | None:
        """`show_of_beat` of a cue as a show writes it (bar 1 beat 1 is show beat 0)."""
        return self.show_of_beat((bar - 1) * meter + (beat - 1))

    def to_json(self) -> dict:
        low, high = self.peers if self.peers is not None else (None, None)
        return {"samples": self.samples, "tempos": [{"show_s": round(s, 3), "bpm": bpm} for s, bpm in self.tempos],
                "peers": {"min": low, "max": high, "joined": self.joined, "left": self.left},
                "changes": [change.to_json() for change in self.changes], "counts": self.counts}


@dataclass(frozen=True)
class Durations:
    """The one figure of each of a show's lengths every review prints (seconds)."""

    show_s: float | None  # where the show clock ended: holds and pauses not counted
    held_s: float  # stood still at GO cues
    paused_s: float  # stood still, paused by the operator
    holds: int
    pauses: int
    wall_s: float | None  # from the run's start to its end, on the wall clock: ran, held and paused
    start_s: float = 0.0  # where the show clock began (--from: its step's time)
    ran_s: float | None = None  # how long it ran: from start_s to show_s, and every --loop pass before
    passes: int = 1  # --loop: the passes begun

    def to_json(self) -> dict:
        return {"show_s": _ms(self.show_s), "held_s": _ms(self.held_s), "paused_s": _ms(self.paused_s),
                "holds": self.holds, "pauses": self.pauses, "wall_s": _ms(self.wall_s),
                "start_s": _ms(self.start_s), "ran_s": _ms(self.ran_s), "passes": self.passes}


def durations(times: ShowTimes, result: Mapping[str, str] | None, last_ns: int | None) -> Durations:
    """The show's lengths: on the show clock, the run's own figure (its result) where it closed
    its log, else the show time of the log's last message; the stands up to that message."""
    show_s = result_show_s(result)
    if show_s is None and last_ns is not None:
        show_s = times.seconds(last_ns)
    held = [s.seconds(last_ns) for s in times.stands if s.kind == HELD]
    paused = [s.seconds(last_ns) for s in times.stands if s.kind == PAUSED]
    ran = None if show_s is None else max(0.0, show_s - times.start_s + times.rewound_s(last_ns))
    wall = None if ran is None else ran + sum(held) + sum(paused)
    return Durations(show_s, sum(held), sum(paused), len(held), len(paused), wall, times.start_s, ran,
                     times.passes(last_ns))


def result_show_s(result: Mapping[str, str] | None) -> float | None:
    """The run's show time at its end, as its result says (None: missing or damaged: metadata
    carries no CRC)."""
    text = (result or {}).get(Result.SHOW_S)
    try:
        value = float(text) if text else None
    except ValueError:
        return None
    return value if value is not None and math.isfinite(value) and abs(value) < 1e9 else None


def _ms(seconds: float | None) -> float | None:
    """Rounded to the millisecond every review agrees to."""
    return None if seconds is None else round(seconds, 3)


RELEASE_SLACK_NS = 100_000_000  # a GO's step starts, and its command is logged, this soon after the hold ends


@dataclass
class StandNote:
    """What a review says of one stand: the cue it held at, and the command that ended it."""

    stand: Stand
    cue: str | None = None  # `cue 1 'applause'`: the GO cue a hold waited at
    by: str | None = None  # `go from key`, `resume from osc udp 127.0.0.1:53001`, `panic from key`

    def ended_by(self, command: str) -> None:
        self.by = command

    def held_at(self, cue: str) -> None:
        self.cue = cue

    def text(self, end_ns: int | None) -> str:
        """`held 2.300 s at cue 1 'applause', go from key`."""
        at = f" at {self.cue}" if self.cue else ""
        by = f", {self.by}" if self.by else "" if self.stand.end_ns is not None else ", to the end of the log"
        return f"{self.stand.kind} {fixed(self.stand.seconds(end_ns))} s{at}{by}"


class StandNotes:
    """Each stand's cue and release, from the step starts and commands a review's pass sees
    (`see`, in log order): the commands given while it stood (the last one carried out ended
    it), the GO cue whose step started as a hold ended. `limit`: how many stands are noted."""

    def __init__(self, times: ShowTimes, limit: int | None = None) -> None:
        self.times = times
        self.notes = [StandNote(stand) for stand in times.stands[:limit]]

    def see(self, log_time: int, command: str | None = None, source: str = "", step_ref: str | None = None) -> None:
        """A command carried out (`command`, from `source`) or a GO cue's step start (`step_ref`)."""
        at = self.times.stand_at(log_time)
        if at < 0 or at >= len(self.notes):
            return
        note = self.notes[at]
        stand = note.stand
        end = stand.end_ns
        if command is not None and (end is None or log_time <= end + RELEASE_SLACK_NS):
            note.ended_by(f"{command} from {source}")
        elif step_ref is not None and stand.kind == HELD and note.cue is None and end is not None \
                and end <= log_time <= end + RELEASE_SLACK_NS:
            note.held_at(step_ref)


def see_for_stands(notes: StandNotes, record: object, log_time: int) -> None:
    """Hand `notes` what it reads from a record of a review's pass: a command carried out (one
    by one: not a sum of those not logged), a GO cue's step start."""
    if isinstance(record, CommandRecord):
        if record.status == "ok" and record.count is None:
            notes.see(log_time, command=str(record.command), source=str(record.source))
    elif isinstance(record, StepRecord) and record.event in ("start", "skip") and record.go:
        notes.see(log_time, step_ref=cue_name(record.cue_number, record.label) if record.cue_number else record.ref)
