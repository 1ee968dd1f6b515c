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
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import socket
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone
from importlib import resources
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from mcap.writer import CompressionType, Writer

from choreo import __version__
from choreo.errors import LogError

if TYPE_CHECKING:
    from choreo.link import RxEvent, TxEvent
    from choreo.runner import StepEvent

TX_TOPIC = "/rcb4/tx"
RX_TOPIC = "/rcb4/rx"
STEP_TOPIC = "/choreo/step"
LOG_TOPIC = "/choreo/log"

# topic -> (schema name, schema file under schemas/)
CHANNELS = {
    TX_TOPIC: ("choreo.Tx", "log.tx.schema.json"),
    RX_TOPIC: ("choreo.Rx", "log.rx.schema.json"),
    STEP_TOPIC: ("choreo.Step", "log.step.schema.json"),
    LOG_TOPIC: ("foxglove.Log", "foxglove.Log.schema.json"),
}

METADATA_NAME = "choreo"
RESULT_METADATA_NAME = "choreo.result"
FLUSH_EVERY_S = 0.5
BATCH = 16  # messages the background flusher writes before it lets the runner have the GIL
CHUNK_SIZE = 64 * 1024

# foxglove.Log levels
DEBUG, INFO, WARNING, ERROR, FATAL = 1, 2, 3, 4, 5


def default_log_path(show_name: str, directory: str | Path = "runs", now: datetime | None = None) -> Path:
    """`runs/<show name>-<UTC time>.mcap`, a name that sorts by time and never repeats a run's."""
    now = now or datetime.now(timezone.utc)
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in show_name) or "show"
    return Path(directory) / f"{safe}-{now.strftime('%Y%m%dT%H%M%SZ')}.mcap"


def schema_text(filename: str) -> bytes:
    return (resources.files("choreo.schemas") / filename).read_bytes()


@dataclass(frozen=True)
class RunInfo:
    """What the log's `choreo` metadata says about the run."""

    show_path: str
    show_name: str
    show_source: bytes
    port: str
    baud: int
    start_ns: int
    layout: str = "seed"

    def metadata(self) -> dict[str, str]:
        return {
            "version": __version__,
            "show": self.show_name,
            "show_path": self.show_path,
            "show_sha256": hashlib.sha256(self.show_source).hexdigest(),
            "port": self.port,
            "baud": str(self.baud),
            "layout": self.layout,
            "start_time": _iso(self.start_ns),
            "start_ns": str(self.start_ns),
            "host": socket.gethostname(),
            "python": platform.python_version(),
            "platform": sys.platform,
        }


def _iso(ns: int) -> str:
    return datetime.fromtimestamp(ns / 1e9, timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


# One encoder for every message: json.dumps with non-default separators builds a new encoder on
# each call, a third of the cost of serialising a frame.
_encode = json.JSONEncoder(separators=(",", ":")).encode


def _dumps(message: dict) -> bytes:
    return _encode(message).encode()


def _tx_message(event: TxEvent) -> dict:
    tag = event.tag
    return {
        "seq": event.seq,
        "step": tag.step if tag else None,
        "label": tag.label if tag else None,
        "kind": event.frame.kind.value,
        "motion": event.frame.motion,
        "attempt": event.attempt,
        "hex": event.frame.hex,
    }


def _rx_message(event: RxEvent) -> dict:
    reply = event.reply
    return {
        "seq": event.seq,
        "kind": reply.kind.value,
        "hex": reply.hex,
        "latency_ms": round(event.latency_s * 1e3, 4),
        "executing": reply.executing,
        "error": reply.error,
        "stale": reply.stale.hex(" ") if reply.stale else None,
    }


def _step_message(event: StepEvent) -> dict:
    return event.message()


def _log_message(entry: tuple[int, str, int]) -> dict:
    level, message, time_ns = entry
    return {
        "timestamp": {"sec": time_ns // 1_000_000_000, "nsec": time_ns % 1_000_000_000},
        "level": level,
        "message": message,
        "name": "choreo",
        "file": "",
        "line": 0,
    }


# A reported event waiting to be written: (topic, log time, how to make its message, the event).
_Pending = tuple[str, int, Callable[[Any], dict], Any]


class Recorder:
    """Writes one run's MCAP log; a LinkListener and a runner listener at once."""

    def __init__(self, path: str | Path, info: RunInfo, *, flush_every_s: float = FLUSH_EVERY_S,
                 unique: bool = False) -> None:
        self._file, self.path = _create_exclusive(Path(path), unique)
        self.failure: str | None = None  # why the file could not be written, once it could not
        self._lock = threading.Lock()
        self._dirty = False
        self._closed = False
        self._pending: deque[_Pending] = deque()  # appended by reporters, drained under the lock
        self._flush_every_s = flush_every_s
        self._flushed = time.monotonic()
        self._written = 0  # messages added to the file so far (their MCAP sequence numbers)
        try:
            self._writer = Writer(self._file, chunk_size=CHUNK_SIZE, compression=CompressionType.NONE)
            self._writer.start(profile="", library=f"choreo {__version__}")
            self._channels = {topic: self._register(topic, *spec) for topic, spec in CHANNELS.items()}
            self._writer.add_metadata(METADATA_NAME, info.metadata())
            self._writer.add_attachment(
                create_time=info.start_ns, log_time=info.start_ns,
                name=Path(info.show_path).name, media_type="application/yaml", data=info.show_source,
            )
            self._writer.flush()
            self._file.flush()
        except OSError as exc:
            self._file.close()
            raise LogError(f"log {self.path}: cannot write: {exc.strerror or exc}") from None
        self._stop = threading.Event()
        self._flusher = threading.Thread(target=self._flush_loop, args=(flush_every_s,),
                                         name="choreo-log-flush", daemon=True)
        self._flusher.start()

    def _register(self, topic: str, schema_name: str, filename: str) -> int:
        schema_id = self._writer.register_schema(name=schema_name, encoding="jsonschema",
                                                 data=schema_text(filename))
        return self._writer.register_channel(topic=topic, message_encoding="json", schema_id=schema_id)

    @property
    def messages(self) -> int:
        """Messages reported so far, written or still queued."""
        return self._written + len(self._pending)

    # -- listeners -------------------------------------------------------------------------

    def on_tx(self, event: TxEvent) -> None:
        """Queued only: the frame has not been written yet (see the module's docstring)."""
        self._pending.append((TX_TOPIC, event.time_ns, _tx_message, event))

    def on_rx(self, event: RxEvent) -> None:
        """Queued only: the next frame may be due right after this reply."""
        self._pending.append((RX_TOPIC, event.time_ns, _rx_message, event))

    def on_step(self, event: StepEvent) -> None:
        """Queued only: a step's start comes just before its first frame."""
        self._pending.append((STEP_TOPIC, event.time_ns, _step_message, event))

    def on_log(self, level: int, message: str, time_ns: int | None = None) -> None:
        """Queued only: a late-cue warning comes just before the cue's first frame."""
        time_ns = time.time_ns() if time_ns is None else time_ns
        self._pending.append((LOG_TOPIC, time_ns, _log_message, (level, message, time_ns)))

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

    # -- durability ------------------------------------------------------------------------

    def on_idle(self) -> None:
        """The runner has time to spare (it is about to sleep): write what is queued, and
        hand the file to the OS if the last time was a while ago.

        A log that can no longer be written stops the run here (LogError): a run is recorded or
        it does not go on, as a log that cannot be opened stops it before the robot moves.
        """
        with self._lock:
            if not self._closed:
                self._write_pending()
                if time.monotonic() - self._flushed >= self._flush_every_s / 2:
                    self._flush_locked()
        if self.failure is not None:
            raise LogError(f"log {self.path}: cannot write: {self.failure}: the run was stopped")

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
        if not self._dirty or self.failure is not None:
            return
        try:
            self._writer.flush()
        except OSError as exc:
            self._failed(exc)
            return
        self._dirty = False

    def _failed(self, exc: OSError) -> None:
        if self.failure is None:
            self.failure = exc.strerror or str(exc)
        self._pending.clear()

    def close(self, result: dict[str, str] | None = None) -> None:
        """Finish the file (summary, indexes, footer). Safe to call twice.

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
                        self._writer.add_metadata(RESULT_METADATA_NAME, result)
                    self._writer.finish()
                    self._file.flush()
                    os.fsync(self._file.fileno())
            except OSError as exc:
                self._failed(exc)
            finally:
                self._closed = True
                try:
                    self._file.close()
                except OSError as exc:
                    self._failed(exc)
        if self.failure is not None and not failed_before:
            raise LogError(f"log {self.path}: cannot finish writing: {self.failure}")

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


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
