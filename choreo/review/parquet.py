"""`choreo log export LOG... --parquet DIR`: many runs' logs as tables one query reads.

A show that plays every night leaves hundreds of logs, and the questions are about all of them:
which cue is late more and more, which robot retries since Tuesday. Each log becomes four Parquet
files in DIR, one a kind of row: `<stem>.frames.parquet` (the rows of `log export`),
`.steps.parquet` (one a step record), `.cues.parquet` (the rows of `log export --cues`) and
`.commands.parquet` (one a command record, the rate limiter's `unlogged` summaries too). Every row
starts with the run's columns (RUN_COLUMNS), so DuckDB's `read_parquet('DIR/*.cues.parquet',
union_by_name = true)` reads a folder of runs as one table.

Each column has one type in every file of its kind, whatever a log holds (int64, float64,
string, bool; null where the log has no value): a query over many runs never meets a column
that is a number in one and text in another. A step's or command's columns are its record's
fields, typed by their annotations, so a field the log gains is a column here too.

A file is written as `NAME.part` and renamed when all four of its run are whole: an export that
fails leaves no half-written table (nor spoils one exported before), and a query over the folder
never reads a file still being written. pyarrow is an optional extra, imported when used.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
import time
from collections.abc import Iterable, Iterator
from contextlib import suppress
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, BinaryIO

from choreo.errors import LogError, UsageError
from choreo.log import LOG_SUFFIX
from choreo.log.format import (COMMAND_TOPIC, STEP_TOPIC, TX_TOPIC, CommandRecord, Info, LogLayouts, Record,
                               StepRecord, parse)
from choreo.log.reader import LogReader
from choreo.review.export import COLUMNS, CUE_COLUMNS, cue_rows, row
from choreo.review.frames import exchanges
from choreo.userfile import kind_of, open_input, reading

INSTALL = "pip install 'choreo[parquet]'"
KINDS = ("frames", "steps", "cues", "commands")
SUFFIX = ".parquet"
PART = ".part"  # a table being written: no `*.parquet` glob reads it
BATCH_ROWS = 16384  # rows held before they go out as a row group: memory stays bounded on a long log

# What each column holds: "int" int64, "float" float64, "str" string, "bool" boolean, "json" a
# dict as JSON text, "time" a UTC timestamp (microseconds).
Columns = tuple[tuple[str, str], ...]
RUN_COLUMNS: Columns = (("run_id", "str"), ("run_start", "time"), ("show_name", "str"), ("host", "str"))
FRAME_TYPES = {
    "seq": "int", "tx_time_ns": "int", "tx_show_s": "float", "step": "int", "label": "str", "frame": "str",
    "motion": "int", "attempt": "int", "tx_hex": "str", "frame_meaning": "str", "rx_time_ns": "int",
    "rx_show_s": "float", "reply": "str", "rx_hex": "str", "latency_ms": "float", "executing": "bool",
    "error": "str", "stale": "str", "reply_meaning": "str", "robot": "str", "layout": "str",
}
CUE_TYPES = {"number": "str", "label": "str", "robot": "str", "pass": "int", "planned_s": "float",
             "actual_s": "float", "late_ms": "float", "released": "str", "bar_beat": "str"}
_ANNOTATED = {"int": "int", "float": "float", "str": "str", "bool": "bool", "dict": "json"}


def record_columns(record_type: type) -> Columns:
    """A record's columns: its log time (`time_ns`), then its fields, typed by their annotations
    (`float | None`: float). An annotation this table cannot type is a KeyError at import."""
    columns = [("time_ns", "int")]
    for f in fields(record_type):
        kinds = [part.strip() for part in str(f.type).split("|") if part.strip() != "None"]
        columns.append((f.name, _ANNOTATED[kinds[0]]))
    return tuple(columns)


TABLES: dict[str, Columns] = {
    "frames": tuple((name, FRAME_TYPES[name]) for name in COLUMNS),
    "steps": record_columns(StepRecord),
    "cues": tuple((name, CUE_TYPES[name]) for name in CUE_COLUMNS),
    "commands": record_columns(CommandRecord),
}


@dataclass(frozen=True)
class Exported:
    """One log's export: its run's id, the rows of each kind, and where they went."""

    run_id: str
    counts: dict[str, int]
    paths: dict[str, Path]


def require_pyarrow() -> tuple[Any, Any]:
    """pyarrow and pyarrow.parquet, or the one line that says how to install them."""
    try:
        import pyarrow
        import pyarrow.parquet
    except ImportError:
        raise UsageError(f"log export --parquet needs pyarrow: {INSTALL}") from None
    return pyarrow, pyarrow.parquet


def stem(log: Path) -> str:
    """The name the tables of a log take: `show-20261126.mcap` -> `show-20261126`."""
    name = log.name
    return name[:-len(LOG_SUFFIX)] if name.endswith(LOG_SUFFIX) and len(name) > len(LOG_SUFFIX) else name


def table_paths(folder: Path, log: Path) -> dict[str, Path]:
    return {kind: folder / f"{stem(log)}.{kind}{SUFFIX}" for kind in KINDS}


def export_parquet(reader: LogReader, folder: Path) -> Exported:
    """Write a log's four tables into `folder` (which exists). LogError: the log is not choreo's,
    or holds a value no column can (a table of it is left nowhere); UsageError: a table cannot be
    written (the folder, the disk)."""
    pa, pq = require_pyarrow()
    paths = table_paths(folder, reader.path)
    _check_targets(paths.values())
    run = run_values(reader)
    parts = {kind: path.with_name(path.name + PART) for kind, path in paths.items()}
    counts: dict[str, int] = {}
    try:
        with _Writer(pa, pq, reader, run) as writer:
            counts["frames"] = writer.table(parts["frames"], "frames", _frame_rows(reader))
            counts["steps"], counts["commands"] = writer.steps_and_commands(parts["steps"], parts["commands"])
            counts["cues"] = writer.table(parts["cues"], "cues", cue_rows(reader))
        for kind in KINDS:
            _rename(parts[kind], paths[kind])
    finally:
        for part in parts.values():
            _remove(part)
    return Exported(str(run["run_id"]), {kind: counts[kind] for kind in KINDS}, paths)


def run_values(reader: LogReader) -> dict[str, object]:
    """The run's columns: its id, start, show and host.

    `run_id` is the show's name and the run's wall-clock start to the nanosecond (`dance@
    2026-11-26T20:00:00.123456789Z`), with the host that ran it (`@left`) in a show of several
    hosts: the same for the same run however its log is named, copied or exported again, and
    readable in a query. A log whose metadata lacks either (another program's, a damaged head)
    is named by its content: `sha256:` and the first 32 hex digits of the file's SHA-256."""
    info = reader.info
    host = ",".join(info.hosts) or info.text.get(Info.SHOW_HOST) or None  # a merged log's hosts, or this run's
    start_ns = info.start_ns
    started = _iso(start_ns) if start_ns is not None else None
    if start_ns is None or started is None:
        start_ns = None
    if info.show and start_ns is not None:
        run_id = f"{info.show}@{started}" + (f"@{host}" if host else "")
    else:
        run_id = f"sha256:{_digest(reader.path)[:32]}"
    return {"run_id": run_id, "run_start": None if start_ns is None else start_ns // 1000,
            "show_name": info.show or None, "host": host}


def _iso(ns: int) -> str | None:
    """`2026-11-26T20:00:00.123456789Z`, or None for a time no calendar holds."""
    try:
        return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(ns // 10**9)) + f".{ns % 10**9:09d}Z"
    except (OverflowError, OSError, ValueError):
        return None


def _digest(path: Path) -> str:
    digest = hashlib.sha256()
    with open_input(path, "run log") as f, reading(path, "run log"):
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _frame_rows(reader: LogReader) -> Iterator[dict]:
    """The rows of `log export`; a frame whose fields no row can be made of is the log's fault,
    said as `log frames --json` says it."""
    layouts = LogLayouts.of(reader.run_info)
    for exchange in exchanges(reader):
        try:
            yield row(exchange, layouts)
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise reader.not_choreo(TX_TOPIC, exchange.seq, exc) from None


class _Writer:
    """The tables of one run, each written batch by batch; every file it made closed at the end."""

    def __init__(self, pa: Any, pq: Any, reader: LogReader, run: dict[str, object]) -> None:
        self.pa, self.pq, self.reader, self.run = pa, pq, reader, run
        self.open: list[_Table] = []

    def __enter__(self) -> _Writer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        for table in self.open:
            table.abandon()

    def create(self, part: Path, kind: str) -> _Table:
        table = _Table(self.pa, self.pq, part, kind, self.run, self.reader.path)
        self.open.append(table)
        return table

    def table(self, part: Path, kind: str, records: Iterable[dict]) -> int:
        table = self.create(part, kind)
        for record in records:
            table.add(record)
        return table.close()

    def steps_and_commands(self, steps_part: Path, commands_part: Path) -> tuple[int, int]:
        """One pass over the step and command records: a row each, as logged."""
        steps, commands = self.create(steps_part, "steps"), self.create(commands_part, "commands")
        topic, number = None, 0
        try:
            for topic, log_time, data in self.reader.messages((STEP_TOPIC, COMMAND_TOPIC)):
                number += 1
                record: Record = parse(topic, data)
                (steps if topic == STEP_TOPIC else commands).add(_record_row(record, log_time))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise self.reader.not_choreo(topic, number, exc) from None
        return steps.close(), commands.close()


def _record_row(record: Record, log_time: int) -> dict:
    return {"time_ns": log_time, **record.to_json()}  # a field the record leaves out is null


class _Table:
    """One Parquet file: rows gathered column by column, a row group each BATCH_ROWS."""

    def __init__(self, pa: Any, pq: Any, part: Path, kind: str, run: dict[str, object], log: Path) -> None:
        self.pa, self.part, self.kind, self.run, self.log = pa, part, kind, run, log
        self.columns = RUN_COLUMNS + TABLES[kind]
        self.schema = pa.schema([(name, _arrow_type(pa, of)) for name, of in self.columns])
        self.values: dict[str, list] = {name: [] for name, _ in TABLES[kind]}
        self.count = 0
        self.file: BinaryIO | None = _create(part)
        try:
            self.writer = pq.ParquetWriter(self.file, self.schema)
        except OSError as exc:
            self.abandon()
            raise self._unwritable(exc) from None

    def add(self, record: dict) -> None:
        for name, values in self.values.items():
            values.append(record.get(name))
        self.count += 1
        if len(next(iter(self.values.values()))) >= BATCH_ROWS:
            self._flush()

    def close(self) -> int:
        """Write what is left and close the file; the number of rows."""
        self._flush()
        try:
            self.writer.close()
            if self.file is not None:
                self.file.close()
        except OSError as exc:
            raise self._unwritable(exc) from None
        self.file = None
        return self.count

    def abandon(self) -> None:
        """Close a file left unfinished (it is removed by its name's end, `.part`)."""
        if self.file is not None:
            with suppress(Exception):  # pyarrow's own errors too: the table is given up either way
                self.writer.close()
            with suppress(OSError):
                self.file.close()
            self.file = None

    def _flush(self) -> None:
        size = len(next(iter(self.values.values())))
        if size == 0:  # a kind the run has none of is still a file: its schema, no row group
            return
        arrays = [self._array(name, of, [self.run[name]] * size) for name, of in RUN_COLUMNS]
        arrays += [self._array(name, of, self.values[name]) for name, of in TABLES[self.kind]]
        try:
            self.writer.write_table(self.pa.Table.from_arrays(arrays, schema=self.schema))
        except OSError as exc:
            raise self._unwritable(exc) from None
        for values in self.values.values():
            values.clear()

    def _array(self, name: str, of: str, values: list) -> Any:
        """A column's values as an Arrow array of its type. Text no UTF-8 can carry (a lone
        surrogate, as an OSC sender's bytes may decode) goes as its escape, `\\udcff`; a value
        the type cannot hold (a number past int64) is the log's fault: LogError, one line."""
        if of == "json":
            values = [None if value is None else json.dumps(value, sort_keys=True) for value in values]
        kind = _arrow_type(self.pa, of)
        try:
            try:
                return self.pa.array(values, type=kind)
            except UnicodeEncodeError:
                return self.pa.array([_utf8(value) for value in values], type=kind)
        except (self.pa.ArrowException, OverflowError, TypeError, ValueError) as exc:
            raise LogError(f"log {self.log}: {self.kind}: {name} holds a value no Parquet {of} column can "
                           f"({str(exc)[:80]}): was this log written by choreo run?") from None

    def _unwritable(self, exc: OSError) -> UsageError:
        return UsageError(f"log export --parquet {self.part.with_name(self.part.name[:-len(PART)])}: "
                          f"cannot write: {exc.strerror or exc}")


def _arrow_type(pa: Any, of: str) -> Any:
    if of == "time":
        return pa.timestamp("us", tz="UTC")
    return {"int": pa.int64(), "float": pa.float64(), "str": pa.string(), "json": pa.string(),
            "bool": pa.bool_()}[of]


def _utf8(value: object) -> object:
    return value.encode("utf-8", "backslashreplace").decode("utf-8") if isinstance(value, str) else value


_CREATE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_BINARY", 0)


def _create(part: Path) -> BinaryIO:
    """A new file for a table; one an export killed half-way left behind is replaced."""
    _remove(part)
    try:
        return os.fdopen(os.open(part, _CREATE_FLAGS, 0o666), "wb")
    except OSError as exc:
        raise UsageError(f"log export --parquet {part.parent}: cannot write: {exc.strerror or exc}") from None


def _check_targets(paths: Iterable[Path]) -> None:
    """Each table's name is free or a file to replace: a folder (or a pipe) there is refused
    before anything is written, not found at the renames with half the run's tables in place."""
    for path in paths:
        try:
            mode = os.lstat(path).st_mode
        except FileNotFoundError:
            continue
        except OSError as exc:
            raise UsageError(f"log export --parquet {path}: cannot write: {exc.strerror or exc}") from None
        if not (stat.S_ISREG(mode) or stat.S_ISLNK(mode)):
            raise UsageError(f"log export --parquet {path}: cannot write: it is {kind_of(mode)}")


def _rename(part: Path, path: Path) -> None:
    try:
        os.replace(part, path)
    except OSError as exc:
        raise UsageError(f"log export --parquet {path}: cannot write: {exc.strerror or exc}") from None


def _remove(part: Path) -> None:
    """A `.part` file gone (a link or a file, never a folder someone named so)."""
    with suppress(OSError):
        if not part.is_dir() or part.is_symlink():
            part.unlink()
