"""`choreo log summary`: did the show run as planned, where did the timing slip, what did the robot say.

One linear pass over the log (see `reader`), in memory that does not grow with the log: counts,
distributions kept as counters of microsecond-rounded values (reply latencies are bounded by the
reply timeout, cue lateness by the show), per-slot motion statistics, and only the first few
plays and log lines listed one by one. Records come typed from `choreo.log.format`, and plays
from its motion tracker, the one the timeline uses too.
"""

from __future__ import annotations

import math

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from choreo.numtext import whole_number
from choreo.log.format import (CHOREO_TOPICS, COMMAND_TOPIC, ERROR, LATE_MS, WARNING, ClockRecord, CommandRecord,
                               LogLayouts, LogRecord, MotionPlay, MotionTracker, Record, RxRecord, StepRecord, TxRecord,
                               is_late, parse, slipped)
from choreo.log.reader import Cut, LogReader
from choreo.review.showtime import ShowTimes
from choreo.wire.protocol import FrameKind, ReplyKind
# counted (and shown) even at 0: the frames every run sends, and every reply (the wire's names)
FRAME_KINDS = tuple(kind.value for kind in (FrameKind.STOP, FrameKind.PLAY, FrameKind.RESTORE, FrameKind.STATUS))
REPLY_KINDS = tuple(kind.value for kind in ReplyKind)
LISTED_PLAYS = 30  # plays listed one by one; past this, per motion slot only
LISTED_LOG_LINES = 10
LISTED_COMMANDS = 20


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

    def add(self, play: Play) -> None:
        self.plays += 1
        if play.duration_s is not None and len(self.durations) < 10_000:
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

    def add(self, sample: ClockRecord) -> None:
        self.samples += 1
        self.last = sample

    @property
    def span_s(self) -> float:
        return (self.last.monotonic_ns - self.first.monotonic_ns) / 1e9

    @property
    def drift_ms(self) -> float:
        """How far the show clock ran ahead of the machine's over the span (ms)."""
        return ((self.last.show_s - self.first.show_s) - self.span_s) * 1e3


@dataclass
class Summary:
    """Everything `choreo log summary` reports about one run log."""

    path: Path
    run: dict[str, str]
    result: dict[str, str] | None
    complete: bool
    cut: Cut | None
    messages: int = 0
    duration_s: float | None = None  # show clock at the last message (or the result's, if closed)
    steps_run: int = 0
    steps_done: int = 0
    steps_late: int = 0  # play steps late on stage, counted once each as the runner counts them:
    # started more than LATE_MS after their time, or (`logformat.slipped`) retries delayed the motion that long
    steps_late_by_retries: int = 0  # of those, the plays on time whose retries made them late
    steps_failed: int = 0
    steps_aborted: int = 0
    steps_unfinished: int = 0
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
        return self.run.get("show") or self.path.stem


_SHARED_FIELDS = ("log", "state", "cut", "show", "result")  # a robot's record in a summary leaves out the whole log's


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
        "result": summary.result,
        "duration_s": summary.duration_s,
        "steps": {"run": summary.steps_run, "done": summary.steps_done, "late": summary.steps_late,
                  "late_by_retries": summary.steps_late_by_retries, "failed": summary.steps_failed,
                  "aborted": summary.steps_aborted, "unfinished": summary.steps_unfinished},
        "frames": {**summary.frames, "retries": summary.retries},
        "replies": {**summary.replies, "stale": summary.stale, "unanswered": summary.unanswered},
        "latency": spread(summary.latency),
        "cue_lateness": spread(summary.lateness),
        "motion_start_vs_cue": spread(summary.motion_starts),
        "clock": None if summary.clock is None else {
            "source": summary.clock.source, "samples": summary.clock.samples, "span_s": round(summary.clock.span_s, 6),
            "drift_ms": round(summary.clock.drift_ms, 3),
            "show_zero_monotonic_ns": _int(summary.result, "show_zero_monotonic_ns"),
            "show_zero_wall_ns": _int(summary.result, "show_zero_wall_ns")},
        "motions": [{"motion": m.motion, "plays": m.plays, "measured": m.measured, "median_s": m.median_s}
                    for m in sorted(summary.motions.values(), key=lambda m: m.motion)],
        "commands": [command.to_json() for command in summary.commands],
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
    summary = Summary(reader.path, dict(reader.run_info), None, False, None)
    tally = _Tally(ShowTimes.of(reader))
    parts: dict[str, _Part] = {}  # a show for several robots: each robot's own tally and tracker
    solo = _Part(summary, tally, MotionTracker(LogLayouts.of(reader.run_info).layout(None)))
    topic, count, last_time = None, 0, None
    try:
        for topic, log_time, data in reader.messages():
            count += 1
            last_time = log_time
            if topic not in CHOREO_TOPICS:
                continue
            record = parse(topic, data)
            if isinstance(record, (TxRecord, RxRecord, StepRecord)):
                robot = record.robot
                part = solo if robot is None else parts.get(robot) or parts.setdefault(
                    robot, _Part.named(reader, robot, tally))
                part.see(record, log_time, tally)
            else:
                _see_shared(summary, tally, record, log_time)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise reader.not_choreo(topic, count, exc) from None
    summary.messages = count
    summary.cut = reader.cut
    summary.result = reader.result
    summary.complete = reader.complete
    for part in [solo, *parts.values()]:
        part.finish()
    tally.fill(summary)
    if parts:
        order = [name for name in reader.robots if name in parts]
        summary.robots = {name: parts[name].summary for name in order + [n for n in parts if n not in order]}
        _gather(summary, parts, reader.run_info.get("unison") == "yes")
    result_s = _seconds((reader.result or {}).get("show_s"))
    if result_s is not None:
        summary.duration_s = result_s
    elif last_time is not None:
        summary.duration_s = tally.times.seconds(last_time)
    return summary


def _see_shared(summary: Summary, tally: _Tally, record: Record, log_time: int) -> None:
    """A record of the whole show, not of one robot: a log line, a clock sample, a command."""
    if isinstance(record, LogRecord):
        tally.log_line(record, log_time, summary)
    elif isinstance(record, ClockRecord):
        _clock_sample(summary, record)
        tally.times.see_clock(log_time, record)
    elif isinstance(record, CommandRecord):
        _command(summary, record)


def _clock_sample(summary: Summary, sample: ClockRecord) -> None:
    if summary.clock is None:
        summary.clock = ClockSpan(sample.source, 1, sample, sample)
    else:
        summary.clock.add(sample)


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
        run = {"port": reader.run_info.get(f"robot.{robot}.port", "?"),
               "baud": reader.run_info.get(f"robot.{robot}.baud", "?"),
               "layout": layouts.name(robot)}
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
        self.outcomes = {"ok": 0, "failed": 0, "timeout": 0, "aborted": 0}
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
            self.motion_starts.add((step.start_s - step.cue) * 1e3)
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
        summary.steps_unfinished = len(self.late_at_start)


def _seconds(text: str | None) -> float | None:
    """A figure from the metadata, or None where it is missing or damaged (metadata records
    carry no CRC: a flipped byte shows only here)."""
    try:
        value = float(text) if text else None
    except ValueError:
        return None
    return value if value is not None and math.isfinite(value) else None


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


# -- text --------------------------------------------------------------------------------------


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f} ms"


def render(summary: Summary) -> Iterable[str]:
    """The summary as the lines `choreo log summary` prints."""
    yield from _render_run(summary)
    yield from _render_outcome(summary)
    yield from _render_wire(summary)
    yield from _render_clock(summary)
    yield from _render_motions(summary)
    yield from _render_robots(summary)
    yield from _render_commands(summary)
    yield from _render_log_lines(summary)
    yield f"messages  {summary.messages}"


def _state(summary: Summary) -> str:
    """Whether the log is whole, and if not, why."""
    if summary.complete:
        return "complete"
    if summary.cut is not None:
        return f"{summary.cut.state.upper()}: {summary.cut}"
    if summary.result is None:
        return "UNFINISHED: the run recorded no result (it did not close its log)"
    return "UNFINISHED: no MCAP footer"


def _render_run(summary: Summary) -> Iterable[str]:
    """Which log, which show, and the run that wrote it (where, when, with what)."""
    run = summary.run
    yield f"log       {summary.path}  ({_state(summary)})"
    sha = run.get("show_sha256", "")
    where = f" ({run['show_path']}" + (f", sha256 {sha[:12]}" if sha else "") + ")" if run.get("show_path") else ""
    yield f"show      {summary.show_name}{where}"
    if run and run.get("robots"):
        names = run["robots"].split(",")
        yield (f"run       started {run.get('start_time', '?')}, {len(names)} robots ({', '.join(names)}; "
               f"ports below) (choreo {run.get('version', '?')}, host {run.get('host', '?')})")
    elif run:
        yield (f"run       started {run.get('start_time', '?')} on {run.get('port', '?')} at "
               f"{run.get('baud', '?')} baud, layout {LogLayouts.of(run).describe(None)} "
               f"(choreo {run.get('version', '?')}, host {run.get('host', '?')})")
    else:
        yield "run       no `choreo` metadata: not a log written by choreo run"


def _render_outcome(summary: Summary) -> Iterable[str]:
    """How the run ended, and what its steps came to."""
    duration = f"{summary.duration_s:.3f} s" if summary.duration_s is not None else "-"
    if summary.result:
        outcome = summary.result.get("outcome", "?")
        error = summary.result.get("error")
        code = summary.result.get("exit_code")
        yield f"outcome   {outcome}" + (f" (exit {code})" if code else "") + f", {duration} on the show clock"
        if error:
            yield f"          {error}"
    else:
        yield f"outcome   unknown (no result recorded): {duration} on the show clock up to the last message"
    by_retries = f" ({summary.steps_late_by_retries} by retries)" if summary.steps_late_by_retries else ""
    steps = (f"steps     {summary.steps_run} run: {summary.steps_done} done, {summary.steps_late} late{by_retries}, "
             f"{summary.steps_failed} failed")
    if summary.steps_aborted:
        steps += f", {summary.steps_aborted} aborted"
    if summary.steps_unfinished:
        steps += f", {summary.steps_unfinished} unfinished"
    yield steps


def _render_wire(summary: Summary) -> Iterable[str]:
    """Frames and replies, and the timing figures: reply latency, cue lateness, motion starts."""
    kinds = ", ".join(f"{k} {n}" for k, n in summary.frames.items() if n or k in FRAME_KINDS)
    yield f"frames    {summary.frames_sent} sent ({kinds}); {summary.retries} retries"
    replies = ", ".join(f"{k.upper() if k in ('ack', 'nak') else k} {n}" for k, n in summary.replies.items())
    unanswered = f"; {summary.unanswered} unanswered (log cut)" if summary.unanswered else ""
    yield f"replies   {replies}; stale {summary.stale} (late replies to earlier frames, set aside){unanswered}"
    lat = summary.latency
    yield (f"latency   min {_ms(lat.min)}, median {_ms(lat.median)}, p99 {_ms(lat.p99)}, "
           f"max {_ms(lat.max)} ({len(lat)} replies)")
    lateness = summary.lateness
    yield (f"cues      lateness median {_ms(lateness.median)}, p99 {_ms(lateness.p99)}, max "
           f"{_ms(lateness.max)} ({len(lateness)} plays, {lateness.above(LATE_MS)} over {LATE_MS:g} ms)")
    starts = summary.motion_starts
    if len(starts):
        yield (f"starts    motion start vs cue (start frame written): median {_ms(starts.median)}, p99 "
               f"{_ms(starts.p99)}, max {_ms(starts.max)} ({len(starts)} cued plays, sent early by their lead)")


def _render_log_lines(summary: Summary) -> Iterable[str]:
    """The warnings and errors the run logged: counted, the first few listed."""
    yield f"log lines {summary.warnings} warnings, {summary.errors} errors"
    for line in summary.log_lines:
        word = "error  " if line.level >= ERROR else "warning"
        yield f"  {line.show_s:9.3f} s  {word} {line.message}"
    if summary.warnings + summary.errors > len(summary.log_lines):
        yield f"  ... and {summary.warnings + summary.errors - len(summary.log_lines)} more (choreo log frames)"


def _render_clock(summary: Summary) -> Iterable[str]:
    """Which clock kept the show, and how it ran against the machine's."""
    clock, result = summary.clock, summary.result or {}
    if clock is None:
        return
    if clock.source == "music":
        music = f"the music ({result.get('music.file', '?')} from {result.get('music.start', '0')} s"
        backend = result.get("audio.backend")
        kept = music + (f", on {backend})" if backend else ")")
    else:
        kept = "the machine's"
    drift = (f"; show clock minus machine clock {clock.drift_ms:+.3f} ms over {clock.span_s:.1f} s"
             if clock.samples > 1 else "")
    yield f"clock     {kept}: {clock.samples} samples{drift}"


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


def _render_commands(summary: Summary) -> Iterable[str]:
    """Who pressed what and when: every GO, panic, start and stop, refused ones included, and
    the counts of those the limits kept out of the log one by one."""
    if not summary.commands_total:
        return
    unlogged = ""
    if summary.commands_unlogged:
        by = ", ".join(f"{n} {name}" for name, n in sorted(summary.commands_by.items(), key=lambda kv: (-kv[1], kv[0])))
        unlogged = f"; {summary.commands_unlogged} of them not logged one by one, over the log's limit): {by}"
    yield f"commands  {summary.commands_total} from the operator ({summary.commands_refused} refused{unlogged or ')'}"
    for command in summary.commands:
        when = f"{command.show_s:9.3f} s" if command.show_s is not None else "   before  "
        what = command.command + (f" {command.label}" if command.label else "")
        verdict = "" if command.status == "ok" else f" {command.status.upper()}"
        yield f"  {when}  {what:<12} {command.source}{verdict}: {command.message}"
    if summary.command_records > len(summary.commands):
        more = summary.command_records - len(summary.commands)
        yield f"  ... and {more} more (all on the log's {COMMAND_TOPIC} topic: open the log in Foxglove)"


def _int(result: dict[str, str] | None, key: str) -> int | None:
    return whole_number((result or {}).get(key, ""))


def _render_robots(summary: Summary) -> Iterable[str]:
    """A show for several robots: a line or two per robot, and how together the unison plays began."""
    if not summary.robots:
        return
    if len(summary.skew):
        skew = summary.skew
        yield (f"unison    motion starts apart: median {_ms(skew.median)}, p99 {_ms(skew.p99)}, max "
               f"{_ms(skew.max)} ({len(skew)} plays by several robots; first robot's start to the last's)")
    layouts = LogLayouts.of(summary.run)
    for name, robot in summary.robots.items():
        run = robot.run
        late = f", {robot.steps_late} late" if robot.steps_late else ""
        failed = f", {robot.steps_failed} failed" if robot.steps_failed else ""
        aborted = f", {robot.steps_aborted} aborted" if robot.steps_aborted else ""
        yield (f"robot {name}: {run.get('port', '?')} at {run.get('baud', '?')} baud, "
               f"layout {layouts.describe(name)}; "
               f"{robot.steps_run} steps{late}{failed}{aborted}, {robot.frames_sent} frames, {robot.retries} retries, "
               f"{robot.plays_total} plays")
        lat, cues = robot.latency, robot.lateness
        yield (f"          latency median {_ms(lat.median)}, p99 {_ms(lat.p99)}; cue lateness median "
               f"{_ms(cues.median)}, max {_ms(cues.max)}")


def _render_motions(summary: Summary) -> Iterable[str]:
    if not summary.plays_total:
        yield "motions   none played"
        return
    yield f"motions   {summary.plays_total} played (measured: restore to the first status not executing)"
    for stats in sorted(summary.motions.values(), key=lambda s: s.motion):
        if stats.durations:
            spread = (f"median {stats.median_s:.3f} s (min {min(stats.durations):.3f}, "
                      f"max {max(stats.durations):.3f})")
        else:
            spread = "not measured (no status query saw it end)"
        yield f"  motion {stats.motion:3d}  x{stats.plays:<5d} {spread}"
    if summary.plays_total <= LISTED_PLAYS:
        for play in summary.plays:
            label = f" '{play.label}'" if play.label else ""
            where = f"step {play.step}{label}" if play.step is not None else "abort"
            took = (f"{play.duration_s:.3f} s" if play.duration_s is not None
                    else f"not measured (ended by {play.ended_by})")
            yield f"  {play.start_s:9.3f} s  motion {play.motion:3d}  {where}: {took}"
