"""`choreo log export`: one row a frame, with every field of the frame and of its reply.

For spreadsheets and pandas (`pandas.read_csv`, `pandas.read_json`): a flat table, times both as
wall-clock nanoseconds (exact, as logged) and show-clock seconds (what a reviewer reads), and the
meaning of each frame and reply in words. Written as it is read, so a long log never sits in memory.

`--cues`: one row a cue a robot (and --loop pass) instead: its number, label, planned and actual
show time (the step records' own, the times every review shows), lateness, and how it was
released (`time`, the GO's source such as `go key` or `go osc udp 127.0.0.1:53001`, `skipped`), or
why it did not run (`waiting (stopped)`: the run ended while it waited for its GO; `not reached`;
`not in this run`: before --from's step or outside --loop's section).
"""

from __future__ import annotations

import csv
import json
import math
import re
from bisect import bisect_left
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import TextIO

from choreo.log.format import (COMMAND_TOPIC, LOG_TOPIC, STEP_TOPIC, CommandRecord, LogLayouts, LogRecord, Record,
                               Result, StepRecord, frame_meaning, parse, reply_meaning)
from choreo.review.attached import AttachedShow, attached_show
from choreo.review.frames import Exchange, exchanges
from choreo.review.showtime import ShowTimes, rounded
from choreo.review.timeline import link_cue_fields
from choreo.log.reader import LogReader
from choreo.show.cues import Cue, CueList, cue_list
from choreo.show.model import Plan, Tempo, beat_text

COLUMNS = (
    "seq",
    "tx_time_ns", "tx_show_s", "step", "label", "frame", "motion", "attempt", "tx_hex", "frame_meaning",
    "rx_time_ns", "rx_show_s", "reply", "rx_hex", "latency_ms", "executing", "error", "stale", "reply_meaning",
    "robot", "layout",
)


def row(exchange: Exchange, layouts: LogLayouts) -> dict:
    """One frame and its reply as a flat dict (None where the log has no such field); the
    meanings read with the layout the log records for the robot (`layout`)."""
    tx, rx = exchange.tx, exchange.rx
    return {
        "seq": exchange.seq,
        "tx_time_ns": exchange.tx_ns,
        "tx_show_s": _round(exchange.tx_s),
        "step": tx.step if tx else None,
        "label": tx.label if tx else None,
        "frame": tx.kind if tx else None,
        "motion": tx.motion if tx else None,
        "attempt": tx.attempt if tx else None,
        "tx_hex": tx.hex if tx else None,
        "frame_meaning": frame_meaning(tx, layouts) if tx else None,
        "rx_time_ns": exchange.rx_ns,
        "rx_show_s": _round(exchange.rx_s),
        "reply": rx.kind if rx else None,
        "rx_hex": rx.hex if rx else None,
        "latency_ms": rx.latency_ms if rx else None,
        "executing": rx.executing if rx else None,
        "error": rx.error if rx else None,
        "stale": rx.stale if rx else None,  # late replies to earlier frames set aside before this one, as hex
        "reply_meaning": reply_meaning(rx, tx, layouts) if rx else None,
        "robot": exchange.robot,  # whose frame, in a show for several robots (empty otherwise)
        "layout": layouts.name(exchange.robot),  # the board layout the meanings are read with
    }


def _round(seconds: float | None) -> float | None:
    return None if seconds is None else rounded(seconds, 9)


def rows(reader: LogReader) -> Iterator[dict]:
    layouts = LogLayouts.of(reader.run_info)
    for exchange in exchanges(reader):
        yield row(exchange, layouts)


class CsvSink:
    """CSV with a header row; empty cells for missing values, booleans as true/false."""

    def __init__(self, out: TextIO, columns: tuple[str, ...] = COLUMNS) -> None:
        self.writer = csv.DictWriter(out, fieldnames=columns, lineterminator="\n")
        self.writer.writeheader()

    def write(self, record: dict) -> None:
        self.writer.writerow({k: _csv_value(v) for k, v in record.items()})

    def close(self) -> None:
        pass


def _csv_value(value: object) -> object:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    return value


class JsonSink:
    """A JSON array of row objects, one per line, written as it goes (valid JSON when closed)."""

    def __init__(self, out: TextIO) -> None:
        self.out = out
        self.first = True
        out.write("[")

    def write(self, record: dict) -> None:
        self.out.write("\n" if self.first else ",\n")
        self.out.write(json.dumps(record, separators=(", ", ": ")))
        self.first = False

    def close(self) -> None:
        self.out.write("\n]\n" if not self.first else "]\n")


class JsonLinesSink:
    """One JSON object a line (JSON Lines): each row is whole as soon as it is written, so a
    reader can stream it, and a cut output loses only its last line."""

    def __init__(self, out: TextIO) -> None:
        self.out = out

    def write(self, record: dict) -> None:
        self.out.write(json.dumps(record, separators=(",", ":")) + "\n")

    def close(self) -> None:
        pass


def export(reader: LogReader, sinks: list[CsvSink | JsonSink | JsonLinesSink]) -> int:
    """Write every frame to every sink; the number of frames written."""
    count = 0
    for record in rows(reader):
        for sink in sinks:
            sink.write(record)
        count += 1
    for sink in sinks:
        sink.close()
    return count


# -- cues (`choreo log export --cues`) ---------------------------------------------------------

CUE_COLUMNS = ("number", "label", "robot", "pass", "planned_s", "actual_s", "late_ms", "released", "bar_beat")
GO_COMMANDS = ("go", "cue_go")
GO = "go"  # a GO cue's row until the pass is over: which GO released it is found then
WAITING = "waiting (stopped)"  # a GO cue a robot stood at, waiting for its GO, when the run ended
NOT_REACHED = "not reached"
NOT_IN_RUN = "not in this run"  # before --from's step, or outside --loop's section
# the runner's line as a robot reaches a GO cue (choreo.run.runner: `[robot R: ]step N['label'] waits for GO`)
WAITS_FOR_GO = re.compile(r"(?:robot (.+?): )?step (\d{1,9})(?: '.*')? waits for GO", re.S)
WAITS_LINE_MAX = 2000  # longer lines are no runner's: not matched (a hostile log's cost stays bounded)


@dataclass
class _Whereabouts:
    """Where one robot's steps went: --loop starts them again (a pass), --from later than 0."""

    passes: int = 1
    first: int | None = None  # the first step it started or skipped
    started: int = -1  # the last step it started or skipped, in this pass
    last: int = -1  # the step of its last event
    between: bool = False  # that event ended or skipped it: the robot stood between steps
    highest: int = -1  # the highest step it reached, in any pass

    def see(self, record: StepRecord) -> None:
        if record.event != "end":
            if record.index <= self.started:
                self.passes += 1
            self.started = record.index
            self.first = record.index if self.first is None else self.first
        self.last, self.between = record.index, record.event != "start"
        self.highest = max(self.highest, record.index)


@dataclass
class _CuePass:
    """One pass over the steps and commands: each cue's row per robot and --loop pass, as its
    step records say; which GO released a GO cue is matched by time once every command is read
    (a GO's command and its step start are logged in either order)."""

    numbers: dict[tuple[str, int], Cue] = field(default_factory=dict)  # (robot or "", index) -> its cue
    tempo: Tempo | None = None  # the attached show's: each cue's bar.beat
    rows: dict[tuple[str, int, int], dict] = field(default_factory=dict)  # (robot, index, pass), as reached
    at: dict[tuple[str, int, int], int] = field(default_factory=dict)  # a GO cue's row: its step's log time
    robots: dict[str, _Whereabouts] = field(default_factory=dict)
    gos: dict[str | None, list[tuple[int, str]]] = field(default_factory=dict)  # cue (None: all) -> GOs' (time, source)
    waits: dict[str, int] = field(default_factory=dict)  # robot -> the GO cue's step it waits at, as last logged

    def see(self, record: Record, log_time: int) -> None:
        if isinstance(record, LogRecord):
            self._waits(record.message)
            return
        if isinstance(record, CommandRecord):
            if record.command in GO_COMMANDS and record.status == "ok" and record.count is None:
                for named in {record.cue, None}:
                    self.gos.setdefault(named, []).append((log_time, str(record.source)))
            return
        if not isinstance(record, StepRecord) or record.event not in ("start", "skip", "end"):
            return
        where = self.robots.setdefault(record.robot or "", _Whereabouts())
        where.see(record)
        self.waits.pop(record.robot or "", None)  # a step began or ended since: it waits no longer
        key = (record.robot or "", record.index, where.passes)
        cue = self.numbers.get(key[:2])
        if record.event == "end" or key in self.rows or \
                not (record.cue is not None or record.go or record.cue_number or cue):
            return
        released = "skipped" if record.event == "skip" else GO if record.go else "time"
        self.rows[key] = _cue_row(record, cue, released, self.tempo, where.passes)
        if released == GO:
            self.at[key] = log_time

    def _waits(self, message: object) -> None:
        """A robot waits for GO at a step: only the runner's line says so (a step that ended,
        aborted by a panic, is no GO cue reached)."""
        if not isinstance(message, str) or len(message) > WAITS_LINE_MAX:
            return
        said = WAITS_FOR_GO.fullmatch(message)
        if said is not None:
            self.waits[said.group(1) or ""] = int(said.group(2))

    def released_by(self) -> None:
        """Each GO cue's row names the GO that released it: of that cue (by number), else any
        (an older log's commands name none), the one logged nearest its step's start."""
        for key, log_time in self.at.items():
            row = self.rows[key]
            gos = self.gos.get(row["number"]) or self.gos.get(None) or []
            at = bisect_left(gos, (log_time, ""))
            near = [gos[i] for i in (at - 1, at) if 0 <= i < len(gos)]
            if near:
                row["released"] = f"go {min(near, key=lambda go: abs(go[0] - log_time))[1]}"


def _cue_row(record: StepRecord, cue: Cue | None, released: str, tempo: Tempo | None, passes: int) -> dict:
    skipped = released == "skipped"
    return {"number": record.cue_number or (cue.number if cue else None), "label": record.label,
            "robot": record.robot, "pass": passes, "planned_s": _ms(_planned(record, released)),
            "actual_s": None if skipped else _ms(record.actual_s),
            "late_ms": None if skipped or record.go else rounded(record.late_ms, 3), "released": released,
            "bar_beat": _bar_beat(cue, tempo, record.estimated_s)}


def _planned(record: StepRecord, released: str) -> float:
    """A timed cue's planned time is its cue time (`at`): what it is late from; the plan's start
    for its step may be later (a `wait: done` before it). A GO cue's: where the plan put it."""
    timed = released != GO and not record.go and isinstance(record.cue, (int, float))
    return float(record.cue) if timed and record.cue is not None else record.estimated_s


def _unreached(cue: Cue, robot: str, passes: int, released: str, tempo: Tempo | None) -> dict:
    planned = cue.at if not cue.go and cue.at is not None else cue.planned_s
    return {"number": cue.number, "label": cue.label, "robot": robot or None, "pass": passes,
            "planned_s": _ms(planned), "actual_s": None, "late_ms": None, "released": released,
            "bar_beat": _bar_beat(cue, tempo, cue.planned_s)}


def _bar_beat(cue: Cue | None, tempo: Tempo | None, planned_s: float) -> str | None:
    """`5.1`: the bar and beat of the cue's planned time in a show with a tempo (as written, for
    a cue written in bars and beats), else nothing."""
    if cue is not None and cue.at_beat is not None:
        bar, beat = cue.at_beat
    elif tempo is not None and isinstance(planned_s, (int, float)) and math.isfinite(planned_s):
        bar, beat = tempo.position(planned_s)
        beat = rounded(beat, 3)
    else:
        return None
    return f"{bar}.{beat_text(beat)}"


def _ms(seconds: float | None) -> float | None:
    return None if seconds is None else rounded(seconds, 3)


def cue_rows(reader: LogReader, show: AttachedShow | None = None) -> list[dict]:
    """One row a cue a robot (and --loop pass): as the run reached it (by time, by whose GO,
    skipped), then the attached show's cues it did not run (waiting when it stopped, not reached,
    not in this run). Numbers from the step records, or for an older log from the attached
    show's cue list (blank without one). Held in memory: a row a cue."""
    show = show or attached_show(reader)
    plans = show.plans or ({"": show.plan} if show.plan is not None else {})
    cues = cue_list(plans) if plans else None
    tempo = show.show.tempo if show.show is not None else None
    seen = _CuePass({step: cue for cue in cues or () for step in cue.steps}, tempo)
    topic, number = None, 0
    try:
        for topic, log_time, data in reader.messages((STEP_TOPIC, COMMAND_TOPIC, LOG_TOPIC)):
            number += 1
            seen.see(parse(topic, data), log_time)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise reader.not_choreo(topic, number, exc) from None
    seen.released_by()
    ended = _Ended.of(reader, seen, plans)
    rows = list(seen.rows.values()) + _not_reached(seen, cues, ended, tempo, set(reader.robots))
    placed = link_cue_fields(show, ended.times)  # on Link: a cue in bars where the session put it
    for cue_row in rows:
        cue_row.update(placed.get(cue_row["number"], {}))
    return _in_cue_order(rows, cues, reader.robots)


@dataclass
class _Ended:
    """Where each robot was when the run ended: its last --loop pass (the clock's passes: a robot
    may not have begun its steps in the last), and the step it stood before, if it stood between
    steps (None: it was in the middle of one, or the run was done)."""

    passes: dict[str, int]
    before: dict[str, int | None]
    times: ShowTimes  # the log's show times (its Link session, on Link)

    @classmethod
    def of(cls, reader: LogReader, seen: _CuePass, plans: Mapping[str, Plan]) -> _Ended:
        times = ShowTimes.of(reader)
        total = times.passes()
        done = (reader.result or {}).get(Result.OUTCOME) == "done"
        passes: dict[str, int] = {}
        before: dict[str, int | None] = {}
        for robot in {**dict.fromkeys(plans), **seen.robots}:
            where = seen.robots.get(robot)
            passes[robot] = max(total, where.passes if where is not None else 1)
            before[robot] = None if done else _stood_before(where, plans.get(robot), robot, total, times.start_s)
        return cls(passes, before, times)


def _stood_before(where: _Whereabouts | None, plan: Plan | None, robot: str, passes: int, start_s: float) -> int | None:
    """The step a robot stood before when a run that was not done ended (None: in a step)."""
    if where is None:
        return _first_step(plan, start_s) if passes == 1 else None
    if where.passes < passes:
        return where.first  # a new --loop pass began, and the robot had not begun its steps
    return _next_step(plan, robot, where.last) if where.between else None


def _not_reached(seen: _CuePass, cues: CueList | None, ended: _Ended, tempo: Tempo | None,
                 robots: set[str]) -> list[dict]:
    """A row for each cue a robot did not run in a pass (one for a cue outside the run). Only
    the log's robots (`robots`; empty: every robot of the show): a host's run (`--host`) drives
    its own, and another host's cues are that host's log's to tell, not "not reached" here."""
    rows = []
    for cue in cues or ():
        for robot, index in cue.steps:
            if robots and robot and robot not in robots:
                continue
            where, passes = seen.robots.get(robot), ended.passes.get(robot, 1)
            if where is not None and where.first is not None and (
                    index < where.first or (passes > 1 and index > where.highest)):
                rows.append(_unreached(cue, robot, 1, NOT_IN_RUN, tempo))
                continue
            for pass_ in range(1, passes + 1):
                if (robot, index, pass_) not in seen.rows:
                    waiting = pass_ == passes and cue.go and ended.before.get(robot) == index \
                        and seen.waits.get(robot) == index
                    rows.append(_unreached(cue, robot, pass_, WAITING if waiting else NOT_REACHED, tempo))
    return rows


def _first_step(plan: Plan | None, start_s: float) -> int | None:
    """A robot's first step in a run that began at `start_s` (--from's step's planned time)."""
    steps = plan.steps if plan is not None else ()
    return next((step.index for step in steps if step.planned_s >= start_s - 1e-6), None)


def _next_step(plan: Plan | None, robot: str, after: int) -> int | None:
    """The robot's next step after step `after` (a step of others comes between in a track)."""
    steps = plan.steps if plan is not None else ()
    return next((step.index for step in steps[after + 1:] if not robot or step.is_for(robot)), None)


def _in_cue_order(rows: list[dict], cues: CueList | None, robots: list[str]) -> list[dict]:
    """Rows pass by pass in the cue list's order, each cue's robots in the show's (a row the
    list does not know keeps its place after the cue before it: sorting is stable)."""
    position = {cue.number: at for at, cue in enumerate(cues or ())}
    robot_at = {name: at for at, name in enumerate(robots)}
    last = -1
    keyed = []
    for row in rows:
        last = position.get(row["number"], last)
        keyed.append(((row["pass"], last, robot_at.get(row["robot"], len(robot_at))), row))
    return [row for _, row in sorted(keyed, key=lambda pair: pair[0])]


def export_cues(reader: LogReader, sinks: list[CsvSink | JsonSink | JsonLinesSink]) -> int:
    """Write every cue's row to every sink; the number of rows."""
    rows = cue_rows(reader)
    for record in rows:
        for sink in sinks:
            sink.write(record)
    for sink in sinks:
        sink.close()
    return len(rows)
