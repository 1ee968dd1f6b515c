"""Reads a run log front to back: fast, in bounded memory, and whole up to where a killed run cut it.

The mcap library's default reader seeks through the summary at the end of the file: a log whose
run was SIGKILLed has no summary and no footer, and the file may stop in the middle of a record.
Reviewing such a run is exactly when a reviewer needs the log most, so this reader is linear:
it walks the records in file order, yields every message that survived, and when the bytes run
out it records *where* and *why* (`LogReader.cut`) instead of raising.

It parses the MCAP framing itself (opcode byte + uint64 length; a chunk holds schema, channel and
message records) with `struct.unpack_from` over one chunk's bytes at a time, so memory is one
chunk whatever the log's size, and a message costs a couple of slices rather than the handful of
small reads and a dataclass the generic reader spends on it. Messages come out as plain tuples
`(topic, log_time_ns, data)`; `decode` turns the JSON data into a dict only where a command needs
the fields.

A chunk whose records do not match its CRC (a disk or a copy damaged the file after the run wrote
it) is treated like a cut: the messages before it are intact and are reviewed, and `cut` says
which chunk is damaged (`Cut.damaged`). Reading past it would mix trusted and untrusted bytes,
and a reviewer would rather see less than see a wrong reply.

Spec: https://mcap.dev/spec (records used here: Header, Footer, Schema, Channel, Message, Chunk,
Attachment, Metadata, Data End; everything else is skipped, as the spec allows).
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Collection, Generator, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from choreo.errors import InputError, LogError
from choreo.log.format import (CHOREO_TOPICS, CLOCK_TOPIC, METADATA_NAME, RESULT_METADATA_NAME, SHOW_MEDIA_TYPE,
                               METADATA_RECORDS_KEPT, base_topic, clock_topic, kept_metadata, LoggedRun)
from choreo.userfile import open_input, reading

MAGIC = b"\x89MCAP0\r\n"
LOG_WHAT = "run log"  # what a file given as a log should be, in messages

OP_HEADER = 0x01
OP_FOOTER = 0x02
OP_SCHEMA = 0x03
OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
OP_ATTACHMENT = 0x09
OP_METADATA = 0x0C
OP_DATA_END = 0x0F
ATTACHMENTS_KEPT = 64  # attachments a review keeps the description of (choreo attaches one: the show)

RECORD_HEAD = struct.Struct("<BQ")  # opcode, length of what follows
# A message record inside a chunk, up to its data: opcode, length, channel id, sequence, log time.
MESSAGE_HEAD = struct.Struct("<BQHIQ")
MESSAGE_HEAD_SIZE = MESSAGE_HEAD.size + 8  # + publish time, then the data
CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression length
FOOTER_SIZE = 1 + 8 + 20  # opcode, length, summary start, summary offset start, crc

# A message as the reader yields it: topic, log time (wall-clock ns), JSON bytes.
Message = tuple[str, int, bytes]





@dataclass(frozen=True)
class Cut:
    """Where an unfinished or damaged log stops, and why: what a reviewer of a killed run needs to know."""

    offset: int  # bytes of the file that could be read
    size: int  # the file's size
    reason: str
    damaged: bool = False  # the file goes on, but a record in it is corrupt (a CRC mismatch)

    @property
    def state(self) -> str:
        """One word for a status line: the log is `unfinished` (killed run) or `damaged`."""
        return "damaged" if self.damaged else "unfinished"

    def __str__(self) -> str:
        if self.offset >= self.size:
            return f"{self.reason} (after {self.size:,} bytes)"
        return f"{self.reason} (readable up to byte {self.offset:,} of {self.size:,})"


@dataclass(frozen=True)
class Channel:
    id: int
    topic: str
    message_encoding: str
    schema_name: str


@dataclass(frozen=True)
class Attachment:
    """An attachment's description; its bytes are read on demand (`LogReader.attachment_data`)."""

    name: str
    media_type: str
    log_time: int
    offset: int  # where its data starts in the file
    size: int


class LogReader:
    """One run log, read linearly.

    Opening reads the head of the file (header, the run's `choreo` metadata, the attached show)
    and stops before the first message, so a command can print what run it is looking at
    before it streams the rest. `messages()` then walks to the end; after it, `cut`, `footer`,
    `metadata` (with `choreo.result` for a finished run) and `complete` say how the log ended.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.library = ""
        self.profile = ""
        self.metadata: dict[str, dict[str, str]] = {}  # bounded as reviews keep it (format.kept_metadata)
        self.metadata_notes: dict[str, list[str]] = {}  # what the bounds left out, by record
        self.attachments: list[Attachment] = []
        self._attached: set[int] = set()  # where each attachment seen starts
        self.channels: dict[int, Channel] = {}
        self.cut: Cut | None = None
        self.footer = False  # Data End, the footer and the closing magic are all there
        self.messages_read = 0
        self._schemas: dict[int, str] = {}
        self._data_start = 0
        self._head_cut: Cut | None = None  # a damaged record before the first message
        self._file: IO[bytes] | None = None
        try:
            self._file = open_input(self.path, LOG_WHAT)  # a pipe, a device, a loop: one line
        except InputError as exc:
            raise self._fail(exc.reason) from None
        try:
            self._size = os.fstat(self._file.fileno()).st_size
            with reading(self.path, LOG_WHAT):
                self._read_head()
        except BaseException:
            self.close()
            raise

    # -- what the log says about its run ---------------------------------------------------

    @property
    def run_info(self) -> dict[str, str]:
        """The `choreo` metadata: show, port, baud, start time... (empty if the log has none)."""
        return self.metadata.get(METADATA_NAME, {})

    @property
    def run_notes(self) -> list[str]:
        """What a review keeps not of a hostile log's `choreo` metadata (its bounds), to say so."""
        return self.metadata_notes.get(METADATA_NAME, [])

    @property
    def info(self) -> LoggedRun:
        """The `choreo` metadata as typed values."""
        return LoggedRun(self.run_info)

    @property
    def robots(self) -> list[str]:
        """The robots of a show for several, in the show's order (empty for a one-robot log)."""
        return self.info.robots

    @property
    def result(self) -> dict[str, str] | None:
        """The `choreo.result` metadata written when the run closed its log, or None."""
        return self.metadata.get(RESULT_METADATA_NAME)

    @property
    def complete(self) -> bool:
        """Closed properly by its run: the run's result is recorded and the MCAP footer is there."""
        return self.footer and self.result is not None and self.cut is None

    def show_attachment(self) -> Attachment | None:
        """The show file the run played (attached as application/yaml), if the log has it."""
        return next((a for a in self.attachments if a.media_type == SHOW_MEDIA_TYPE), None)

    def attachment_data(self, attachment: Attachment) -> bytes:
        """An attachment's bytes (read now: a log's attachments never sit in memory unasked)."""
        with open_input(self.path, LOG_WHAT) as f, reading(self.path, f"attachment {attachment.name} of the run log"):
            f.seek(attachment.offset)
            return f.read(attachment.size)

    def show_source(self) -> bytes | None:
        attachment = self.show_attachment()
        return self.attachment_data(attachment) if attachment else None

    def topic_of(self, channel_id: int) -> str | None:
        channel = self.channels.get(channel_id)
        return channel.topic if channel else None

    # -- opening and closing ---------------------------------------------------------------

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> LogReader:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def not_choreo(self, topic: str | None, number: int, exc: BaseException) -> LogError:
        """A message whose fields are not what choreo writes: say which one, not a traceback."""
        detail = f"missing field {exc}" if isinstance(exc, KeyError) else str(exc) or type(exc).__name__
        return self._fail(f"message {number} on {topic or '?'} is not a choreo {topic or ''} message "
                          f"({detail}): was this log written by choreo run?")

    def _fail(self, what: str) -> LogError:
        return LogError(f"log {self.path}: {what}")

    def _read_head(self) -> None:
        """Magic, header, and every record before the first message (metadata, attachments).

        A file without a whole Header record after the magic is not a log, not a cut one: the
        recorder writes the header, the show and the metadata before the first frame, so even a
        run killed at once leaves more than that. Reporting it as an "unfinished run" would send
        a user looking for a run that never was.
        """
        f = self._file
        assert f is not None
        magic = f.read(len(MAGIC))
        if magic != MAGIC and not (len(magic) < len(MAGIC) and MAGIC.startswith(magic)):
            raise self._fail("not an MCAP file (it does not start with the MCAP magic bytes); "
                             "choreo logs are the .mcap files `choreo run` writes")
        head = f.read(RECORD_HEAD.size)
        if len(magic) < len(MAGIC) or len(head) < RECORD_HEAD.size:
            raise self._too_short()
        opcode, length = RECORD_HEAD.unpack(head)
        if opcode != OP_HEADER:
            raise self._fail(f"not an MCAP file (the MCAP magic is not followed by a header record, "
                             f"but by opcode 0x{opcode:02x}); choreo logs are the .mcap files "
                             "`choreo run` writes")
        if length > self._size - len(MAGIC) - RECORD_HEAD.size:
            raise self._too_short()
        try:
            self._top_level(opcode, f.read(length), len(MAGIC))
        except (struct.error, ValueError, IndexError):
            raise self._fail(f"damaged: its MCAP header record (byte {len(MAGIC)}) cannot be read, so "
                             "nothing in it can be trusted; it is not a log that can be reviewed") from None
        while True:
            start = f.tell()
            head = f.read(RECORD_HEAD.size)
            if len(head) < RECORD_HEAD.size:
                self._data_start = start
                return  # the message loop reports the cut
            opcode, length = RECORD_HEAD.unpack(head)
            if opcode in (OP_CHUNK, OP_MESSAGE, OP_DATA_END, OP_FOOTER) or length > self._size - start - 9:
                self._data_start = start
                return
            body = f.read(length)
            try:
                self._top_level(opcode, body, start)
            except (struct.error, ValueError, IndexError) as exc:
                self._head_damaged(opcode, start, length, exc)
                return

    def _head_damaged(self, opcode: int, start: int, length: int, exc: Exception) -> None:
        """A record before the first message does not hold what its header says: the records
        after it cannot be found, so the read stops there, as at a damaged chunk."""
        what = {OP_METADATA: "metadata record", OP_ATTACHMENT: "attachment", OP_SCHEMA: "schema",
                OP_CHANNEL: "channel"}.get(opcode, f"record (opcode 0x{opcode:02x})")
        self._head_cut = Cut(start, self._size, f"the {what} at byte {start:,} is damaged ({exc or 'too short'}, "
                             f"{length} bytes): the file changed after the run wrote it; nothing after "
                             "it is read", damaged=True)

    def _check_choreo(self) -> None:
        """After a whole read: an MCAP with neither choreo's run metadata nor any of choreo's
        topics was written by another tool. Reviewing it would report an empty run (exit 0)."""
        if self.run_info or self.cut is not None or self.library.startswith("choreo"):
            return  # a choreo log, perhaps cut or damaged before its metadata
        if any(base_topic(channel.topic) in CHOREO_TOPICS for channel in self.channels.values()):
            return
        topics = ", ".join(sorted({c.topic for c in self.channels.values()})[:4]) or "none"
        raise self._fail(f"not a choreo log: an MCAP file without choreo's run metadata or topics "
                         f"(its topics: {topics}; written by {self.library or 'another tool'!r}); "
                         "choreo reviews the .mcap files `choreo run` writes")

    def _too_short(self) -> LogError:
        if not self._size:
            return self._fail("not an MCAP file (empty)")
        return self._fail(f"not an MCAP file (only {self._size} bytes: too short to hold an MCAP header; "
                          "a `choreo run` log starts with its header, metadata and show)")

    def _top_level(self, opcode: int, body: bytes, start: int) -> None:
        """A record outside chunks other than a message: note what a review needs from it."""
        if opcode == OP_HEADER:
            self.profile, pos = _string(body, 0)
            self.library, _ = _string(body, pos)
        elif opcode == OP_METADATA:
            name, pos = _string(body, 0)
            if name in (METADATA_NAME, RESULT_METADATA_NAME) or len(self.metadata) < METADATA_RECORDS_KEPT:
                self.metadata[name], self.metadata_notes[name] = kept_metadata(name, _string_map(body, pos)[0])
        elif opcode == OP_ATTACHMENT:
            pos = 16
            name, pos = _string(body, pos)
            media_type, pos = _string(body, pos)
            (size,) = struct.unpack_from("<Q", body, pos)
            if pos + 8 + size > len(body):
                raise ValueError(f"its data size {size:,} is more than the record holds")
            self._attach(Attachment(name, media_type, struct.unpack_from("<Q", body, 0)[0], start + 9 + pos + 8, size))
        elif opcode == OP_SCHEMA:
            self._schema(body, 0)
        elif opcode == OP_CHANNEL:
            self._channel(body, 0)

    def _attach(self, attachment: Attachment) -> None:
        """An attachment's description, kept once (a second pass over the log meets it again; a
        list searched for each made a hostile log's 20,000 attachments cost minutes) and at most
        ATTACHMENTS_KEPT of them, the show a review needs besides."""
        if attachment.offset in self._attached:
            return
        self._attached.add(attachment.offset)
        show = attachment.media_type == SHOW_MEDIA_TYPE and self.show_attachment() is None
        if show or len(self.attachments) < ATTACHMENTS_KEPT:
            self.attachments.append(attachment)

    def _schema(self, buf: bytes, pos: int) -> None:
        (schema_id,) = struct.unpack_from("<H", buf, pos)
        self._schemas[schema_id] = _string(buf, pos + 2)[0]

    def _channel(self, buf: bytes, pos: int) -> None:
        channel_id, schema_id = struct.unpack_from("<HH", buf, pos)
        topic, pos = _string(buf, pos + 4)
        encoding, pos = _string(buf, pos)
        self.channels[channel_id] = Channel(channel_id, topic, encoding, self._schemas.get(schema_id, ""))

    # -- the messages ----------------------------------------------------------------------

    def messages(self, topics: Collection[str] | None = None) -> Generator[Message, None, None]:
        """Every message in file order (the order the run wrote them) as (topic, log_time, data).

        `topics` limits it to those topics (the others are skipped without copying). Ends
        quietly at the end of the file; `cut` then says whether and where it was cut short.
        Calling it again starts over. A file that turns out not to be a choreo log at all is a
        LogError at the end.
        """
        with reading(self.path, LOG_WHAT):  # a disk error mid-log: "cannot read the run log"
            yield from self._messages(topics)
        self._check_choreo()

    def _messages(self, topics: Collection[str] | None) -> Iterator[Message]:
        f = self._file
        if f is None:
            raise self._fail("the log is closed")
        self.cut, self.footer, self.messages_read = self._head_cut, False, 0
        if self._head_cut is not None:
            return  # the records before the first message are damaged: none can be found
        f.seek(self._data_start)
        read = f.read
        size = self._size
        head_size = RECORD_HEAD.size
        unpack_head = RECORD_HEAD.unpack
        wanted = None if topics is None else frozenset(topics)
        routes: dict[int, str | None] = {}  # channel id -> topic, or None if not wanted
        count = 0
        try:
            while True:
                start = f.tell()
                # The log as it was when opened: a run still writing it makes it longer meanwhile
                # (a record past `size` would be read as a negative rest: a ValueError).
                head = read(min(head_size, max(size - start, 0)))
                if len(head) < head_size:
                    self._ended(start, head)
                    return
                opcode, length = unpack_head(head)
                if length > size - start - head_size:
                    found: Iterable[Message] = self._truncated(opcode, start, length, read(size - start - head_size),
                                                               routes, wanted)
                    last = True
                else:
                    found, last = self._record(opcode, start, length, read(length), routes, wanted)
                for message in found:
                    count += 1
                    yield message
                if last:
                    return
        finally:
            self.messages_read = count

    def _record(self, opcode: int, start: int, length: int, body: bytes, routes: dict[int, str | None],
                wanted: frozenset[str] | None) -> tuple[Iterable[Message], bool]:
        """One whole top-level record: the messages it holds (read lazily from a chunk), and
        whether it is the last record to read (the data's end, the footer, a damaged chunk)."""
        if opcode == OP_CHUNK:
            try:
                records, first, last = self._chunk_records(body, start)
            except _Damaged as exc:
                self.cut = Cut(start, self._size, str(exc), damaged=True)
                return (), True
            return self._in_chunk(records, first, last, routes, wanted), False
        if opcode == OP_MESSAGE:
            message = self._message(body, 0, length, routes, wanted)
            return ((message,) if message is not None else ()), False
        if opcode == OP_DATA_END:
            self._check_footer(start + RECORD_HEAD.size + length)
            return (), True
        if opcode == OP_FOOTER:
            self.footer = True
            return (), True
        self._top_level(opcode, body, start)
        return (), False

    def _route(self, channel_id: int, routes: dict[int, str | None],
               wanted: frozenset[str] | None) -> str | None:
        channel = self.channels.get(channel_id)
        # a robot's own topic (`/rcb4/left/tx`) reads as its kind; the record names the robot
        topic = base_topic(channel.topic) if channel else f"channel {channel_id}"
        if channel and topic == CLOCK_TOPIC and channel.topic != clock_topic(self.run_info):
            topic = channel.topic  # a merged log's other hosts' clocks: kept, but one clock times the show
        routes[channel_id] = topic if wanted is None or topic in wanted else None
        return routes[channel_id]

    def _in_chunk(self, buf: bytes, pos: int, end: int, routes: dict[int, str | None],
                  wanted: frozenset[str] | None) -> Iterator[Message]:
        """The messages of one chunk's records, `buf[pos:end]`; the hot loop of every command."""
        unpack = MESSAGE_HEAD.unpack_from
        unpack_head = RECORD_HEAD.unpack_from
        data_offset = MESSAGE_HEAD_SIZE
        fast_end = end - MESSAGE_HEAD.size  # where a full message head still fits
        while pos < end:
            if pos <= fast_end:
                opcode, length, channel_id, _, log_time = unpack(buf, pos)
            elif end - pos >= 9:
                opcode, length = unpack_head(buf, pos)
            else:
                return  # a record head cut short
            record_end = pos + 9 + length
            if record_end > end:
                return  # a record cut short (salvage of a truncated chunk): keep what was whole
            if opcode == OP_MESSAGE:
                try:
                    topic = routes[channel_id]
                except KeyError:
                    topic = self._route(channel_id, routes, wanted)
                if topic is not None:
                    yield topic, log_time, buf[pos + data_offset:record_end]
            elif opcode == OP_CHANNEL:
                self._channel(buf, pos + 9)
                routes.clear()
            elif opcode == OP_SCHEMA:
                self._schema(buf, pos + 9)
            pos = record_end

    def _message(self, buf: bytes, pos: int, length: int, routes: dict[int, str | None],
                 wanted: frozenset[str] | None) -> Message | None:
        """A message record outside any chunk (writers without chunking)."""
        channel_id, _, log_time = struct.unpack_from("<HIQ", buf, pos)
        topic = routes[channel_id] if channel_id in routes else self._route(channel_id, routes, wanted)
        if topic is None:
            return None
        return topic, log_time, buf[pos + 22:pos + length]

    def _chunk_records(self, body: bytes, start: int) -> tuple[bytes, int, int]:
        """The records of a whole chunk: the buffer, and where they start and end in it.

        Checked against the chunk's CRC where the writer gave one (0 means none): crc32 runs in
        C at gigabytes a second, a few percent of the time a message costs the commands.
        """
        try:
            _, _, uncompressed_size, crc, name_length = CHUNK_HEAD.unpack_from(body, 0)
            compression = body[CHUNK_HEAD.size:CHUNK_HEAD.size + name_length].decode()
            pos = CHUNK_HEAD.size + name_length
            (records_length,) = struct.unpack_from("<Q", body, pos)
        except (struct.error, UnicodeDecodeError):
            raise _Damaged(start, "its header does not parse") from None
        pos += 8
        end = pos + records_length
        if end > len(body):
            raise _Damaged(start, f"its records claim {records_length:,} bytes, the chunk holds "
                                  f"{len(body) - pos:,}")
        if not compression:
            data, first, last = body, pos, end
        else:
            try:
                data = self._decompress(compression, body[pos:end], uncompressed_size, start)
            except LogError:
                raise
            except Exception as exc:  # the compressors' own error types: the bytes are corrupt
                raise _Damaged(start, f"its {compression} data does not decompress ({exc})") from None
            first, last = 0, len(data)
        if crc:
            actual = zlib.crc32(memoryview(data)[first:last])
            if actual != crc:
                raise _Damaged(start, f"its CRC is 0x{crc:08x} but its records' is 0x{actual:08x}")
        return data, first, last

    def _decompress(self, compression: str, data: bytes, size: int, start: int) -> bytes:
        """zstd or lz4 chunks, with the libraries the mcap package uses, where installed."""
        if compression == "lz4":
            try:
                import lz4.frame
            except ImportError:
                raise self._fail(f"chunk at byte {start} is lz4-compressed: install lz4 "
                                 "(pip install lz4) to read it") from None
            return lz4.frame.decompress(data)
        if compression == "zstd":
            try:
                import zstandard
            except ImportError:
                raise self._fail(f"chunk at byte {start} is zstd-compressed: install zstandard "
                                 "(pip install zstandard) to read it") from None
            return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
        raise self._fail(f"chunk at byte {start} uses compression {compression!r}, which choreo "
                         "cannot read (it reads uncompressed, lz4 and zstd chunks)")

    # -- how the file ends -----------------------------------------------------------------

    def _ended(self, start: int, head: bytes) -> None:
        """The file ran out between records, or inside a record's 9-byte head."""
        if head:
            reason = "the file ends inside a record's header: the run stopped while writing its log"
        else:
            reason = ("the file ends without the log's closing records (no Data End, no footer): "
                      "the run did not close its log (killed, or still running)")
        self.cut = Cut(start, self._size, reason)

    def _truncated(self, opcode: int, start: int, length: int, partial: bytes,
                   routes: dict[int, str | None], wanted: frozenset[str] | None) -> list[Message]:
        """A record longer than what is left of the file: keep the whole messages of a cut chunk."""
        salvaged: list[Message] = []
        what = {OP_CHUNK: "a chunk", OP_MESSAGE: "a message", OP_ATTACHMENT: "an attachment",
                OP_METADATA: "a metadata record"}.get(opcode, f"a record (opcode 0x{opcode:02x})")
        have = len(partial)
        reason = (f"the file ends inside {what} ({have:,} of its {length:,} bytes): the run was "
                  "killed while writing its log")
        if opcode == OP_CHUNK and have >= CHUNK_HEAD.size:
            name_length = CHUNK_HEAD.unpack_from(partial, 0)[4]
            pos = CHUNK_HEAD.size + name_length + 8
            compressed = partial[CHUNK_HEAD.size:CHUNK_HEAD.size + name_length]
            if compressed:
                method = compressed.decode(errors="replace")
                reason += f"; the cut chunk is {method}-compressed, so its messages are lost"
            elif have > pos:
                salvaged = list(self._in_chunk(partial, pos, have, routes, wanted))
                if salvaged:
                    reason += f"; {len(salvaged)} whole messages read from the cut chunk"
        self.cut = Cut(start, self._size, reason)
        return salvaged

    def _check_footer(self, data_end: int) -> None:
        """After Data End comes the summary; the file must close with a footer and the magic."""
        f = self._file
        assert f is not None
        tail_at = self._size - FOOTER_SIZE - len(MAGIC)
        if tail_at < data_end:
            self.cut = Cut(data_end, self._size, "the file ends after the data section without a "
                           "footer: the run was killed while closing its log")
            return
        f.seek(tail_at)
        tail = f.read(FOOTER_SIZE + len(MAGIC))
        opcode, length = RECORD_HEAD.unpack_from(tail, 0)
        if opcode != OP_FOOTER or length != 20 or tail[-len(MAGIC):] != MAGIC:
            self.cut = Cut(data_end, self._size, "the file has no MCAP footer after its data: "
                           "the run was killed while closing its log")
            return
        self.footer = True


class _Damaged(Exception):
    """A chunk whose bytes are not the ones written: ends the read like a cut, saying which."""

    def __init__(self, start: int, detail: str) -> None:
        super().__init__(f"the chunk at byte {start:,} is damaged ({detail}): the file changed after "
                         "the run wrote it (disk or copy); what comes before that chunk is intact "
                         "and reviewed, nothing after it is read")


def _string(buf: bytes, pos: int) -> tuple[str, int]:
    (length,) = struct.unpack_from("<I", buf, pos)
    pos += 4
    return buf[pos:pos + length].decode("utf-8", errors="replace"), pos + length


def _string_map(buf: bytes, pos: int) -> tuple[dict[str, str], int]:
    (length,) = struct.unpack_from("<I", buf, pos)
    pos += 4
    end = pos + length
    out: dict[str, str] = {}
    while pos < end:
        key, pos = _string(buf, pos)
        out[key], pos = _string(buf, pos)
    return out, end


def open_log(path: str | Path) -> LogReader:
    """Open a run log for reading (LogError if it is missing or not MCAP)."""
    return LogReader(path)
