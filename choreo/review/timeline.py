"""`choreo log timeline`: each motion on the show clock, planned against actual.

Planned: where the compiled plan put the play step (`estimated_s`) and how long the show says
the motion takes. Actual: from the restore frame that started it (once ACKed) to the first status
query that found the board no longer executing, or to the stop frame of the next play, or to
the end of the log. Late cues (a step starting more than 1 ms after it was due) and faults (any
reply other than ACK or status; error lines) are marked where they happened, and so are the
times the show clock stood still (held at a GO cue, paused), the operator's commands (GO, pause,
skip, panic...) and the skipped cues.

On an Ableton Link session a cue in bars and beats is planned where the session put that beat
(`showtime.LinkTimes`, by the clock samples: a peer's tempo change moves it), a step after it
keeps its place after the cue, and the session's changes (tempo, peers, transport, jumps) are
marks of their own. A host's log (`choreo run --host`) holds only its own robots: the attached
show's other robots are another host's, said once, never drawn as plays not played.

The figures are show times (`showtime`, the one definition every review shares). The bars are
drawn on `elapsed` time: the show clock with its holds and pauses put back in, so a motion that
ran through a hold is as long as it really was, and a hold is a span of its own (shaded, labelled
with the show time it stood at). With no hold or pause, the two are the same.

Text by default; `--png` draws the same with matplotlib (the optional extra `choreo[plot]`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, BinaryIO

from choreo.errors import ChoreoError
from choreo.review.attached import AttachedShow, attached_show
from choreo.review.showtime import (Durations, fixed, LinkTimes, ShowTimes, StandNote, StandNotes, durations,
                                    see_for_stands)
from choreo.log.format import (ABORT_LABEL, CLOCK_TOPIC, COMMAND_TOPIC, ERROR, LATE_MS, LOG_TOPIC, RX_TOPIC,
                               STEP_TOPIC, TX_TOPIC, ClockRecord, CommandRecord, LogLayouts, LogRecord, MotionPlay,
                               MotionTracker, Info, Record, Result, RxRecord, StepRecord, TxRecord, cue_name, is_late,
                               parse, slipped)
from choreo.log.reader import Cut, LogReader
from choreo.show.model import beat_text
from choreo.textfit import fit, visible

if TYPE_CHECKING:  # for the types only, as `attached` does
    from choreo.show.model import Plan


class PlotUnavailable(ChoreoError):
    """`--png` without matplotlib installed."""

    exit_code = 2


@dataclass(frozen=True)
class MotionRun:
    """One play of a motion: planned and actual spans on the show clock (seconds)."""

    motion: int
    name: str | None
    step: int | None
    label: str | None
    planned_s: float | None  # the compiled plan's start for the play step
    expected_s: float  # how long the show says it takes
    due_s: float | None  # when the step was due at run time
    start_s: float | None  # the restore frame that started it (None: the play never started)
    end_s: float | None
    ended_by: str  # status | stop | state read | end of log | not started
    late_ms: float = 0.0
    robot: str | None = None  # whose play, in a show for several robots
    # where it is drawn: on `elapsed` time (the show clock with its holds and pauses put back in)
    planned_at: float | None = None
    start_at: float | None = None
    end_at: float | None = None

    @property
    def planned_end_s(self) -> float | None:
        return None if self.planned_s is None else self.planned_s + self.expected_s

    @property
    def planned_end_at(self) -> float | None:
        return None if self.planned_at is None else self.planned_at + self.expected_s

    @property
    def drawn_end_at(self) -> float | None:
        """`drawn_end_s` on the drawing's axis: a motion is drawn as long as it ran."""
        if self.start_at is None or self.end_at is None or self.measured:
            return self.end_at
        return min(self.end_at, self.start_at + self.expected_s)

    @property
    def measured(self) -> bool:
        """A status query saw it end: `end_s` is its end (to within the 50 ms poll)."""
        return self.ended_by == "status"

    @property
    def drawn_end_s(self) -> float | None:
        """Where its actual bar ends: the measured end, else its expected length at most (what
        ended it - the next play's stop frame, the log's end - is only an upper bound)."""
        if self.start_s is None or self.end_s is None or self.measured:
            return self.end_s
        return min(self.end_s, self.start_s + self.expected_s)

    @property
    def started_late(self) -> bool:
        """It started: late at its step's start, or by retries (the summary's rule, kept in late_ms)."""
        return self.late_ms > LATE_MS and self.start_s is not None

    @property
    def actual_s(self) -> float | None:
        """How long it ran: from its start's log time to its end's (on `elapsed`), as the
        summary measures it; not by show times, which stand still through a hold or pause."""
        if self.start_at is None or self.end_at is None:
            return None
        return self.end_at - self.start_at

    def title(self) -> str:
        named = f" {self.name}" if self.name else ""
        return f"motion {self.motion}{named}"


@dataclass(frozen=True)
class Mark:
    """A moment worth a reviewer's eye: a late play, a fault on the wire, a failed or aborted step,
    an error line, a hold or pause, an operator's command, a skipped cue."""

    show_s: float
    kind: str  # late | fault | failure | abort | error | held | paused | command | skip | session
    text: str
    at: float | None = None  # where it is drawn (`elapsed`); None: at its show time
    length_s: float = 0.0  # a hold's or pause's length

    @property
    def drawn_at(self) -> float:
        return self.show_s if self.at is None else self.at


FAULT_KINDS = ("fault", "error", "failure", "abort")
LISTED_MARKS = 200  # of each kind of mark, listed one a line (text) or labelled (PNG)
LISTED_CUES = 100
STAND_KINDS = ("held", "paused")
COMMAND_KINDS = ("command", "skip")
SESSION = "session"  # a change of the Link session: tempo, peers, transport, a jump
# each change's cell on the timeline's link row, by how its text begins (`showtime.SessionChange`)
SESSION_CELLS = {"tempo": "t", "peers": "p", "transport stopped": "|", "transport playing": ">", "beat timeline": "j"}


@dataclass(frozen=True)
class Cue:
    """A step with an `at:` time: where the show said something must happen."""

    show_s: float
    step: int
    label: str | None
    at: float | None = None  # where it is drawn (`elapsed`): where its step started
    number: str | None = None  # its number in the cue list

    @property
    def name(self) -> str:
        """`cue 1 'applause'`, as the cue list names it (an older log's: its label or step)."""
        return cue_name(self.number, self.label) if self.number else self.label or f"step {self.step}"

    @property
    def drawn_at(self) -> float:
        return self.show_s if self.at is None else self.at


@dataclass
class Timeline:
    show: str
    runs: list[MotionRun] = field(default_factory=list)
    marks: list[Mark] = field(default_factory=list)
    cues: list[Cue] = field(default_factory=list)
    unplayed: list[MotionRun] = field(default_factory=list)  # the plan's plays the run never reached
    end_s: float = 0.0
    outcome: str | None = None
    cut: Cut | None = None
    show_problem: str | None = None
    lengths: Durations | None = None  # the show's duration, holds, pauses, wall time (`showtime`)
    end_at: float = 0.0  # the end on the drawing's axis (`elapsed`)
    link: LinkTimes | None = None  # the Link session, on the Link clock
    host: str | None = None  # the show's host this run drove (`choreo run --host`)
    elsewhere: list[str] = field(default_factory=list)  # the attached show's robots other hosts drove

    @property
    def late(self) -> list[Mark]:
        return [m for m in self.marks if m.kind == "late"]

    @property
    def faults(self) -> list[Mark]:
        return [m for m in self.marks if m.kind in FAULT_KINDS]

    @property
    def stands(self) -> list[Mark]:
        """The holds and pauses."""
        return [m for m in self.marks if m.kind in STAND_KINDS]

    @property
    def commands(self) -> list[Mark]:
        """The operator's commands and the cues skipped."""
        return [m for m in self.marks if m.kind in COMMAND_KINDS]

    @property
    def session(self) -> list[Mark]:
        """The Link session's changes."""
        return [m for m in self.marks if m.kind == SESSION]

    @property
    def span_s(self) -> float:
        """How far the drawing's axis runs."""
        planned = (r.planned_end_at or 0.0 for r in self.runs + self.unplayed)
        stands = (m.drawn_at + m.length_s for m in self.marks)
        return max(self.end_at, self.end_s, max(planned, default=0.0), max(stands, default=0.0),
                   max((c.drawn_at for c in self.cues), default=0.0), 0.001)


def _tracker(trackers: dict[str | None, MotionTracker], layouts: LogLayouts, robot: str | None) -> MotionTracker:
    """The robot's motion tracker, made with the layout the log records for it."""
    tracker = trackers.get(robot)
    if tracker is None:
        tracker = trackers[robot] = MotionTracker(layouts.layout(robot))
    return tracker


@dataclass
class _Step:
    """A play step as its events tell it: when it was due, and how late its motion began."""

    start: StepRecord
    late_ms: float = 0.0
    placed: float | None = None  # a cued play's cue as the runner placed it (its end record: due + lead)


def build(reader: LogReader, show: AttachedShow | None = None) -> Timeline:
    """One pass over the log: the motion runs (from the same tracker as `log summary`), the
    marks (late plays by the same rule), the cues, and the plan's plays the run never reached."""
    show = show or attached_show(reader)
    timeline = Timeline(reader.info.show or reader.path.stem, show_problem=show.problem)
    seen = _Pass(timeline, ShowTimes.of(reader), LogLayouts.of(reader.run_info))
    topic, number = None, 0
    try:
        for topic, log_time, data in reader.messages((STEP_TOPIC, TX_TOPIC, RX_TOPIC, LOG_TOPIC, CLOCK_TOPIC,
                                                      COMMAND_TOPIC)):
            number += 1
            seen.see(parse(topic, data), log_time)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise reader.not_choreo(topic, number, exc) from None
    seen.finish(reader, show)
    return timeline


@dataclass
class _Pass:
    """What one pass over a log has seen so far, and how each record adds to the timeline."""

    timeline: Timeline
    clock: ShowTimes
    layouts: LogLayouts  # a lost start reply is judged by the robot's layout
    trackers: dict[str | None, MotionTracker] = field(default_factory=dict)  # by robot: motions are each one's own
    steps: dict[tuple[str | None, int], _Step] = field(default_factory=dict)
    last_ns: int | None = None
    notes: StandNotes | None = None  # each hold's cue and each stand's release, as the pass sees them

    def __post_init__(self) -> None:
        self.notes = StandNotes(self.clock)

    def see(self, record: Record, log_time: int) -> None:
        self.last_ns = log_time if self.last_ns is None else max(self.last_ns, log_time)  # as the summary's
        if isinstance(record, ClockRecord):
            self.clock.see_clock(log_time, record)
            return
        assert self.notes is not None  # made with the pass
        see_for_stands(self.notes, record, log_time)
        marks = self.timeline.marks
        if isinstance(record, TxRecord):  # most of a log: a frame's place is worked out only for a mark
            _tracker(self.trackers, self.layouts, record.robot).tx(record, log_time)
            if record.label == ABORT_LABEL and not any(m.kind == "abort" for m in marks):
                what = f"abort motion {record.motion} played" if record.motion is not None else "stop frames sent"
                marks.append(Mark(*self._at(log_time, "abort", f"show stopped: {what}")))
        elif isinstance(record, RxRecord):
            _tracker(self.trackers, self.layouts, record.robot).rx(record, log_time)
            if not record.answered:
                marks.append(_fault(record, *self._when(log_time)))
        elif isinstance(record, StepRecord):
            if record.event == "start":
                self.clock.see_start(log_time, record.actual_s)
            _see_step(self.timeline, self.steps, record, *self._when(log_time))
        elif isinstance(record, LogRecord) and record.level >= ERROR:
            marks.append(Mark(*self._at(log_time, "error", str(record.message))))
        elif isinstance(record, CommandRecord) and record.count is None:
            marks.append(Mark(*self._at(log_time, "command", command_text(record))))

    def _when(self, log_time: int) -> tuple[float, float | None]:
        """Show time and where it is drawn (`elapsed`), the show time worked out once."""
        now = self.clock.seconds(log_time) or 0.0
        return now, now + self.clock.stood_s(log_time) + self.clock.rewound_s(log_time)

    def _at(self, log_time: int, kind: str, text: str) -> tuple[float, str, str, float | None]:
        """A mark's fields (show time, kind, text, where drawn) at `log_time`."""
        now, at = self._when(log_time)
        return now, kind, text, at

    def finish(self, reader: LogReader, show: AttachedShow) -> None:
        """The runs in robot then time order, the marks in time order, what was never played."""
        timeline: Timeline = self.timeline  # this module's record, filled in by this pass
        clock = self.clock
        lengths = timeline.lengths = durations(clock, reader.result, self.last_ns)
        timeline.end_s = lengths.show_s or 0.0
        timeline.end_at = clock.elapsed(self.last_ns) or 0.0 if self.last_ns is not None else 0.0
        notes = self.notes.notes if self.notes is not None else [StandNote(stand) for stand in clock.stands]
        timeline.marks.extend(_stand_mark(note, clock, self.last_ns) for note in notes)
        placed = _Placed.of(show, clock.link)
        timeline.link = clock.link
        timeline.marks.extend(_session_marks(clock, self.last_ns))
        order: dict[str | None, int] = {name: i for i, name in enumerate(reader.robots)}
        for robot, tracker in self.trackers.items():
            for play in tracker.finish(self.last_ns):
                known = self.steps.get((robot, play.step)) if play.step is not None else None
                timeline.runs.append(_run_of(play, known, show, clock, robot, placed.planned(robot, play.step, known)))
        stood_end = self.last_ns
        timeline.runs.sort(key=lambda r: (order.get(r.robot, len(order)),  # as drawn: --loop's passes in turn
                                          r.start_at if r.start_at is not None else
                                          r.start_s if r.start_s is not None else r.due_s or 0.0))
        timeline.marks.sort(key=lambda m: m.show_s)
        robots = _hosted(timeline, show, reader)
        unplayed = [placed.unplayed(run) for robot in robots for run in _unplayed(show, self.steps, robot)]
        timeline.unplayed = [replace(run, planned_at=clock.elapsed_of_show(run.planned_s or 0.0, stood_end))
                             for run in unplayed]
        timeline.cues = [placed.cue(cue) for cue in timeline.cues]
        timeline.cut = reader.cut
        timeline.outcome = (reader.result or {}).get(Result.OUTCOME)
        if timeline.outcome in ("aborted", "interrupted") and not any(m.kind == "abort" for m in timeline.marks):
            timeline.marks.append(Mark(timeline.end_s, "abort", f"show {timeline.outcome}", timeline.end_at))


@dataclass
class _Placed:
    """On the Link clock, the plan where the session put it: a cue in bars at its beat on the
    session's timeline (`LinkTimes.show_of_bar`), a cue in seconds at its time, a step between
    cues as far after the cue before it as the plan has it. Off Link: empty, the plan's own."""

    link: bool = False
    steps: dict[tuple[str | None, int], float] = field(default_factory=dict)
    cues: dict[str, float] = field(default_factory=dict)  # cue number -> show s

    @classmethod
    def of(cls, show: AttachedShow, link: LinkTimes | None) -> _Placed:
        if link is None:
            return cls()
        meter = show_meter(show)
        steps: dict[tuple[str | None, int], float] = {}
        cues: dict[str, float] = {}
        plans: dict[str | None, Plan] = {None: show.plan} if show.plan is not None else {}
        if show.plans:
            plans = {robot: plan for robot, plan in show.plans.items()}
        for robot, plan in plans.items():
            shift = 0.0
            for step in plan.steps:
                cue = link.show_of_bar(*step.at_beat, meter) if step.at_beat and not step.go else None
                cue = None if step.go else step.at if cue is None else cue  # no beat sampled: as written
                if cue is not None:
                    shift = cue - step.planned_s
                    if step.cue is not None:
                        cues[step.cue] = cue
                steps[(robot, step.index)] = cue if cue is not None else step.planned_s + shift
        return cls(True, steps, cues)

    def planned(self, robot: str | None, index: int | None, known: _Step | None) -> float | None:
        """A play's planned time on Link: its cue as the runner placed it (each --loop pass its
        own), else by the plan as placed; None: off Link, or nothing known."""
        if not self.link:
            return None
        if known is not None and known.placed is not None:
            return known.placed
        return self.steps.get((robot, index)) if index is not None else None

    def unplayed(self, run: MotionRun) -> MotionRun:
        placed = self.steps.get((run.robot, run.step)) if run.step is not None else None
        return run if placed is None else replace(run, planned_s=placed)

    def cue(self, cue: Cue) -> Cue:
        placed = self.cues.get(cue.number) if cue.number is not None else None
        return cue if placed is None else replace(cue, show_s=placed)


def link_cue_fields(show: AttachedShow, times: ShowTimes) -> dict[str, dict]:
    """On a Link session (`times.link`), each timed cue's fields as `log export --cues` gives
    them, by cue number: its planned time where the session put it (`_Placed`), and for a cue in
    seconds the bar and beat the session was at then (one in bars keeps its bar as written);
    off Link, none: the cue times and bars of the plan stand."""
    link = times.link
    if link is None:
        return {}
    meter = show_meter(show)
    fields: dict[str, dict] = {}
    written = {step.cue for plan in [*show.plans.values(), show.plan] if plan is not None
               for step in plan.steps if step.cue is not None and step.at_beat is not None}
    for number, at in _Placed.of(show, link).cues.items():
        fields[number] = {"planned_s": round(at, 3)}
        beat = None if number in written else link.beat_of_show(at)
        if beat is not None:
            bar, within = divmod(round(beat, 3), meter)
            fields[number]["bar_beat"] = f"{int(bar) + 1}.{beat_text(round(within + 1, 3))}"
    return fields


def show_meter(show: AttachedShow) -> int:
    """The beats a bar the show's cues in bars count by on Link (its quantum)."""
    attached = show.show
    if attached is not None and attached.link is not None:
        return attached.link.meter
    return attached.tempo.meter if attached is not None and attached.tempo is not None else 4


def _hosted(timeline: Timeline, show: AttachedShow, reader: LogReader) -> list[str | None]:
    """The attached show's robots this log's run drove (its metadata's `robots`): a host's run
    (`--host`) drives its own, and the show's others are other hosts' (`Timeline.elsewhere`)."""
    if not show.plans:
        return [None]
    ran = set(reader.robots)
    timeline.host = reader.run_info.get(Info.SHOW_HOST) or None
    if not ran:
        return list(show.plans)
    timeline.elsewhere = [robot for robot in show.plans if robot not in ran]
    return [robot for robot in show.plans if robot in ran]


def _session_marks(clock: ShowTimes, end_ns: int | None) -> list[Mark]:
    """The Link session's changes (tempo, peers, transport, jumps) where the samples mark them."""
    link = clock.link
    if link is None:
        return []
    return [Mark(change.show_s, SESSION, change.text, clock.elapsed_of_show(change.show_s, end_ns))
            for change in link.changes]


def command_text(record: CommandRecord) -> str:
    """`go cue 1 'applause' from key: GO: cue 1 'applause'` (REFUSED when it was not carried out)."""
    what = record.what
    verdict = "" if record.status == "ok" else f" {str(record.status).upper()}"
    return f"{what} from {record.source}{verdict}: {record.message}"


def _stand_mark(note: StandNote, clock: ShowTimes, last_ns: int | None) -> Mark:
    stand = note.stand
    return Mark(stand.show_s, stand.kind, note.text(last_ns), clock.elapsed(stand.start_ns), stand.seconds(last_ns))


def _see_step(timeline: Timeline, steps: dict[tuple[str | None, int], _Step], step: StepRecord,
              now: float, at: float | None = None) -> None:
    whose = f"{step.robot}: " if step.robot else ""
    if step.event == "skip":
        what = f"{cue_name(step.cue_number, step.label)} skipped (step {step.index})" if step.cue_number \
            else f"{step.ref} skipped"
        timeline.marks.append(Mark(now, "skip", whose + what, at))
        return
    if step.event == "start":
        cue_s = step.cue if step.cue is not None else step.actual_s if step.go else None
        if cue_s is not None and not any(c.show_s == cue_s and c.step == step.index for c in timeline.cues):
            timeline.cues.append(Cue(cue_s, step.index, step.label, at, step.cue_number))
        if step.kind == "play":
            steps[(step.robot, step.index)] = _Step(step, step.late_ms if is_late(step) else 0.0)
            if is_late(step):
                timeline.marks.append(Mark(now, "late", f"{whose}{step.ref} started {fixed(step.late_ms, 1)} ms late "
                                                        f"(due {fixed(step.planned_s)} s)", at))
        return
    known: _Step | None = steps.get((step.robot, step.index))
    if known is not None and step.cue is not None and step.lead_ms is not None:
        known.placed = step.planned_s + step.lead_ms / 1e3  # due is the cue less the lead
    if known is not None and slipped(step, late_at_start=known.late_ms > 0):
        known.late_ms = step.late_ms
        timeline.marks.append(Mark(now, "late", f"{whose}{step.ref}: motion {step.motion} started "
                                                f"{fixed(step.late_ms, 1)} ms late (retries)", at))
    if step.outcome in ("failed", "timeout"):
        timeline.marks.append(Mark(now, "failure", f"{whose}{step.ref} {step.outcome}", at))
    elif step.outcome == "aborted":
        timeline.marks.append(Mark(now, "abort", f"{whose}{step.ref} aborted: the show was stopped", at))


def _fault(rx: RxRecord, now: float, at: float | None) -> Mark:
    what = rx.error or rx.kind
    whose = f"{rx.robot}: " if rx.robot else ""
    return Mark(now, "fault", f"{whose}{rx.kind.upper()} to frame #{rx.seq}: {what}", at)


def _run_of(play: MotionPlay, step: _Step | None, show: AttachedShow, clock: ShowTimes,
            robot: str | None = None, placed: float | None = None) -> MotionRun:
    """`placed`: its planned time where the Link session put it (None: the plan's)."""
    start = step.start if step is not None else None
    motion = play.motion if play.motion is not None else -1
    end_s = clock.seconds(play.end_ns) if play.start_ns is not None else None
    end_at = clock.elapsed(play.end_ns) if play.start_ns is not None else None
    planned = placed if placed is not None else start.estimated_s if start else None
    return MotionRun(motion, show.name_of(play.motion), play.step, play.label,
                     planned, show.expected_s(motion),
                     start.planned_s if start else None, clock.seconds(play.start_ns),
                     end_s, play.ended_by, step.late_ms if step else 0.0, robot,
                     _planned_at(planned, clock.seconds(play.start_ns), clock.elapsed(play.start_ns), clock),
                     clock.elapsed(play.start_ns), end_at)


def _planned_at(planned_s: float | None, start_s: float | None, start_at: float | None,
                clock: ShowTimes) -> float | None:
    """Where a play's planned bar is drawn: as far before (or after) its actual start as the plan
    put it on the show clock; a play that never started, where its show time falls."""
    if planned_s is None:
        return None
    if start_s is None or start_at is None:
        return clock.elapsed_of_show(planned_s)
    return start_at + planned_s - start_s


def _unplayed(show: AttachedShow, steps: dict[tuple[str | None, int], _Step], robot: str | None) -> list[MotionRun]:
    """The attached plan's plays after the last one the run started: what a stopped, failed or
    cut run never got to (drawn in grey), for one robot."""
    plan = show.plan_of(robot)
    if plan is None:
        return []
    last = max((index for whose, index in steps if whose == robot), default=-1)
    return [MotionRun(step.motion, show.name_of(step.motion), step.index, step.label, step.planned_s,
                      show.expected_s(step.motion), None, None, None, "not played", robot=robot)
            for step in plan.steps if step.index > last and step.kind.value == "play" and step.motion is not None
            and (robot is None or step.is_for(robot))]


# -- text --------------------------------------------------------------------------------------

MIN_BAR = 20  # the bar never gets narrower than this, however narrow the terminal
PREFIX = 5 + 1 + 16 + 1 + 11 + 1 + 11 + 2  # step, motion, planned, actual, the gaps: 48 columns
NARROW_PREFIX = 5 + 1 + 10 + 2  # step and motion only


def _cells(start: float | None, end: float | None, scale: float, width: int) -> range:
    if start is None:
        return range(0)
    first = min(width - 1, max(0, int(start * scale)))
    last = min(width - 1, max(first, int((end if end is not None else start) * scale)))
    return range(first, last + 1)


def _bar(run: MotionRun, scale: float, width: int) -> str:
    """'-' planned only, '#' actual only, '=' both (the plan stays visible under the actual),
    '.' an unmeasured end, '!' a late start, ':' a planned play the run never reached."""
    bar = [" "] * width
    planned = set(_cells(run.planned_at, run.planned_end_at, scale, width))
    for i in planned:
        bar[i] = ":" if run.ended_by == "not played" else "-"
    for i in _cells(run.start_at, run.end_at, scale, width):
        bar[i] = "."
    for i in _cells(run.start_at, run.drawn_end_at, scale, width):
        bar[i] = "=" if i in planned else "#"
    if run.started_late:
        bar[_cells(run.start_at, run.start_at, scale, width)[0]] = "!"
    return "".join(bar)


def render_text(timeline: Timeline, columns: int = 80) -> Iterator[str]:
    """The timeline as text that fits `columns`: a row a motion, the cues above, then the marks.
    Narrower than the planned and actual figures and a 20-column bar, the figures go."""
    for line in _text_lines(timeline, columns):
        yield fit(line, columns)


def _text_lines(timeline: Timeline, columns: int) -> Iterator[str]:
    figures = columns >= PREFIX + MIN_BAR + 2
    width = columns - (PREFIX if figures else NARROW_PREFIX) - 2
    width = max(width, 8)
    span = timeline.span_s
    scale = width / span
    yield from _head(timeline, span, width)
    end = f"{fixed(span, 1)} s"
    ruler = f"0 s{'':{max(width - 3 - len(end), 1)}}{end}"[:width]
    yield _row("step", "motion", "planned", "actual", ruler, figures)
    yield from _mark_rows(timeline, scale, width, figures)
    lane = object()
    for run in sorted(timeline.runs + timeline.unplayed, key=_lane_order(timeline)):
        if run.robot is not None and run.robot != lane:
            lane = run.robot
            yield f"robot {lane}"
        planned = _span(run.planned_s, run.planned_end_s)
        if run.ended_by == "not played":
            actual = "not played"
        elif run.start_s is None:
            actual = "not started"
        else:
            ran = run.actual_s  # through a hold or pause the end's show time stands: its start plus how long it ran
            ran_to = run.start_s + ran if run.measured and ran is not None else None
            actual = _span(run.start_s, ran_to) if ran_to is not None else _span(run.start_s, None) + "?"
        step = str(run.step) if run.step is not None else "abort"
        yield _row(step, run.title(), planned, actual, _bar(run, scale, width), figures)
    if not timeline.runs:
        yield "  (no motion played)"
    ended = [_ENDED_BY[r.ended_by] for r in timeline.runs if r.ended_by in _ENDED_BY]
    if ended:
        yield "?: no status query timed its end (no `wait: done`, or the show stopped first): drawn"
        yield "   for its expected length, '.' up to what ended it:"
        yield f"   {', '.join(dict.fromkeys(sorted(ended)))}"
    yield from _listed(timeline)


# What ended a play no status query timed, in the legend of its '?' (MotionPlay.ended_by).
_ENDED_BY = {"stop": "the next play", "end of log": "the log's end",
             "state read": "the state read after a lost start reply (over by then)"}


def _head(timeline: Timeline, span: float, width: int) -> Iterator[str]:
    """The show's lengths, the scale, the legend."""
    outcome = f", {timeline.outcome}" if timeline.outcome else ""
    yield f"timeline of {timeline.show}: {fixed(timeline.end_s)} s on the show clock{outcome}"
    stood = stood_text(timeline.lengths)
    if stood:
        yield stood
    if timeline.link is not None:
        yield f"clock: {link_text(timeline.link)}"
    if timeline.host is not None or timeline.elsewhere:
        yield hosted_text(timeline.host, timeline.elsewhere)
    drawn = " (drawn with the holds and pauses in)" if timeline.stands else ""
    yield f"one column = {span / width * 1000:.0f} ms{drawn}"
    yield "bars: '-' planned, '#' actual, '=' both, '!' late, ':' not played, 'v' cue"
    if timeline.stands or timeline.commands:
        yield "marks: '~' held or paused, '^' command, 'x' command refused, 's' cue skipped"
    if timeline.session:
        yield "session: 't' tempo, 'p' peers, '|' transport stopped, '>' playing again, 'j' timeline jumped"
    if timeline.show_problem:
        yield f"(planned lengths: {timeline.show_problem}; 1 s each assumed)"


LISTED_TEMPOS = 5  # tempo changes (and transport stops, jumps) named in the clock's line


def link_text(link: LinkTimes) -> str:
    """`the Link session's: 120.00 bpm, 150.00 from 1.48 s; 2 other peers; 13 samples`, with
    the peers' joins and leaves, the transport's stops and the timeline's jumps."""
    tempos = link.tempos
    text = "the Link session's: " + (f"{fixed(tempos[0][1], 2)} bpm" if tempos else "no tempo sampled")
    text += "".join(f", {fixed(bpm, 2)} from {fixed(show_s, 2)} s" for show_s, bpm in tempos[1:LISTED_TEMPOS + 1])
    more = link.counts.get("tempo", 0) - min(max(len(tempos) - 1, 0), LISTED_TEMPOS)
    text += f", ... ({more} more tempo changes)" if more > 0 else ""
    if link.peers is not None:
        low, high = link.peers
        many = "no other peer" if high == 0 else f"{low if low == high else f'{low}..{high}'} other peer" + \
            ("s" if high > 1 else "")
        moved = ", ".join(f"{n} {word}" for n, word in ((link.joined, "joined"), (link.left, "left")) if n)
        text += f"; {many}" + (f" ({moved})" if moved else "")
    for kind, word in (("stopped", "transport stopped"), ("playing", "playing again"), ("jump", "timeline jumped")):
        count = link.counts.get(kind, 0)
        if count:
            times = [change.show_s for change in link.changes if change.kind == kind][:LISTED_TEMPOS]
            text += f"; {word} at " + ", ".join(f"{fixed(at, 2)} s" for at in times) + \
                (f" ({count} times)" if count > len(times) else "")
    return text


def hosted_text(host: str | None, elsewhere: list[str]) -> str:
    """`host left: the show's other robots (b) are other hosts'` (a `choreo run --host` log)."""
    who = f"host {host}" if host else "this run"
    if not elsewhere:
        return f"{who}: every robot of the show"
    return (f"{who}: the show's other robots ({', '.join(elsewhere)}) are "
            f"{'other hosts' if host else 'not in this run'}': not reviewed here")


def stood_text(lengths: Durations | None) -> str:
    """`held 4.600 s at 2 GO cues, paused 1.200 s; 9.851 s in all`, with --from's start and
    --loop's passes (`from 12.000 s, 3 passes: ran 30.500 s; ...`), or "": a show that ran
    from 0 once, never held nor paused."""
    if lengths is None:
        return ""
    ran = []
    if lengths.start_s >= 0.0005:
        ran.append(f"from {fixed(lengths.start_s)} s")
    if lengths.passes > 1:
        ran.append(f"{lengths.passes} passes")
    stood = []
    if lengths.holds:
        stood.append(f"held {fixed(lengths.held_s)} s at {counted(lengths.holds, 'GO cue')}")
    if lengths.pauses:
        pauses = f" ({lengths.pauses} pauses)" if lengths.pauses > 1 else ""
        stood.append(f"paused {fixed(lengths.paused_s)} s{pauses}")
    if not (ran or stood):
        return ""
    parts = [", ".join(ran) + (f": ran {fixed(lengths.ran_s)} s" if lengths.ran_s is not None else "")] if ran else []
    parts += [", ".join(stood)] if stood else []
    if lengths.wall_s is not None:
        parts.append(f"{fixed(lengths.wall_s)} s in all")
    return "; ".join(parts)


def _marks_row(timeline: Timeline, scale: float, width: int) -> str:
    """The holds and pauses as '~' spans, the commands as '^' (refused 'x'), skips as 's'."""
    row = [" "] * width
    for mark in timeline.stands:
        for i in _cells(mark.drawn_at, mark.drawn_at + mark.length_s, scale, width):
            row[i] = "~"
    for mark in timeline.commands:
        refused = mark.kind == "command" and (" ERROR:" in mark.text or " DENIED:" in mark.text)
        row[_cells(mark.drawn_at, mark.drawn_at, scale, width)[0]] = "s" if mark.kind == "skip" else \
            "x" if refused else "^"
    return "".join(row)


def _mark_rows(timeline: Timeline, scale: float, width: int, figures: bool) -> Iterator[str]:
    """The rows above the motions: the cues, the holds and commands, the Link session's changes."""
    if timeline.cues:
        row = [" "] * width
        for cue in timeline.cues:
            row[_cells(cue.drawn_at, cue.drawn_at, scale, width)[0]] = "v"
        yield _row("", "cues", "", "", "".join(row), figures)
    if timeline.stands or timeline.commands:
        yield _row("", "holds/cmds", "", "", _marks_row(timeline, scale, width), figures)
    if timeline.session:
        yield _row("", "link", "", "", _session_row(timeline, scale, width), figures)


def _session_row(timeline: Timeline, scale: float, width: int) -> str:
    """The Link session's changes, each a cell by its kind (`SESSION_CELLS`)."""
    row = [" "] * width
    for mark in timeline.session:
        cell = next((c for start, c in SESSION_CELLS.items() if mark.text.startswith(start)), "*")
        row[_cells(mark.drawn_at, mark.drawn_at, scale, width)[0]] = cell
    return "".join(row)


def _lane_order(timeline: Timeline) -> Callable[[MotionRun], tuple[int, int]]:
    """Runs lane by lane (robots in the order they first played), then as they were."""
    robots: dict[str | None, int] = {}
    for run in timeline.runs + timeline.unplayed:
        robots.setdefault(run.robot, len(robots))
    position = {id(run): i for i, run in enumerate(timeline.runs + timeline.unplayed)}
    return lambda run: (robots[run.robot], position[id(run)])


def _row(step: str, title: str, planned: str, actual: str, bar: str, figures: bool) -> str:
    if figures:
        return f"{step:>5} {title[:16]:<16} {planned:>11} {actual[:11]:>11}  |{bar}|"
    return f"{step:>5} {title.replace('motion ', '')[:10]:<10}  |{bar}|"


def _listed(timeline: Timeline) -> Iterator[str]:
    """The cues, then each kind of mark, the first LISTED_MARKS of each one a line (a log of
    thousands of holds or commands is still a page, not a flood)."""
    if timeline.cues:
        more = len(timeline.cues) - LISTED_CUES
        yield "cues: " + ", ".join(f"{c.name} at {round(c.show_s, 3):g} s" for c in timeline.cues[:LISTED_CUES]) \
            + (f", ... and {more} more" if more > 0 else "")
    for title, marks in (("late plays", timeline.late), ("faults", timeline.faults),
                         ("holds and pauses", timeline.stands), ("commands", timeline.commands),
                         ("Link session changes", timeline.session)):
        if marks or title in ("late plays", "faults"):
            yield f"{title}: {len(marks) or 'none'}"
        for mark in marks[:LISTED_MARKS]:
            yield f"  {fixed(mark.show_s, 3, 9)} s  {mark.text}"
        if len(marks) > LISTED_MARKS:
            yield f"  ... and {len(marks) - LISTED_MARKS} more"
    if timeline.unplayed:
        robots = sorted({run.robot for run in timeline.unplayed if run.robot})
        whose = f" (robot {', '.join(robots)})" if robots else ""
        yield (f"not played: {counted(len(timeline.unplayed), 'play')} of the plan{whose} that the run "
               f"{'never reached' if timeline.cut is None else 'had not reached where the log was cut'}")
    if timeline.cut is not None:
        yield f"log {timeline.cut.state}: {timeline.cut}"


def counted(n: int, word: str) -> str:
    """`1 late play`, `3 faults`."""
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def _span(start: float | None, end: float | None) -> str:
    """`1.500-3.500` in at most 11 characters: fewer decimals for later times."""
    if start is None:
        return "-"
    for decimals in (3, 2, 1, 0):
        text = f"{start:.{decimals}f}-" + (f"{end:.{decimals}f}" if end is not None else "")
        if len(text) <= 11:
            return text
    return text


# -- picture -----------------------------------------------------------------------------------


def require_matplotlib(needed_by: str = "timeline --png",
                       works_without: str = "the text timeline works without it") -> None:
    """PlotUnavailable (exit 2, how to get it) before any file is made or any log read."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot  # noqa: F401 - imported to fail here, before any file is made
    except ImportError:
        raise PlotUnavailable(f"{needed_by} needs matplotlib: pip install 'choreo[plot]' "
                              f"(or pip install matplotlib); {works_without}") from None


def render_png(timeline: Timeline, out: BinaryIO) -> None:
    """Draw the timeline as a PNG into `out`: a row a motion slot, planned bars above actual ones,
    the plan's unplayed plays in grey, cue lines with their labels, the marks, the holds and
    pauses shaded (on `elapsed` time, as the text) and the commands on a row of their own.

    Takes an open file, not a path: the command opens its output before it reads the log, so a
    path it cannot write is one line at once, never a long read and then a traceback.
    """
    require_matplotlib()
    import matplotlib.pyplot as plt

    everything = sorted(timeline.runs + timeline.unplayed, key=_lane_order(timeline))
    slots = list(dict.fromkeys((r.robot, r.motion) for r in everything))  # a row a robot's motion slot
    if not any(r.robot for r in everything):
        slots.sort(key=lambda slot: slot[1])
    names = {(r.robot, r.motion): (f"{r.robot}: " if r.robot else "") + r.title() for r in everything}
    height = max(2.5, 0.55 * (len(slots) + 1) + 1.8)
    with plt.rc_context({"text.parse_math": False, "text.usetex": False}):  # names from the log: `$` is a dollar
        fig, ax = plt.subplots(figsize=(11, height), dpi=100)
        try:
            _draw_png(ax, timeline, everything, slots, names)
            fig.tight_layout()
            fig.savefig(out, format="png")
        finally:
            plt.close(fig)


def _draw_png(ax: Any, timeline: Timeline, everything: list[MotionRun], slots: list, names: dict) -> None:
    """The figure's content (`render_png`): runs, marks, axes, title and legend."""
    row = {slot: i for i, slot in enumerate(slots)}
    for run in everything:
        _draw_run(ax, run, row[(run.robot, run.motion)])
    extra = _draw_marks(ax, timeline, len(slots))
    ax.set_yticks(list(range(len(slots) + len(extra))))
    ax.set_yticklabels([visible(names[m]) for m in slots] + extra)
    ax.set_ylim(-0.8, len(slots) - 1 + len(extra) + (0.8 if extra else 0.6))
    ax.invert_yaxis()
    ax.set_xlim(0, timeline.span_s * 1.02)
    ax.set_xlabel("show clock (s), with the holds and pauses in" if timeline.stands else "show clock (s)")
    ax.grid(axis="x", color="#dddddd", linewidth=0.6)
    ax.set_axisbelow(True)
    ax.set_title(visible(_png_title(timeline)))
    ax.legend(handles=_legend(), loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=5,
              frameon=False, fontsize="small")


def _draw_marks(ax: Any, timeline: Timeline, first_y: int) -> list[str]:  # ax: a matplotlib Axes
    """The faults' and the commands' rows below the motions (their names, for the y axis), the
    cues' lines, the holds' and pauses' shaded spans labelled with the show time they stood at."""
    rows: list[str] = []
    faults, commands = timeline.faults, timeline.commands
    for name, marks, styles in (("faults", faults, _MARK_STYLES), ("commands", commands, _COMMAND_STYLES),
                                ("Link session", timeline.session, _SESSION_STYLES)):
        if not marks:
            continue
        y = first_y + len(rows)
        rows.append(name)
        for kind, marker, colour in styles:
            at = [m.drawn_at for m in marks if m.kind == kind]
            if at:
                ax.plot(at, [y] * len(at), marker=marker, color=colour, markersize=9, markeredgewidth=2,
                        linestyle="")
    for mark in timeline.session[:LISTED_MARKS]:
        ax.annotate(visible(mark.text), (mark.drawn_at, first_y + rows.index("Link session") - 0.25),
                    fontsize="x-small", color="#9467bd")
    if timeline.cues:  # the lines in one artist, the first few labelled: a log of thousands draws at once
        ax.vlines([cue.drawn_at for cue in timeline.cues], 0, 1, transform=ax.get_xaxis_transform(),
                  colors="#555555", linestyles="--", linewidth=0.8)
    for cue in timeline.cues[:LISTED_CUES]:
        ax.annotate(visible(cue.name), (cue.drawn_at, 1.0), xycoords=("data", "axes fraction"), rotation=90,
                    va="top", ha="right", fontsize="x-small", color="#333333")
    if timeline.stands:
        ax.broken_barh([(stand.drawn_at, stand.length_s) for stand in timeline.stands], (0, 1),
                       transform=ax.get_xaxis_transform(), facecolors=STOOD, linewidth=0, zorder=0)
    for stand in timeline.stands[:LISTED_MARKS]:
        ax.annotate(f"{stand.kind} {fixed(stand.length_s, 1)} s at {fixed(stand.show_s)} s", (stand.drawn_at, 0.0),
                    xycoords=("data", "axes fraction"), va="bottom", ha="left", fontsize="x-small",
                    color="#555555")
    return rows


PLANNED, UNPLAYED, MEASURED, UNMEASURED, RED = "#b8c4d6", "#dddddd", "#2f6db5", "#8c6bb1", "#d62728"
STOOD = "#f0e0a0"  # a hold's or pause's span
_COMMAND_STYLES = (("command", "^", "#2ca02c"), ("skip", "s", "#7f7f7f"))
_SESSION_STYLES = ((SESSION, "D", "#9467bd"),)
_MARK_STYLES = (("fault", "x", RED), ("error", "x", "#8b0000"), ("failure", "X", "#8b0000"),
                ("abort", "s", "#ff7f0e"))


def _draw_run(ax: Any, run: MotionRun, y: int) -> None:  # ax: a matplotlib Axes, imported lazily
    if run.planned_at is not None:
        unplayed = run.ended_by == "not played"
        ax.broken_barh([(run.planned_at, run.expected_s)], (y - 0.42, 0.34),
                       facecolors=UNPLAYED if unplayed else PLANNED,
                       edgecolors="#aaaaaa" if unplayed else "#6b7a90", linewidth=0.5)
    if run.start_at is not None and run.end_at is not None and run.drawn_end_at is not None:
        colour = MEASURED if run.measured else UNMEASURED
        ax.broken_barh([(run.start_at, max(run.drawn_end_at - run.start_at, 0.005))], (y - 0.04, 0.44),
                       facecolors=colour)
        if not run.measured and run.end_at > run.drawn_end_at:
            ax.hlines(y + 0.18, run.drawn_end_at, run.end_at, colors=colour, linestyles="dotted", linewidth=1.5)
    if run.started_late:
        ax.plot([run.start_at], [y - 0.04], marker="v", color=RED, markersize=9, linestyle="")
        ax.annotate(f"{run.late_ms:.0f} ms late", (run.start_at, y - 0.1), fontsize="x-small", color=RED)


def _png_title(timeline: Timeline) -> str:
    stood = stood_text(timeline.lengths)
    title = f"{timeline.show}: {fixed(timeline.end_s, 2)} s" + (f" ({stood})" if stood else "")
    if timeline.outcome:
        title += f", {timeline.outcome}"
    if timeline.cut is not None:
        title += f" (log {timeline.cut.state})"
    return title + f"; {counted(len(timeline.late), 'late play')}, {counted(len(timeline.faults), 'fault')}"


def _legend() -> list:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    return [Patch(facecolor=PLANNED, edgecolor="#6b7a90", label="planned"),
            Patch(facecolor=UNPLAYED, edgecolor="#aaaaaa", label="not played"),
            Patch(facecolor=MEASURED, label="actual (to status: done)"),
            Patch(facecolor=UNMEASURED, label="actual (end not polled)"),
            Line2D([], [], color="#555555", linestyle="--", label="cue"),
            Line2D([], [], marker="v", color=RED, linestyle="", label="late play"),
            Line2D([], [], marker="x", color=RED, linestyle="", markeredgewidth=2, label="fault"),
            Line2D([], [], marker="X", color="#8b0000", linestyle="", label="failed step"),
            Line2D([], [], marker="s", color="#ff7f0e", linestyle="", label="aborted"),
            Patch(facecolor=STOOD, label="held / paused"),
            Line2D([], [], marker="^", color="#2ca02c", linestyle="", label="command"),
            Line2D([], [], marker="s", color="#7f7f7f", linestyle="", label="cue skipped"),
            Line2D([], [], marker="D", color="#9467bd", linestyle="", label="Link session change")]
