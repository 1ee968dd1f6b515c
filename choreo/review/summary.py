"""`choreo log summary`: did the show run as planned, where did the timing slip, what did the robot say.

One linear pass over the log (see `reader`), in memory that does not grow with the log: counts,
distributions kept as counters of microsecond-rounded values (reply latencies are bounded by the
reply timeout, cue lateness by the show), per-slot motion statistics, and only the first few
plays and log lines listed one by one. Records come typed from `choreo.log.format`, and plays
from its motion tracker, the one the timeline uses too.
"""

from __future__ import annotations


from dataclasses import dataclass, field, replace
from pathlib import Path

from choreo.numtext import whole_number
from choreo.log.format import (CHOREO_TOPICS, ERROR, WARNING, ClockRecord, CommandRecord, LogLayouts, LogRecord,
                               ROBOTS_KEPT, Info, MotionPlay, MotionTracker, Record, Result, RxRecord, StepRecord,
                               TxRecord,
                               is_late, parse, robot_key, slipped)
from choreo.log.reader import Cut, LogReader
from choreo.review.showtime import (Durations, LinkTimes, ShowTimes, StandNote, StandNotes, durations,
                                    see_for_stands)
from choreo.wire.protocol import FrameKind, ReplyKind
# counted (and shown) even at 0: the frames every run sends, and every reply (the wire's names)
FRAME_KINDS = tuple(kind.value for kind in (FrameKind.STOP, FrameKind.PLAY, FrameKind.RESTORE, FrameKind.STATUS))
REPLY_KINDS = tuple(kind.value for kind in ReplyKind)
LISTED_PLAYS = 30  # plays listed one by one; past this, per motion slot only
LISTED_LOG_LINES = 10
LISTED_COMMANDS = 20
LISTED_STANDS = 20


class Distribution:
    """Values in milliseconds, kept as counts per microsecond: exact to 1 us, bounded in memory.

    A log of a million replies has a few thousand distinct latencies, so quantiles over the
    whole run cost a dict of that size, not a list of a million floats.
    """

    def __init__(self, counts: dict[int, int] | None = None) -> None:
        self.counts: dict[int, int] = counts if counts is not None else {}

    def add(self, ms: float) -> None:
        key = round(ms * 1000)
        self.counts[key] = self.counts.get(key, 0) + 1

    def __len__(self) -> int:
        return sum(self.counts.values())

    @property
    def min(self) -> float | None:
        return min(self.counts) / 1000 if self.counts else None

    @property
    def max(self) -> float | None:
        return max(self.counts) / 1000 if self.counts else None

    def quantile(self, q: float) -> float | None:
        """The nearest-rank quantile (the value below which a fraction q of the samples lie)."""
        n = len(self)
        if not n:
            return None
        rank = max(1, -(-q * n // 1))  # ceil(q * n), at least the first
        seen = 0
        for key in sorted(self.counts):
            seen += self.counts[key]
            if seen >= rank:
                return key / 1000
        return max(self.counts) / 1000

    @property
    def median(self) -> float | None:
        return self.quantile(0.5)

    @property
    def p99(self) -> float | None:
        return self.quantile(0.99)

    def above(self, ms: float) -> int:
        return sum(c for k, c in self.counts.items() if k > ms * 1000)


@dataclass(frozen=True)
class Play:
    """A motion the board was told to play: from its ACKed restore to the status that saw it end."""

    motion: int
    step: int | None
    label: str | None
    start_s: float  # show clock: the restore frame that started it
    duration_s: float | None  # to the first status query that found it not executing
    ended_by: str  # "status" (measured), "stop" (the next play stopped it), "state read" (over by then), "end of log"


@dataclass
class MotionStats:
    """One motion slot over the run: how often it played and how long it really took."""

    motion: int
    plays: int = 0
    durations: list[float] = field(default_factory=list)  # kept per slot up to a bound
    unmeasured: dict[str, int] = field(default_factory=dict)  # what ended the plays no status query timed: count

    def add(self, play: Play) -> None:
        self.plays += 1
        if play.duration_s is None:
            self.unmeasured[play.ended_by] = self.unmeasured.get(play.ended_by, 0) + 1
        elif len(self.durations) < 10_000:
            self.durations.append(play.duration_s)

    @property
    def measured(self) -> int:
        return len(self.durations)

    @property
    def median_s(self) -> float | None:
        if not self.durations:
            return None
        ordered = sorted(self.durations)
        return ordered[(len(ordered) - 1) // 2]


@dataclass(frozen=True)
class LogLine:
    show_s: float
    level: int
    message: str


@dataclass
class ClockSpan:
    """The show clock against the machine's over the run (/choreo/clock): on the music's clock
    the two part as the sound card's crystal drifts from the computer's."""

    source: str
    samples: int
    first: ClockRecord
    last: ClockRecord
    first_ns: int = 0  # their log times
    last_ns: int = 0
    stood_s: float = 0.0  # of the span, the time the show clock stood still (held, paused)
    rewound_s: float = 0.0  # of the span, the show time --loop passes went back

    def add(self, sample: ClockRecord, log_time: int = 0) -> None:
        self.samples += 1
        self.last = sample
        self.last_ns = log_time

    @property
    def span_s(self) -> float:
        return (self.last.monotonic_ns - self.first.monotonic_ns) / 1e9

    @property
    def ran_s(self) -> float:
        """Of the span, the time the show clock ran: drift is over this time only."""
        return max(0.0, self.span_s - self.stood_s)

    @property
    def drift_ms(self) -> float:
        """How far the show clock ran ahead of the machine's while it ran (ms): a hold or a
        pause is no drift."""
        return ((self.last.show_s - self.first.show_s + self.rewound_s) - self.ran_s) * 1e3


@dataclass
class Summary:
    """Everything `choreo log summary` reports about one run log."""

    path: Path
    run: dict[str, str]
    result: dict[str, str] | None
    complete: bool
    cut: Cut | None
    run_notes: list[str] = field(default_factory=list)  # what the review keeps not of a hostile log's metadata
    messages: int = 0
    duration_s: float | None = None  # show clock at the last message (or the result's, if closed)
    lengths: Durations | None = None  # the duration, holds, pauses, wall time: `showtime.durations`
    stands: list[StandNote] = field(default_factory=list)  # the holds and pauses, the first LISTED_STANDS
    end_ns: int | None = None  # the log time of its last message (where a stand that never ended ends)
    clock_disordered: int = 0  # clock samples earlier than the one before, passed over
    steps_run: int = 0
    steps_done: int = 0
    steps_late: int = 0  # play steps late on stage, counted once each as the runner counts them:
    # started more than LATE_MS after their time, or (`logformat.slipped`) retries delayed the motion that long
    steps_late_by_retries: int = 0  # of those, the plays on time whose retries made them late
    steps_failed: int = 0
    steps_aborted: int = 0
    steps_unfinished: int = 0
    steps_skipped: int = 0  # cues the operator skipped: their steps never ran
    frames: dict[str, int] = field(default_factory=dict)  # tx kind -> count
    retries: int = 0  # frames sent again (attempt > 1)
    replies: dict[str, int] = field(default_factory=dict)  # rx kind -> count
    unanswered: int = 0  # frames with no reply in the log (a cut log)
    stale: int = 0  # late replies to earlier frames, read and set aside before a frame's own reply
    latency: Distribution = field(default_factory=Distribution)  # ms, replies that came back
    lateness: Distribution = field(default_factory=Distribution)  # ms, play step starts (the cues)
    motion_starts: Distribution = field(default_factory=Distribution)  # ms, cued plays: start frame minus cue
    plays: list[Play] = field(default_factory=list)  # the first LISTED_PLAYS
    plays_total: int = 0
    motions: dict[int, MotionStats] = field(default_factory=dict)
    warnings: int = 0
    errors: int = 0
    log_lines: list[LogLine] = field(default_factory=list)  # the first LISTED_LOG_LINES warnings/errors
    robots: dict[str, Summary] = field(default_factory=dict)  # a show for several robots: each one's figures
    skew: Distribution = field(default_factory=Distribution)  # ms, unison plays: first to last motion start
    clock: ClockSpan | None = None  # the show clock against the machine's (/choreo/clock)
    link: LinkTimes | None = None  # on an Ableton Link session: its tempos, peers, stops and jumps
    commands: list[CommandRecord] = field(default_factory=list)  # the operator's, the first LISTED_COMMANDS records
    commands_total: int = 0  # every command, those `unlogged` records sum up included
    commands_refused: int = 0  # of those, refused or ignored
    commands_unlogged: int = 0  # of those, not logged one by one (summed up by `unlogged` records)
    command_records: int = 0
    commands_by: dict[str, int] = field(default_factory=dict)  # command name -> count, summed up ones included

    @property
    def frames_sent(self) -> int:
        return sum(self.frames.values())

    @property
    def show_name(self) -> str:
        return self.run.get(Info.SHOW) or self.path.stem


# A robot's record in a summary leaves out the whole log's fields.
_SHARED_FIELDS = ("log", "state", "cut", "show", "run_notes", "result")


def summary_record(summary: Summary) -> dict:
    """The summary as one JSON object (`choreo log summary --json`): the same figures as the
    text, in milliseconds and seconds, for scripts."""

    def spread(values: Distribution) -> dict:
        return {"count": len(values), "min_ms": values.min, "median_ms": values.median,
                "p99_ms": values.p99, "max_ms": values.max}

    return {
        "log": str(summary.path),
        "state": "complete" if summary.complete else (summary.cut.state if summary.cut else "unfinished"),
        "cut": str(summary.cut) if summary.cut else None,
        "show": summary.show_name,
        "run": summary.run,
        "run_notes": summary.run_notes,
        "result": summary.result,
        "duration_s": summary.duration_s,
        "lengths": summary.lengths.to_json() if summary.lengths else None,
        "stands": [{"kind": n.stand.kind, "show_s": round(n.stand.show_s, 3),
                    "seconds": round(n.stand.seconds(summary.end_ns), 3), "ended": n.stand.end_ns is not None,
                    "cue": n.cue, "by": n.by} for n in summary.stands],
        "steps": {"run": summary.steps_run, "done": summary.steps_done, "late": summary.steps_late,
                  "late_by_retries": summary.steps_late_by_retries, "failed": summary.steps_failed,
                  "aborted": summary.steps_aborted, "unfinished": summary.steps_unfinished,
                  "skipped": summary.steps_skipped},
        "frames": {**summary.frames, "retries": summary.retries},
        "replies": {**summary.replies, "stale": summary.stale, "unanswered": summary.unanswered},
        "latency": spread(summary.latency),
        "cue_lateness": spread(summary.lateness),
        "motion_start_vs_cue": spread(summary.motion_starts),
        "clock": None if summary.clock is None else {
            "source": summary.clock.source, "samples": summary.clock.samples, "span_s": round(summary.clock.span_s, 6),
            "ran_s": round(summary.clock.ran_s, 6), "drift_ms": round(summary.clock.drift_ms, 3),
            "disordered": summary.clock_disordered,
            Result.SHOW_ZERO_MONOTONIC_NS: _int(summary.result, Result.SHOW_ZERO_MONOTONIC_NS),
            Result.SHOW_ZERO_WALL_NS: _int(summary.result, Result.SHOW_ZERO_WALL_NS),
            **({"link": summary.link.to_json()} if summary.link is not None else {})},
        "motions": [{"motion": m.motion, "plays": m.plays, "measured": m.measured, "median_s": m.median_s,
                     "unmeasured": m.unmeasured}
                    for m in sorted(summary.motions.values(), key=lambda m: m.motion)],
        "commands": [{**command.to_json(), "what": command.what} for command in summary.commands],
        "commands_total": summary.commands_total,
        "commands_refused": summary.commands_refused,
        "commands_unlogged": summary.commands_unlogged,
        "commands_by": summary.commands_by,
        "warnings": summary.warnings,
        "errors": summary.errors,
        **({"unison_skew": spread(summary.skew),
            "robots": {name: {k: v for k, v in summary_record(robot).items() if k not in _SHARED_FIELDS}
                       for name, robot in summary.robots.items()}} if summary.robots else {}),
    }


def stale_replies(stale: str | None) -> list[str]:
    """The late replies in an rx message's `stale` hex, one hex string each.

    The link keeps them as one run of bytes; an RCB-4 reply starts with its own length, which
    splits them back into the replies a reviewer can match with earlier frames. Bytes that do not
    split that way (noise that was waiting on the line) stay together, as logged.
    """
    if not stale:
        return []
    try:
        data = bytes.fromhex(stale)
    except ValueError:
        return [stale]
    replies: list[str] = []
    pos = 0
    while pos < len(data):
        length = data[pos]
        if length < 4 or pos + length > len(data):  # an ACK, the shortest reply, is 4 bytes
            replies.append(data[pos:].hex(" "))
            break
        replies.append(data[pos:pos + length].hex(" "))
        pos += length
    return replies


def summarize(path: str | Path) -> Summary:
    """Read a run log once and summarise it (LogError if it is not a log; a cut log is fine)."""
    with LogReader(path) as reader:
        return summarize_reader(reader)


def summarize_reader(reader: LogReader) -> Summary:
    summary = Summary(reader.path, dict(reader.run_info), None, False, None, list(reader.run_notes))
    tally = _Tally(ShowTimes.of(reader))
    notes = StandNotes(tally.times, LISTED_STANDS)
    parts: dict[str, _Part] = {}  # a show for several robots: each robot's own tally and tracker
    solo = _Part(summary, tally, MotionTracker(LogLayouts.of(reader.run_info).layout(None)))
    topic, count, last_time, left_out = None, 0, None, 0
    try:
        for topic, log_time, data in reader.messages():
            count += 1
            last_time = log_time
            if topic not in CHOREO_TOPICS:
                continue
            record = parse(topic, data)
            see_for_stands(notes, record, log_time)
            if isinstance(record, (TxRecord, RxRecord, StepRecord)):
                part = solo if record.robot is None else _robot_part(parts, record.robot, reader, tally)
                left_out += part is None
                if part is not None:
                    part.see(record, log_time, tally)
            else:
                _see_shared(summary, tally, record, log_time)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise reader.not_choreo(topic, count, exc) from None
    summary.messages = count
    if left_out:
        summary.run_notes.append(f"{left_out:,} frames, replies and steps of robots past the first {ROBOTS_KEPT} "
                                 f"the log names in its messages not reviewed (a show has at most {ROBOTS_KEPT})")
    summary.cut = reader.cut
    summary.result = reader.result
    summary.complete = reader.complete
    for part in [solo, *parts.values()]:
        part.finish()
    tally.fill(summary)
    summary.link = tally.times.link
    if parts:
        order = [name for name in reader.robots if name in parts]
        summary.robots = {name: parts[name].summary for name in order + [n for n in parts if n not in order]}
        _gather(summary, parts, reader.info.unison)
    _lengths(summary, tally.times, reader, last_time)
    summary.stands = notes.notes
    return summary


def _robot_part(parts: dict[str, _Part], robot: str, reader: LogReader, tally: _Tally) -> _Part | None:
    """A robot's own part of the pass; None past ROBOTS_KEPT robots: a hostile log naming 20,000
    robots in its frames made as many trackers and sections (3.3 MB of summary from 390 KB)."""
    part = parts.get(robot)
    if part is None and len(parts) < ROBOTS_KEPT:
        part = parts[robot] = _Part.named(reader, robot, tally)
    return part


def _lengths(summary: Summary, times: ShowTimes, reader: LogReader, last_time: int | None) -> None:
    """The show's lengths by the one definition every review shares; the clock's drift over
    the time it ran."""
    summary.lengths = durations(times, reader.result, last_time)
    summary.duration_s = summary.lengths.show_s
    summary.end_ns = last_time
    summary.clock_disordered = times.disordered
    if summary.clock is not None:
        clock = summary.clock
        summary.clock = replace(clock, stood_s=times.stood_s(clock.last_ns) - times.stood_s(clock.first_ns),
                                rewound_s=times.rewound_s(clock.last_ns) - times.rewound_s(clock.first_ns))


def _see_shared(summary: Summary, tally: _Tally, record: Record, log_time: int) -> None:
    """A record of the whole show, not of one robot: a log line, a clock sample, a command."""
    if isinstance(record, LogRecord):
        tally.log_line(record, log_time, summary)
    elif isinstance(record, ClockRecord):
        tally.times.see_clock(log_time, record)
        if summary.clock is None:
            summary.clock = ClockSpan(record.source, 1, record, record, log_time, log_time)
        else:
            summary.clock.add(record, log_time)
    elif isinstance(record, CommandRecord):
        _command(summary, record)


@dataclass
class _Part:
    """One robot's share of the pass: its frames pair by their own seq, its motions are its own."""

    summary: Summary
    tally: _Tally
    tracker: MotionTracker
    starts: dict[int, int] = field(default_factory=dict)  # unison: step index -> motion start (ns)

    @classmethod
    def named(cls, reader: LogReader, robot: str, whole: _Tally) -> _Part:
        layouts = LogLayouts.of(reader.run_info)
        run = {Info.PORT: reader.run_info.get(robot_key(robot, Info.PORT), "?"),
               Info.BAUD: reader.run_info.get(robot_key(robot, Info.BAUD), "?"),
               Info.LAYOUT: layouts.name(robot)}
        tracker = MotionTracker(layouts.layout(robot))
        return cls(Summary(reader.path, run, None, False, None), _Tally(whole.times), tracker)

    def see(self, record: TxRecord | RxRecord | StepRecord, log_time: int, whole: _Tally) -> None:
        tallies = (whole,) if self.tally is whole else (whole, self.tally)
        if isinstance(record, RxRecord):
            for tally in tallies:
                tally.reply(record, self.tally)
            self.tracker.rx(record, log_time)
        elif isinstance(record, TxRecord):
            for tally in tallies:
                tally.frame(record, self.summary, self.tally)
            self.tracker.tx(record, log_time)
        else:
            for tally in tallies:
                tally.step(record, log_time)
        if len(self.tracker.plays) > 256:
            self._plays()

    def finish(self) -> None:
        summary: Summary = self.summary  # this module's record, filled in by this pass
        if self.tally.pending_seq != -1:
            summary.unanswered += 1
        self.tracker.finish(None)
        self._plays()
        self.tally.fill(self.summary)

    def _plays(self) -> None:
        """Plays on the show clock: one ShowTimes for the whole log, every robot's tally shares it."""
        for play in self.tracker.plays:
            if play.start_ns is not None and play.step is not None:
                self.starts.setdefault(play.step, play.start_ns)
        _add_plays(self.summary, self.tracker.plays, self.tally.times)


def _gather(summary: Summary, parts: dict[str, _Part], unison: bool) -> None:
    """The whole show's figures from its robots': plays and motions, and for shared steps the
    skew of each unison play (first robot's motion start to the last's)."""
    summary.unanswered = sum(part.summary.unanswered for part in parts.values())
    for part in parts.values():
        summary.plays_total += part.summary.plays_total
        for stats in part.summary.motions.values():
            merged = summary.motions.setdefault(stats.motion, MotionStats(stats.motion))
            merged.plays += stats.plays
            merged.durations.extend(stats.durations[:10_000 - len(merged.durations)])
            for by, count in stats.unmeasured.items():
                merged.unmeasured[by] = merged.unmeasured.get(by, 0) + count
    if not unison:
        return
    steps = set().union(*(part.starts for part in parts.values()))
    for step in sorted(steps):
        starts = [part.starts[step] for part in parts.values() if step in part.starts]
        if len(starts) > 1:
            summary.skew.add((max(starts) - min(starts)) / 1e6)


class _Tally:
    """The counts of one pass: frames, replies, latencies, steps and their lateness."""

    def __init__(self, times: ShowTimes) -> None:
        self.times = times  # log times to show time (one for the whole log, shared by each robot's)
        self.frames = dict.fromkeys(FRAME_KINDS, 0)
        self.replies = dict.fromkeys(REPLY_KINDS, 0)
        self.latency = Distribution()
        self.lateness = Distribution()
        self.motion_starts = Distribution()
        self.late_at_start: dict[tuple[str | None, int], bool] = {}  # (robot, step) started and not ended
        self.retried: set[tuple[str | None, int]] = set()  # open (robot, step)s with a frame sent again
        self.outcomes = {"ok": 0, "failed": 0, "timeout": 0, "aborted": 0, "skipped": 0}
        self.retries = self.late = self.late_by_retries = self.started = self.stale = 0
        self.pending_seq = -1  # the frame waiting for its reply

    def reply(self, rx: RxRecord, own: _Tally | None = None) -> None:
        """`own`: the tally of the robot the reply is from (its frames have their own seq)."""
        own = own or self
        self.replies[rx.kind] = self.replies.get(rx.kind, 0) + 1
        if rx.seq == own.pending_seq and own is self:
            self.pending_seq = -1
        if rx.stale:
            self.stale += len(stale_replies(rx.stale))
        if rx.kind in ("ack", "nak", "status"):
            self.latency.add(rx.latency_ms)

    def frame(self, tx: TxRecord, summary: Summary, own: _Tally | None = None) -> None:
        """`own`: the tally of the robot the frame is to, which pairs it with its reply."""
        self.frames[tx.kind] = self.frames.get(tx.kind, 0) + 1
        if own is None or own is self:
            if self.pending_seq != -1:
                summary.unanswered += 1
            self.pending_seq = tx.seq
        if tx.attempt > 1:
            self.retries += 1
            if tx.step is not None:
                self.retried.add((tx.robot, tx.step))

    def step(self, step: StepRecord, log_time: int) -> None:
        key = (step.robot, step.index)
        if step.event == "start":
            self.started += 1
            self.late_at_start[key] = is_late(step)
            if step.kind == "play":  # a wait starts when the play before it is answered
                self.lateness.add(step.late_ms)
                self.late += is_late(step)
            self.times.see_start(log_time, step.actual_s)
            return
        if step.kind == "play" and step.cue is not None and step.start_s is not None:
            self.motion_starts.add((step.start_s - placed_cue(step, self.times)) * 1e3)
        late_at_start = self.late_at_start.pop(key, False)
        self.outcomes[step.outcome or "?"] = self.outcomes.get(step.outcome or "?", 0) + 1
        if key in self.retried:
            self.retried.discard(key)
            if slipped(step, late_at_start):
                self.late += 1
                self.late_by_retries += 1

    def log_line(self, line: LogRecord, log_time: int, summary: Summary) -> None:
        if line.level < WARNING:
            return
        if line.level >= ERROR:
            summary.errors += 1
        else:
            summary.warnings += 1
        if len(summary.log_lines) < LISTED_LOG_LINES:
            summary.log_lines.append(LogLine(self.times.seconds(log_time) or 0.0, line.level, str(line.message)))

    def fill(self, summary: Summary) -> None:
        summary.frames = self.frames
        summary.replies = self.replies
        summary.retries = self.retries
        summary.stale = self.stale
        summary.latency = self.latency
        summary.lateness = self.lateness
        summary.motion_starts = self.motion_starts
        summary.steps_run = self.started
        summary.steps_late = self.late
        summary.steps_late_by_retries = self.late_by_retries
        summary.steps_done = self.outcomes.get("ok", 0)
        summary.steps_failed = self.outcomes.get("failed", 0) + self.outcomes.get("timeout", 0)
        summary.steps_aborted = self.outcomes.get("aborted", 0)
        summary.steps_skipped = self.outcomes.get("skipped", 0)
        summary.steps_unfinished = len(self.late_at_start)


def placed_cue(step: StepRecord, times: ShowTimes) -> float:
    """A cued play's cue time: as written, or on a Link session where the runner placed it (a cue
    in bars moves with the session's tempo): its due time and lead, from its end record."""
    if times.link is not None and step.lead_ms is not None and step.cue is not None:
        return step.planned_s + step.lead_ms / 1e3
    return float(step.cue) if step.cue is not None else step.planned_s


def _add_plays(summary: Summary, plays: list[MotionPlay], times: ShowTimes) -> None:
    """Move the tracker's plays into the summary's per-slot statistics (and the listed first
    few); a play that never started is no play of its motion."""
    for done in plays:
        if done.start_ns is None or done.motion is None:
            continue
        duration = (done.end_ns - done.start_ns) / 1e9 if done.measured and done.end_ns is not None else None
        play = Play(done.motion, done.step, done.label, times.seconds(done.start_ns) or 0.0, duration, done.ended_by)
        summary.plays_total += 1
        if len(summary.plays) < LISTED_PLAYS:
            summary.plays.append(play)
        summary.motions.setdefault(done.motion, MotionStats(done.motion)).add(play)
    plays.clear()


def _command(summary: Summary, record: CommandRecord) -> None:
    """Counted from every record: a summary record (`unlogged`) by the counts it carries."""
    count = record.commands
    summary.commands_total += count
    summary.commands_refused += record.refused
    summary.command_records += 1
    if record.count is None:
        by = {record.command: 1}
    else:
        summary.commands_unlogged += count
        by = record.counts if record.counts is not None else {record.command: count}  # counts are optional
        if not isinstance(by, dict) or not all(type(n) is int and n > 0 for n in by.values()) \
                or sum(by.values()) != count:
            raise ValueError(f"unlogged: counts {record.counts!r} do not add up to count {count}")
    for name, n in by.items():
        summary.commands_by[name] = summary.commands_by.get(name, 0) + n
    if len(summary.commands) < LISTED_COMMANDS:
        summary.commands.append(record)


def _int(result: dict[str, str] | None, key: str) -> int | None:
    return whole_number((result or {}).get(key, ""))
