"""`choreo log export`: one row a frame, with every field of the frame and of its reply.

For spreadsheets and pandas (`pandas.read_csv`, `pandas.read_json`): a flat table, times both as
wall-clock nanoseconds (exact, as logged) and show-clock seconds (what a reviewer reads), and the
meaning of each frame and reply in words. Written as it is read, so a long log never sits in memory.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterator
from typing import TextIO

from choreo.log.format import LogLayouts, frame_meaning, reply_meaning
from choreo.review.frames import Exchange, exchanges
from choreo.log.reader import LogReader

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

    def __init__(self, out: TextIO) -> None:
        self.writer = csv.DictWriter(out, fieldnames=COLUMNS, lineterminator="\n")
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
