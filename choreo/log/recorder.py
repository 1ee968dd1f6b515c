"""The run log: every frame, reply, step and warning of a run, as MCAP with JSON messages.

The recorder is a listener of the link (frames and replies) and of the runner (steps and log
lines). It must not cost the show its timing: a frame is reported just before it is written,
often right at a cue's due time, and the next frame may be due right after a reply. So every
report is only queued (one deque append, no lock); the queue is serialised and written when the
runner has time to spare (`on_idle`, called before it sleeps), which also hands the file to the
OS every quarter second. A background thread flushes a run that never idles (back-to-back
frames), so a killed run loses at most half a second and a linear reader can read the rest.
Messages keep the order they were reported in. The file is created exclusively: a log is never
overwritten.

A run is recorded or it does not go on. The run's start (header, metadata, the show, the
schemas) is written, flushed and fsync'd before the port opens, and a file that cannot take it
is removed. Then disk space is kept reserved ahead of the write position (Linux
fallocate(FALLOC_FL_KEEP_SIZE): the file's size does not change, so a crash still leaves a valid
MCAP): enough for every message reported but not yet written, the chunk being built, what the
run may still report once told to stop (the exchange in flight, the abort motion) and the file's
summary. The room is checked as each message is reported, before the next frame can go out;
when the reserve cannot grow (a full disk) the run is told to stop, and everything it sent still
fits. Closing truncates the file to its length, which frees what was left of the reserve. Where
fallocate is not supported, a write that fails stops the run instead, and what was sent since
the last write that worked is missing from the log.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import platform
import socket
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from datetime import datetime, timezone
from importlib import resources
from pathlib import Path
from typing import IO, Any

from mcap.writer import CompressionType, Writer

from choreo import SCHEMAS, __version__
from choreo.errors import LogError
from choreo.log import LOG_DIR, LOG_SUFFIX
from choreo.events import CommandEvent, RxEvent, StepEvent, StopRequest, TxEvent
from choreo.wire.layouts import DEFAULT_LAYOUT
from choreo.log.format import (CLOCK_TOPIC, COMMAND_TOPIC, LOG_TOPIC, METADATA_NAME, RESULT_METADATA_NAME, RX_TOPIC,
                               SHOW_MEDIA_TYPE, STEP_TOPIC, TX_TOPIC, UNLOGGED, ClockRecord, CommandRecord, Info,
                               LogRecord, RxRecord, StepRecord, TxRecord, channels_for, layout_key, robot_key,
                               robot_topic)

FLUSH_EVERY_S = 0.5
BATCH = 16  # messages the background flusher writes before it lets the runner have the GIL
CHUNK_SIZE = 64 * 1024

# The reserve (see the module's docstring). Every figure is a bound with room to spare: a logged
# message takes about 220 bytes in the file with its index entry; a label or an error line makes
# one longer, so MESSAGE_BUDGET is what they take on average at worst.
MESSAGE_BUDGET = 512  # bytes a message may take in the file, its index entries included
IN_FLIGHT = 256  # messages a run may still report once told to stop: the exchange in flight
#                  and its retries, the abort motion and its retries, the last steps and warnings
CHUNK_BUDGET = 512  # bytes each chunk adds: its index in the summary, its message indexes
CHUNK_BOUND = CHUNK_SIZE * 5 // 4 + MESSAGE_BUDGET  # the chunk being built, with its indexes
SUMMARY_SLACK = 8 * 1024  # summary beyond the schemas: channels, statistics, indexes, footer, result
START_SLACK = 4 * 1024  # the start beyond the schemas and the show: header, metadata, channels
RESERVE_AHEAD = 256 * 1024  # reserved beyond what is needed, so the reserve grows only now and then
ROOM_MARGIN = RESERVE_AHEAD // 4 // MESSAGE_BUDGET  # messages short of the room: look at the reserve again

MAX_NAME_BYTES = 200  # of a default log name's show part: 255 less the time, a suffix, `.mcap`


def default_log_path(show_name: str, directory: str | Path = LOG_DIR, now: datetime | None = None) -> Path:
    """`runs/<show name>-<UTC time>.mcap` (LOG_DIR, LOG_SUFFIX), a name that sorts by time and never repeats a run's."""
    now = now or datetime.now(timezone.utc)
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in show_name) or "show"
    # A file name is at most 255 bytes: a long show name is cut (at a character) so that the
    # time, a `-99` suffix and `.mcap` always fit.
    safe = safe.encode()[:MAX_NAME_BYTES].decode("utf-8", "ignore")
    return Path(directory) / f"{safe}-{now.strftime('%Y%m%dT%H%M%SZ')}{LOG_SUFFIX}"


def schema_text(filename: str) -> bytes:
    return (resources.files(SCHEMAS) / filename).read_bytes()


@dataclass(frozen=True)
class RobotInfo:
    """One robot of a show for several: what the metadata says of its link."""

    name: str
    port: str
    baud: int
    layout: str = DEFAULT_LAYOUT


@dataclass(frozen=True)
class RunInfo:
    """What the log's `choreo` metadata says about the run (`port`, `baud` and `layout`: the
    first robot's; `robots`: every robot of a show for several)."""

    show_path: str
    show_name: str
    show_source: bytes
    port: str
    baud: int
    start_ns: int
    layout: str = DEFAULT_LAYOUT
    robots: tuple[RobotInfo, ...] = ()
    unison: bool = False  # the robots share their steps (a unison play's starts are comparable)
    show_host: str | None = None  # the show's `hosts:` entry this run drove (None: a show for one host)

    def metadata(self) -> dict[str, str]:
        host = {Info.SHOW_HOST: self.show_host} if self.show_host is not None else {}
        return {key: _utf8(value) for key, value in {**self._run(), **self._robots(), **host}.items()}

    def _robots(self) -> dict[str, str]:
        """`robots: left,right` and `robot.left.port` etc.: MCAP metadata is flat text."""
        if not self.robots:
            return {}
        named = {Info.ROBOTS: ",".join(robot.name for robot in self.robots),
                 Info.UNISON: Info.YES if self.unison else Info.NO}
        for robot in self.robots:
            named.update({robot_key(robot.name, Info.PORT): robot.port,
                          robot_key(robot.name, Info.BAUD): str(robot.baud), layout_key(robot.name): robot.layout})
        return named

    def _run(self) -> dict[str, str]:
        return {
            Info.VERSION: __version__,
            Info.SHOW: self.show_name,
            Info.SHOW_PATH: self.show_path,
            Info.SHOW_SHA256: hashlib.sha256(self.show_source).hexdigest(),
            Info.PORT: self.port,
            Info.BAUD: str(self.baud),
            layout_key(None): self.layout,
            Info.START_TIME: _iso(self.start_ns),
            Info.START_NS: str(self.start_ns),
            Info.HOST: socket.gethostname(),
            Info.PYTHON: platform.python_version(),
            Info.PLATFORM: sys.platform,
        }


def _utf8(text: str) -> str:
    """`text` as MCAP metadata can hold it (UTF-8): a file name's bytes that are not UTF-8
    (lone surrogates, as Python reads them) kept as escapes (`\\udcff`), not a crash at start."""
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def _iso(ns: int) -> str:
    return datetime.fromtimestamp(ns / 1e9, timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


# One encoder for every message: json.dumps with non-default separators builds a new encoder on
# each call, a third of the cost of serialising a frame.
_encode = json.JSONEncoder(separators=(",", ":")).encode


def _dumps(message: dict) -> bytes:
    return _encode(message).encode()


def _tx_message(event: TxEvent, robot: str | None = None) -> dict:
    tag = event.tag
    return TxRecord(event.seq, event.frame.kind.value, event.frame.hex, event.attempt,
                    tag.step if tag else None, tag.label if tag else None, event.frame.motion, robot).to_json()


def _rx_message(event: RxEvent, robot: str | None = None) -> dict:
    reply = event.reply
    return RxRecord(event.seq, reply.kind.value, reply.hex, round(event.latency_s * 1e3, 4), reply.executing,
                    reply.error, reply.stale.hex(" ") if reply.stale else None, robot).to_json()


def step_record(event: StepEvent) -> StepRecord:
    """A step event as the log keeps it (times rounded to the microsecond)."""
    step = event.step
    return StepRecord(step.index, step.kind.value, event.event, round(event.actual_s, 6),
                      round(event.planned_s, 6), round(step.planned_s, 6), round(event.late_ms, 3),
                      step.path, step.label, step.motion, step.at, event.outcome, event.robot,
                      None if event.start_s is None else round(event.start_s, 6),
                      round(event.lead_ms, 3) if event.lead_ms else None, True if step.go else None,
                      step.cue)


def _step_message(event: StepEvent) -> dict:
    return step_record(event).to_json()


def _record_message(record: ClockRecord | CommandRecord | StepRecord) -> dict:
    return record.to_json()


def _log_message(entry: tuple[int, str, int]) -> dict:
    level, message, time_ns = entry
    return LogRecord.at(level, message, time_ns).to_json()


# A reported event waiting to be written: (topic, log time, how to make its message, the event).
_Pending = tuple[str, int, Callable[[Any], dict], Any]


class RobotTap:
    """One robot's link, heard by the recorder: frames and replies on `/rcb4/<robot>/...`,
    each naming the robot."""

    def __init__(self, recorder: Recorder, robot: str) -> None:
        self.recorder = recorder
        self.robot = robot
        self.tx_topic = robot_topic(TX_TOPIC, robot)
        self.rx_topic = robot_topic(RX_TOPIC, robot)

    def on_tx(self, event: TxEvent) -> None:
        self.recorder._queue((self.tx_topic, event.time_ns, self._tx, event))

    def on_rx(self, event: RxEvent) -> None:
        self.recorder._queue((self.rx_topic, event.time_ns, self._rx, event))

    def _tx(self, event: TxEvent) -> dict:
        return _tx_message(event, self.robot)

    def _rx(self, event: RxEvent) -> dict:
        return _rx_message(event, self.robot)


class Recorder:
    """Writes one run's MCAP log; a LinkListener and a runner listener at once."""

    def __init__(self, path: str | Path, info: RunInfo, *, flush_every_s: float = FLUSH_EVERY_S,
                 unique: bool = False) -> None:
        self._file, self.path = _create_exclusive(Path(path), unique)
        self.failure: str | None = None  # why the file could not be written, once it could not
        self.full: str | None = None  # why the reserve could not grow: the run must stop
        self.stopped_run = False  # the log asked the run to stop
        self._stop_request: StopRequest | None = None  # whom to ask, while a run goes (`stopping`)
        self._lock = threading.Lock()
        self._dirty = False
        self._closed = False
        self._pending: deque[_Pending] = deque()  # appended by reporters, drained under the lock
        self._flush_every_s = flush_every_s
        self._flushed = time.monotonic()
        self._written = 0  # messages added to the file so far (their MCAP sequence numbers)
        self._chunks = 0  # chunks closed by a flush so far
        self._room = sys.maxsize  # messages reported that the reserve is known to hold
        self._topics = channels_for(tuple(robot.name for robot in info.robots))
        schemas = {topic: schema_text(filename) for topic, (_, filename) in self._topics.items()}
        self._summary_bytes = sum(map(len, schemas.values())) + SUMMARY_SLACK
        self._reserve = DiskReserve(self._file.fileno())
        need = self._summary_bytes + len(info.show_source) + START_SLACK + self._tail_bytes()
        try:
            self._grow_reserve(need, need + RESERVE_AHEAD)
            self._write_start(info, schemas)
        except OSError as exc:
            self._discard()
            raise LogError(f"log {self.path}: cannot write the start of the run: "
                           f"{exc.strerror or exc}{_space_hint(exc, self.path, need)}"
                           ) from None
        self._update_room()
        self._stop = threading.Event()
        self._flusher = threading.Thread(target=self._flush_loop, args=(flush_every_s,),
                                         name="choreo-log-flush", daemon=True)
        self._flusher.start()

    def _write_start(self, info: RunInfo, schemas: dict[str, bytes]) -> None:
        """Header, schemas, channels, metadata and the show, on the disk before the port opens."""
        self._writer = Writer(self._file, chunk_size=CHUNK_SIZE, compression=CompressionType.NONE)
        self._writer.start(profile="", library=f"choreo {__version__}")
        self._channels = {topic: self._register(topic, self._topics[topic][0], schemas[topic])
                          for topic in self._topics}
        self._writer.add_metadata(METADATA_NAME, info.metadata())
        self._writer.add_attachment(
            create_time=info.start_ns, log_time=info.start_ns,
            name=_utf8(Path(info.show_path).name), media_type=SHOW_MEDIA_TYPE, data=info.show_source,
        )
        self._writer.flush()
        self._file.flush()
        os.fsync(self._file.fileno())

    def _discard(self) -> None:
        """A file that could not take the run's start is no log: remove it."""
        with suppress(OSError):  # the buffered start could not be written either
            self._file.close()
        self._reserve.release()
        with suppress(OSError):  # gone already, or not ours to remove: nothing more to do
            self.path.unlink()

    def _register(self, topic: str, schema_name: str, schema: bytes) -> int:
        schema_id = self._writer.register_schema(name=schema_name, encoding="jsonschema", data=schema)
        return self._writer.register_channel(topic=topic, message_encoding="json", schema_id=schema_id)

    @property
    def messages(self) -> int:
        """Messages reported so far, written or still queued."""
        return self._written + len(self._pending)

    # -- listeners -------------------------------------------------------------------------

    def on_tx(self, event: TxEvent) -> None:
        """Queued only: the frame has not been written yet (see the module's docstring)."""
        self._queue((TX_TOPIC, event.time_ns, _tx_message, event))

    def on_rx(self, event: RxEvent) -> None:
        """Queued only: the next frame may be due right after this reply."""
        self._queue((RX_TOPIC, event.time_ns, _rx_message, event))

    def on_step(self, event: StepEvent) -> None:
        """Queued only: a step's start comes just before its first frame."""
        self._queue((robot_topic(STEP_TOPIC, event.robot), event.time_ns, _step_message, event))

    def on_step_record(self, record: StepRecord, time_ns: int) -> None:
        """Queued only: a step as the log keeps it, given whole (a replay re-times the recorded
        ones; it has no planned step to build one from)."""
        self._queue((robot_topic(STEP_TOPIC, record.robot), time_ns, _record_message, record))

    def for_robot(self, robot: str) -> RobotTap:
        """The link listener of one robot of several: its frames on its own topics."""
        return RobotTap(self, robot)

    def on_log(self, level: int, message: str, time_ns: int) -> None:
        """Queued only: a late-cue warning comes just before the cue's first frame. `time_ns`:
        the run clock's wall time (`RunClock.wall_ns`), never the machine's: on virtual time or
        the music's clock that would place the line elsewhere on the show clock."""
        self._queue((LOG_TOPIC, time_ns, _log_message, (level, message, time_ns)))

    def on_clock(self, record: ClockRecord, time_ns: int) -> None:
        """Queued only: a sample of the show clock (`choreo.run.session.ClockSampler`)."""
        self._queue((CLOCK_TOPIC, time_ns, _record_message, record))

    def on_command(self, event: CommandEvent) -> None:
        """Queued only: an operator's command and its answer (`choreo.live.controls`)."""
        command, answer = event.command, event.answer
        summed = command.name == UNLOGGED  # commands held back by the limits, summed up
        cue, cue_label = answer.data.get("cue"), answer.data.get("label")  # the cue it acted on, whatever was typed
        record = CommandRecord(command.name, command.source, answer.status, answer.message, command.label,
                               None if event.show_s is None else round(event.show_s, 6),
                               answer.data.get("count") if summed else None,
                               answer.data.get("counts") if summed else None,
                               cue if isinstance(cue, str) else None,
                               cue_label if isinstance(cue, str) and isinstance(cue_label, str) else None)
        self._queue((COMMAND_TOPIC, event.time_ns, _record_message, record))

    def _queue(self, item: _Pending) -> None:
        """One append, and one comparison: is the message still inside the reserve? If not, the
        reserve grows now, or the run is told to stop before its next frame."""
        self._pending.append(item)
        if self._written + len(self._pending) > self._room:
            with self._lock:
                self._keep_reserve()

    def _write_pending(self, limit: int | None = None) -> None:
        """Serialise and add queued messages (all, or `limit`), in order; the caller holds the lock."""
        pending = self._pending
        left = len(pending) if limit is None else limit
        try:
            while pending and self.failure is None and left > 0:
                left -= 1
                topic, time_ns, make, event = pending.popleft()
                self._writer.add_message(self._channels[topic], log_time=time_ns,
                                         data=_dumps(make(event)), publish_time=time_ns,
                                         sequence=self._written)
                self._written += 1
                self._dirty = True
        except OSError as exc:  # a chunk reached the disk and the disk said no
            self._failed(exc)
        if self._written + len(pending) + ROOM_MARGIN > self._room:
            self._keep_reserve()  # only near the edge: it asks the file where it is (a syscall)

    # -- the reserve -----------------------------------------------------------------------

    def _tail_bytes(self) -> int:
        """What the file still needs beyond the messages reported: the chunk being built, what
        a stopping run still reports, and the summary with one index for each chunk."""
        return (CHUNK_BOUND + IN_FLIGHT * MESSAGE_BUDGET + self._summary_bytes
                + CHUNK_BUDGET * (self._chunks + self._file.tell() // CHUNK_SIZE + 2))

    def _update_room(self) -> None:
        if self._reserve.supported:
            base = self._file.tell() + self._tail_bytes()
            self._room = self._written + max(0, self._reserve.end - base) // MESSAGE_BUDGET

    def _keep_reserve(self) -> None:
        """Grow the reserve when less than half of RESERVE_AHEAD is left; the caller holds the
        lock. A disk that cannot give more stops the run (what it sent still fits)."""
        if not self._reserve.supported or self.full or self.failure or self._closed:
            self._room = sys.maxsize  # nothing left to check: nothing is reserved, or the run is stopping
            return
        needed = (self._file.tell() + self._tail_bytes()
                  + (len(self._pending) + 1) * MESSAGE_BUDGET)
        if self._reserve.end - needed < RESERVE_AHEAD // 2:
            try:
                self._grow_reserve(needed + RESERVE_AHEAD // 16, needed + RESERVE_AHEAD)
            except OSError as exc:
                self.full = exc.strerror or str(exc)
                self._ask_to_stop(f"stopped: the log's disk is full ({self.full})")
                return
        self._update_room()

    def _grow_reserve(self, least: int, wanted: int) -> None:
        """Reserve up to `wanted`, or else `least`; OSError if the disk has not even that."""
        try:
            self._reserve.extend_to(wanted)
        except OSError:
            self._reserve.extend_to(least)

    @contextmanager
    def stopping(self, stop: StopRequest) -> Iterator[None]:
        """For the block's time (a run), a log that cannot take more asks `stop` to end the run
        (the exchange in flight, then the abort motion); after it, nobody is asked."""
        self._stop_request = stop
        try:
            yield
        finally:
            self._stop_request = None

    def _ask_to_stop(self, reason: str) -> None:
        """The log stopped the run only if its reason took: a disk that fills once a panic (or
        a Ctrl-C) is stopping the run leaves the run that reason (first reason wins)."""
        stop = self._stop_request
        if not self.stopped_run and stop is not None:
            self.stopped_run = stop.request(reason)

    def check(self) -> None:
        """LogError if the log failed, or stopped the run: the run's outcome is this error."""
        if self.failure is not None:
            raise LogError(f"log {self.path}: cannot write: {self.failure}: the run was stopped")
        if self.full is not None and self.stopped_run:
            raise LogError(f"log {self.path}: the disk is full ({self.full}): the run was "
                           "stopped; the log holds every frame sent")

    # -- durability ------------------------------------------------------------------------

    def on_idle(self) -> None:
        """The runner has time to spare (it is about to sleep): write what is queued, and
        hand the file to the OS if the last time was a while ago."""
        with self._lock:
            if not self._closed:
                self._write_pending()
                if time.monotonic() - self._flushed >= self._flush_every_s / 2:
                    self._flush_locked()

    def _flush_loop(self, every_s: float) -> None:
        """The safety net: a run that never idles (back-to-back frames) is flushed from here.

        It writes in small batches and yields between them: the runner thread, waking for a
        reply, must not wait for this thread to finish a long stretch of work under the GIL.
        """
        while not self._stop.wait(every_s / 2):
            if time.monotonic() - self._flushed < every_s / 2:
                continue
            while self._pending and not self._closed:
                with self._lock:
                    if not self._closed:
                        self._write_pending(limit=BATCH)
                time.sleep(0)
            self.flush()

    def flush(self) -> None:
        """Close the chunk in progress and hand it to the OS: a SIGKILL now loses nothing."""
        with self._lock:
            if not self._closed:
                self._write_pending()
                self._flush_locked()

    def _flush_locked(self) -> None:
        self._flushed = time.monotonic()
        # Once the disk is full the run is stopping: its last messages reach the file when it
        # closes, as one chunk, so no chunk index beyond those the reserve counted is added.
        if not self._dirty or self.failure is not None or self.full is not None:
            return
        try:
            self._writer.flush()
        except OSError as exc:
            self._failed(exc)
            return
        self._dirty = False
        self._chunks += 1
        self._keep_reserve()

    def _failed(self, exc: OSError) -> None:
        if self.failure is None:
            self.failure = exc.strerror or str(exc)
        self._pending.clear()
        self._ask_to_stop(f"stopped: the log cannot be written ({self.failure})")

    def close(self, result: dict[str, str] | None = None) -> None:
        """Finish the file (summary, indexes, footer), free what is left of the reserve. Safe to
        call twice.

        A log that already failed is closed quietly (its error was raised where it happened);
        one that fails only now raises one LogError.
        """
        if self._closed:
            return
        self._stop.set()
        if self._flusher.is_alive() and self._flusher is not threading.current_thread():
            self._flusher.join(timeout=2)
        with self._lock:
            failed_before = self.failure is not None
            try:
                self._write_pending()
                if self.failure is None:
                    if result is not None:
                        self._writer.add_metadata(RESULT_METADATA_NAME, {k: _utf8(v) for k, v in result.items()})
                    self._writer.finish()
                    self._file.flush()
                    os.fsync(self._file.fileno())
            except OSError as exc:
                self._failed(exc)
            finally:
                self._closed = True
                self._release()
        if self.failure is not None and not failed_before:
            raise LogError(f"log {self.path}: cannot finish writing: {self.failure}")

    def _release(self) -> None:
        """Close the file, cut at its length: the reserve beyond it is freed."""
        try:
            self._file.close()
        except OSError as exc:
            self._failed(exc)
        self._reserve.release()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def _space_hint(exc: OSError, path: Path, need: int) -> str:
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return f" (a run needs about {need // 1024} KiB free on {path.parent}; nothing was sent)"
    return " (nothing was sent)"


class DiskReserve:
    """Disk space held for a file beyond its end (Linux fallocate with FALLOC_FL_KEEP_SIZE).

    The file's size is unchanged, so a linear reader of a crashed run's log finds its last
    record at the end, not zeros. `supported` is False where the system or the file system
    cannot reserve: then nothing is reserved and writes themselves find a full disk. It keeps
    its own descriptor of the file, to free the rest once the file is closed.
    """

    KEEP_SIZE = 1  # FALLOC_FL_KEEP_SIZE
    UNSUPPORTED = frozenset({errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL, errno.ENODEV})

    def __init__(self, fd: int) -> None:
        self.end = 0  # the file's bytes below this offset are held on the disk
        self._fallocate = _fallocate_function()
        self._fd = -1
        if self._fallocate is not None:
            try:
                self._fd = os.dup(fd)
            except OSError:
                self._fallocate = None  # no descriptor to spare: run unreserved

    @property
    def supported(self) -> bool:
        return self._fallocate is not None

    def extend_to(self, end: int) -> None:
        """Hold the disk space up to `end`; OSError (ENOSPC, EDQUOT) if the disk has not got it."""
        if self._fallocate is None or end <= self.end:  # not supported, or held already
            return
        if self._fallocate(self._fd, self.KEEP_SIZE, self.end, end - self.end) != 0:
            import ctypes

            code = ctypes.get_errno()
            if code not in self.UNSUPPORTED:
                raise OSError(code, os.strerror(code))
            self._fallocate = None  # not supported here after all
            return
        self.end = end

    def release(self) -> None:
        """Free what is held beyond the file's end (a truncate to its own length). Once only."""
        if self._fd < 0:
            return
        try:
            if self.end:
                os.ftruncate(self._fd, os.fstat(self._fd).st_size)
        except OSError:
            pass  # nothing more can be done: the space is freed when the file is removed
        finally:
            os.close(self._fd)
            self._fd = -1
            self.end = 0


def _fallocate_function() -> Callable[[int, int, int, int], int] | None:
    """libc's fallocate, or None where there is none (not Linux, no ctypes)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        function = getattr(libc, "fallocate64", None) or libc.fallocate
    except (ImportError, OSError, AttributeError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int64, ctypes.c_int64]
    function.restype = ctypes.c_int
    return function


def _create_exclusive(path: Path, unique: bool = False) -> tuple[IO[bytes], Path]:
    """Create the log file, never overwriting one; with `unique`, a taken name gets -2, -3..."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a file where a folder should be is a FileExistsError too
        raise LogError(f"log {path}: cannot create its folder {path.parent}: "
                       f"{exc.strerror or exc}") from None
    candidates = [path] + ([path.with_name(f"{path.stem}-{n}{path.suffix}") for n in range(2, 100)]
                           if unique else [])
    for candidate in candidates:
        try:
            return open(candidate, "xb"), candidate
        except FileExistsError:
            continue
        except OSError as exc:
            raise LogError(f"log {candidate}: cannot create: {exc.strerror or exc}") from None
    raise LogError(f"log {path}: already exists: choreo never overwrites a log; "
                   "give another --log path or remove that file")
