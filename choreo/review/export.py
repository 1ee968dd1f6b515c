"""`choreo log export`: one row a frame, with every field of the frame and of its reply.

For spreadsheets and pandas (`pandas.read_csv`, `pandas.read_json`): a flat table, times both as
wall-clock nanoseconds (exact, as logged) and show-clock seconds (what a reviewer reads), and the
meaning of each frame and reply in words. Written as it is read, so a long log never sits in memory.

`--cues`: one row a cue a robot instead: its number, label, planned and actual show time (the
step records' own, the times every review shows), lateness, and how it was released (`time`, the
GO's source such as `go key` or `go osc udp 127.0.0.1:53001`, `skipped`, `not reached`).
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TextIO

from choreo.log.format import (COMMAND_TOPIC, STEP_TOPIC, CommandRecord, LogLayouts, Record, StepRecord,
                               frame_meaning, parse, reply_meaning)
from choreo.review.attached import AttachedShow, attached_show
from choreo.review.frames import Exchange, exchanges
from choreo.log.reader import LogReader
from choreo.show.cues import Cue, CueList, cue_list
from choreo.show.model import Tempo, beat_text

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
    return None if seconds is None else round(seconds, 9)


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

CUE_COLUMNS = ("number", "label", "robot", "planned_s", "actual_s", "late_ms", "released", "bar_beat")
GO_COMMANDS = ("go", "cue_go")


@dataclass
class _CuePass:
    """One pass over the steps and commands: each cue's row per robot, as its step records say."""

    numbers: dict[tuple[str, int], Cue] = field(default_factory=dict)  # (robot or "", index) -> its cue
    tempo: Tempo | None = None  # the attached show's: each cue's bar.beat
    rows: dict[tuple[str, int], dict] = field(default_factory=dict)  # in the order the run reached them
    go_by: str | None = None  # the source of the last GO carried out

    def see(self, record: Record) -> None:
        if isinstance(record, CommandRecord):
            if record.command in GO_COMMANDS and record.status == "ok" and record.count is None:
                self.go_by = record.source
            return
        if not isinstance(record, StepRecord) or record.event not in ("start", "skip"):
            return
        key = (record.robot or "", record.index)
        cue = self.numbers.get(key)
        if key in self.rows or not (record.cue is not None or record.go or record.cue_number or cue):
            return
        self.rows[key] = _cue_row(record, cue, self._released(record), self.tempo)

    def _released(self, record: StepRecord) -> str:
        if record.event == "skip":
            return "skipped"
        if record.go:
            return f"go {self.go_by}" if self.go_by else "go"
        return "time"


def _cue_row(record: StepRecord, cue: Cue | None, released: str, tempo: Tempo | None) -> dict:
    skipped = released == "skipped"
    return {"number": record.cue_number or (cue.number if cue else None), "label": record.label,
            "robot": record.robot, "planned_s": _ms(record.estimated_s),
            "actual_s": None if skipped else _ms(record.actual_s),
            "late_ms": None if skipped or record.go else round(record.late_ms, 3), "released": released,
            "bar_beat": _bar_beat(cue, tempo, record.estimated_s)}


def _unreached(cue: Cue, robot: str, tempo: Tempo | None) -> dict:
    return {"number": cue.number, "label": cue.label, "robot": robot or None, "planned_s": _ms(cue.planned_s),
            "actual_s": None, "late_ms": None, "released": "not reached",
            "bar_beat": _bar_beat(cue, tempo, cue.planned_s)}


def _bar_beat(cue: Cue | None, tempo: Tempo | None, planned_s: float) -> str | None:
    """`5.1`: the bar and beat of the cue's planned time in a show with a tempo (as written, for
    a cue written in bars and beats), else nothing."""
    if cue is not None and cue.at_beat is not None:
        bar, beat = cue.at_beat
    elif tempo is not None and isinstance(planned_s, (int, float)) and math.isfinite(planned_s):
        bar, beat = tempo.position(planned_s)
        beat = round(beat, 3)
    else:
        return None
    return f"{bar}.{beat_text(beat)}"


def _ms(seconds: float | None) -> float | None:
    return None if seconds is None else round(seconds, 3)


def cue_rows(reader: LogReader, show: AttachedShow | None = None) -> list[dict]:
    """One row a cue a robot: as the run reached it (by time, by whose GO, skipped), then the
    attached show's cues it never reached. Numbers from the step records, or for an older log
    from the attached show's cue list (blank without one). Held in memory: a row a cue."""
    show = show or attached_show(reader)
    plans = show.plans or ({"": show.plan} if show.plan is not None else {})
    cues = cue_list(plans) if plans else None
    tempo = show.show.tempo if show.show is not None else None
    seen = _CuePass({step: cue for cue in cues or () for step in cue.steps}, tempo)
    topic, number = None, 0
    try:
        for topic, _, data in reader.messages((STEP_TOPIC, COMMAND_TOPIC)):
            number += 1
            seen.see(parse(topic, data))
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise reader.not_choreo(topic, number, exc) from None
    rows = list(seen.rows.values())
    reached = set(seen.rows)
    for cue in cues or ():
        rows += [_unreached(cue, robot, tempo) for robot, index in cue.steps if (robot, index) not in reached]
    return _in_cue_order(rows, cues, reader.robots)


def _in_cue_order(rows: list[dict], cues: CueList | None, robots: list[str]) -> list[dict]:
    """Rows in the cue list's order, each cue's robots in the show's (a row the list does not
    know keeps its place after the cue before it: sorting is stable)."""
    position = {cue.number: at for at, cue in enumerate(cues or ())}
    robot_at = {name: at for at, name in enumerate(robots)}
    last = -1
    keyed = []
    for row in rows:
        last = position.get(row["number"], last)
        keyed.append(((last, robot_at.get(row["robot"], len(robot_at))), row))
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
