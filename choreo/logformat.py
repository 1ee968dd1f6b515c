"""The run log's format, in one place: topics, schemas, levels, the lateness rule, each message
as a typed record with its JSON form, and the motion tracker every review reads plays with.

The recorder writes records through `to_json`; every reader (summary, frames, timeline, export,
replay) gets them back through `parse`, so a field is named once, here, and a log choreo did not
write fails in one way (KeyError, TypeError or ValueError, which the reader turns into one line).
A logged frame's bytes mean what the board layout its robot ran with says (the metadata records
it, `LogLayouts`): `frame_meaning` and `reply_meaning` are the one way a review puts them in words.
JSON forms leave absent fields out: Foxglove's JSON-schema support takes one `type` per field
and refuses a topic whose schema allows null.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from functools import lru_cache
from dataclasses import MISSING, dataclass, field, fields
from typing import Any, ClassVar

from choreo import protocol as p
from choreo.layouts import DEFAULT_LAYOUT, LAYOUTS, Layout, layout_of_call

TX_TOPIC = "/rcb4/tx"
RX_TOPIC = "/rcb4/rx"
STEP_TOPIC = "/choreo/step"
LOG_TOPIC = "/choreo/log"
CLOCK_TOPIC = "/choreo/clock"
CLOCK_EVERY_S = 0.5  # how often (show time) /choreo/clock samples the show clock
COMMAND_TOPIC = "/choreo/command"
# topic -> (schema name, schema file under schemas/)
CHANNELS = {
    TX_TOPIC: ("choreo.Tx", "log.tx.schema.json"),
    RX_TOPIC: ("choreo.Rx", "log.rx.schema.json"),
    STEP_TOPIC: ("choreo.Step", "log.step.schema.json"),
    LOG_TOPIC: ("foxglove.Log", "foxglove.Log.schema.json"),
    CLOCK_TOPIC: ("choreo.Clock", "log.clock.schema.json"),
    COMMAND_TOPIC: ("choreo.Command", "log.command.schema.json"),
}
CHOREO_TOPICS = frozenset(CHANNELS)
PER_ROBOT = (TX_TOPIC, RX_TOPIC, STEP_TOPIC)  # split by robot in a show for several robots


def robot_topic(topic: str, robot: str | None) -> str:
    """A robot's own topic in a show for several robots: `/rcb4/tx` -> `/rcb4/left/tx` (Foxglove
    then plots and filters each robot on its own); a one-robot log keeps `/rcb4/tx`."""
    if robot is None or topic not in PER_ROBOT:
        return topic
    head, _, tail = topic.rpartition("/")
    return f"{head}/{robot}/{tail}"


def base_topic(topic: str) -> str:
    """`/rcb4/left/tx` -> `/rcb4/tx`: what kind of message a topic carries, whoever's it is."""
    parts = topic.split("/")
    if len(parts) == 4:
        joined = f"/{parts[1]}/{parts[3]}"
        if joined in PER_ROBOT:
            return joined
    return topic


def channels_for(robots: tuple[str, ...] = ()) -> dict[str, tuple[str, str]]:
    """Topic -> (schema name, schema file) of a log: the four topics, or with several robots
    each robot's tx/rx/step and the shared log."""
    if not robots:
        return dict(CHANNELS)
    split = {robot_topic(topic, robot): CHANNELS[topic] for robot in robots for topic in PER_ROBOT}
    shared = (LOG_TOPIC, CLOCK_TOPIC, COMMAND_TOPIC)
    return {**split, **{topic: CHANNELS[topic] for topic in shared}}
METADATA_NAME = "choreo"
RESULT_METADATA_NAME = "choreo.result"


def layout_key(robot: str | None) -> str:
    """The metadata key of a robot's board layout (`layout` in a one-robot log)."""
    return "layout" if robot is None else f"robot.{robot}.layout"

DEBUG, INFO, WARNING, ERROR, FATAL = 1, 2, 3, 4, 5  # foxglove.Log levels
ABORT_LABEL = "on_abort"  # the label of the abort motion's frames (they belong to no step)

# A play is late when it starts more than this after its time, or when retries delay the play
# sequence that worked by more than this (the step's end event says by how much).
LATE_MS = 1.0


@lru_cache(maxsize=None)
def _field_names(cls: type) -> tuple[str, ...]:
    """A record type's field names, worked out once (the recorder serialises every frame)."""
    return tuple(f.name for f in fields(cls))  # type: ignore[arg-type]


class _Record:
    """JSON form of a dataclass record: absent fields omitted, required ones checked on read."""

    topic: ClassVar[str]

    def to_json(self) -> dict:
        values = (getattr(self, name) for name in _field_names(type(self)))
        return {name: value for name, value in zip(_field_names(type(self)), values) if value is not None}

    @classmethod
    def from_json(cls, message: Any) -> Any:
        if not isinstance(message, dict):
            raise TypeError(f"a JSON object, not {type(message).__name__}")
        try:
            return cls(**message)  # what choreo wrote: exactly the record's fields (the fast path)
        except TypeError:
            pass  # a field missing, or one from another version of choreo: field by field
        given = {}
        for f in fields(cls):  # type: ignore[arg-type]
            if f.name in message:
                given[f.name] = message[f.name]
            elif f.default is MISSING and f.default_factory is MISSING:
                raise KeyError(f.name)
        return cls(**given)

    @classmethod
    def partial(cls, message: Any) -> Any:
        """As far as the message goes: a missing field is blank (0, "") instead of an error, for
        the views that show a log as it is (`log frames`, `log export`) even when another tool
        wrote part of it; the reviews that count (summary, timeline) use `from_json`."""
        if not isinstance(message, dict):
            raise TypeError(f"a JSON object, not {type(message).__name__}")
        given = {}
        for f in fields(cls):  # type: ignore[arg-type]
            if f.name in message:
                given[f.name] = message[f.name]
            elif f.default is MISSING and f.default_factory is MISSING:
                given[f.name] = _BLANK[f.type]  # type: ignore[index]
        return cls(**given)


_BLANK = {"int": 0, "float": 0.0, "str": ""}  # a required field's blank, by its annotation


@dataclass(frozen=True, slots=True)
class TxRecord(_Record):
    """A frame sent: its sequence number, kind (stop, play, restore, status...), bytes as hex."""

    topic: ClassVar[str] = TX_TOPIC
    seq: int
    kind: str
    hex: str
    attempt: int = 1
    step: int | None = None
    label: str | None = None
    motion: int | None = None
    robot: str | None = None  # whose frame, in a show for several robots


@dataclass(frozen=True, slots=True)
class RxRecord(_Record):
    """The verdict on what came back for frame `seq`: ack, nak, status, timeout or invalid."""

    topic: ClassVar[str] = RX_TOPIC
    seq: int
    kind: str
    hex: str = ""
    latency_ms: float = 0.0
    executing: bool | None = None
    error: str | None = None
    stale: str | None = None  # late replies to earlier frames, set aside, as hex
    robot: str | None = None  # whose reply, in a show for several robots

    @property
    def answered(self) -> bool:
        """The board answered the frame as it should (an ACK or a status)."""
        return self.kind in ("ack", "status")


@dataclass(frozen=True, slots=True)
class StepRecord(_Record):
    """A step starting or ending, on the show clock (seconds since the show started)."""

    topic: ClassVar[str] = STEP_TOPIC
    index: int
    kind: str
    event: str  # start | end
    actual_s: float
    planned_s: float = 0.0  # when it was due at run time
    estimated_s: float = 0.0  # where the compiled plan put it
    late_ms: float = 0.0  # start: how late it started; end of a play: how late its motion began
    path: str = ""
    label: str | None = None
    motion: int | None = None
    cue: float | None = None
    outcome: str | None = None  # end: ok | failed | aborted | timeout
    robot: str | None = None  # whose step, in a show for several robots
    start_s: float | None = None  # end of a play: when the frame that started the motion was written
    lead_ms: float | None = None  # end of a cued play: how far ahead of its cue the first frame was due
    go: bool | None = None  # a GO cue (`at: go`): it waited for the operator's GO

    @property
    def ref(self) -> str:
        """`step 4 'spin'`."""
        return f"step {self.index}" + (f" '{self.label}'" if self.label else "")


@dataclass(frozen=True, slots=True)
class LogRecord(_Record):
    """A log line (foxglove.Log): level, message, and its time."""

    topic: ClassVar[str] = LOG_TOPIC
    level: int
    message: str
    timestamp: dict = field(default_factory=dict)
    name: str = "choreo"
    file: str = ""
    line: int = 0

    @classmethod
    def at(cls, level: int, message: str, time_ns: int) -> LogRecord:
        return cls(level, message, {"sec": time_ns // 1_000_000_000, "nsec": time_ns % 1_000_000_000})

    def to_json(self) -> dict:
        return {"timestamp": self.timestamp, "level": self.level, "message": self.message,
                "name": self.name, "file": self.file, "line": self.line}


@dataclass(frozen=True, slots=True)
class ClockRecord(_Record):
    """The show clock against the machine's monotonic clock (CLOCK_MONOTONIC on Linux), sampled
    every half second: any other recording made on the machine lines up with the show by it.
    On the music's clock the two drift apart as the sound card's crystal does."""

    topic: ClassVar[str] = CLOCK_TOPIC
    show_s: float
    monotonic_ns: int
    source: str = "machine"  # machine | music: what keeps the show clock


@dataclass(frozen=True, slots=True)
class CommandRecord(_Record):
    """An operator's command (GO, panic, start, stop, a cue's GO), where it came from (`key`,
    `osc udp 127.0.0.1:53001`), and what it did: a review shows who pressed what and when."""

    topic: ClassVar[str] = COMMAND_TOPIC
    command: str
    source: str
    status: str  # ok | error | denied (a sender not allowed)
    message: str = ""
    label: str | None = None  # a cue's GO: which cue; unknown or refused: the OSC address
    show_s: float | None = None  # the show clock when it came (absent before the show started)
    count: int | None = None  # `unlogged`: how many commands it sums up (absent: this one)
    counts: dict | None = None  # `unlogged`: those commands by name (go, refused, unknown...)

    @property
    def commands(self) -> int:
        """How many commands the record stands for: a summary's count, else one (ValueError:
        a count that is no count, in a log another program wrote)."""
        if self.count is None:
            return 1
        if type(self.count) is not int or self.count < 1:
            raise ValueError(f"count {self.count!r} is not a number of commands")
        return self.count

    @property
    def refused(self) -> int:
        """How many of them were not carried out (a summary holds refused ones only)."""
        return self.commands if self.count is not None or self.status != "ok" else 0


Record = TxRecord | RxRecord | StepRecord | LogRecord | ClockRecord | CommandRecord
RECORD_TYPES: dict[str, type] = {TX_TOPIC: TxRecord, RX_TOPIC: RxRecord, STEP_TOPIC: StepRecord,
                                 LOG_TOPIC: LogRecord, CLOCK_TOPIC: ClockRecord, COMMAND_TOPIC: CommandRecord}


_scan_once = json.JSONDecoder().scan_once


def decode(data: bytes) -> dict:
    """A message's JSON as a dict.

    Calls the C scanner directly: `json.loads` spends more than half its time on encoding
    detection and whitespace checks that a recorder-written message never needs. Anything the
    scanner does not take (leading whitespace, bad JSON) goes through `json.loads`, whose error
    is the one to report.
    """
    try:
        return _scan_once(data.decode(), 0)[0]
    except (StopIteration, ValueError, UnicodeDecodeError):
        return json.loads(data)


def parse(topic: str, data: bytes, partial: bool = False) -> Record:
    """A message of a choreo topic as its record (ValueError, KeyError or TypeError if it is not
    one; `partial`: missing fields blank, see `_Record.partial`)."""
    kind = RECORD_TYPES[topic]
    return kind.partial(decode(data)) if partial else kind.from_json(decode(data))


def is_late(start: StepRecord) -> bool:
    """A play that started late (only a play's lateness shows on stage: a wait starts when the
    play before it is answered)."""
    return start.kind == "play" and start.late_ms > LATE_MS


def slipped(end: StepRecord, late_at_start: bool) -> bool:
    """A play on time at its start whose retries delayed its motion past LATE_MS (the runner
    says so in the play's end event). A play late at its start is counted there: never twice."""
    return end.kind == "play" and end.outcome == "ok" and not late_at_start and end.late_ms > LATE_MS


# -- motions -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class MotionPlay:
    """One play of a motion as the wire shows it (log times, wall-clock ns)."""

    motion: int | None
    step: int | None
    label: str | None
    start_ns: int | None  # the restore frame that started it; None: it never started
    end_ns: int | None
    ended_by: str  # status | stop | end of log | not started

    @property
    def measured(self) -> bool:
        """A status query saw it end: `end_ns` is its end (to within the 50 ms poll)."""
        return self.ended_by == "status"


@dataclass
class _Armed:
    motion: int | None
    step: int | None
    label: str | None
    start_ns: int | None = None  # the restore of the try in progress
    restore_seq: int | None = None


class MotionTracker:
    """Which motion runs when, from the frames and replies alone.

    A play frame (the CALL) arms a motion; the ACK to the restore after it starts it, at the
    restore's time. A retry of the same step's sequence re-arms it; an armed play that never got
    its restore answered did not start. A status query answered "not executing" ends the motion
    at the query's time (measured); the next play's stop frame, or the log's end, ends it
    unmeasured. A restore whose answer was lost but after which the board reports the motion
    executing did start (the runner counted that play done without sending it again).
    """

    def __init__(self) -> None:
        self.plays: list[MotionPlay] = []
        self._armed: _Armed | None = None
        self._running: _Armed | None = None
        self._lost_start: _Armed | None = None  # a restore with no answer: started, or not
        self._sent: dict[int, tuple[TxRecord, int]] = {}

    def tx(self, record: TxRecord, time_ns: int) -> None:
        self._sent[record.seq] = (record, time_ns)
        if len(self._sent) > 64:
            self._sent.pop(next(iter(self._sent)))
        if record.kind == "play":
            armed = self._armed
            if armed is None or (armed.step, armed.motion) != (record.step, record.motion):
                self._not_started()
                self._armed = _Armed(record.motion, record.step, record.label)
            else:
                armed.start_ns = armed.restore_seq = None  # the sequence tried again
        elif record.kind == "restore" and self._armed is not None:
            self._armed.start_ns, self._armed.restore_seq = time_ns, record.seq
        elif record.kind == "stop":
            self._lost_start = None  # the board was asked and the motion had not started
            if self._running is not None:
                self._end(time_ns, "stop")

    def rx(self, record: RxRecord, time_ns: int) -> None:
        sent, sent_ns = self._sent.pop(record.seq, (None, time_ns))
        kind = sent.kind if sent is not None else None
        armed = self._armed
        if kind == "restore" and armed is not None and record.seq == armed.restore_seq:
            if record.kind == "ack":
                self._start(armed)
            elif record.kind != "nak":
                self._lost_start = armed  # carried out, or not: the board is asked next
        elif kind == "status" and record.kind == "status":
            if self._lost_start is not None and record.executing:
                self._start(self._lost_start)
            elif self._running is not None and record.executing is False:
                self._end(sent_ns, "status")

    def finish(self, end_ns: int | None) -> list[MotionPlay]:
        """The plays, in the order they began, once the log is read to `end_ns`."""
        self._not_started()
        if self._running is not None:
            self._end(end_ns, "end of log")
        return self.plays

    def _start(self, armed: _Armed) -> None:
        if self._running is not None:
            self._end(armed.start_ns, "stop")
        self._running, self._armed, self._lost_start = armed, None, None

    def _end(self, end_ns: int | None, ended_by: str) -> None:
        running = self._running
        assert running is not None
        self.plays.append(MotionPlay(running.motion, running.step, running.label, running.start_ns,
                                     end_ns, ended_by))
        self._running = None

    def _not_started(self) -> None:
        armed = self._armed
        if armed is not None:
            self.plays.append(MotionPlay(armed.motion, armed.step, armed.label, None, None, "not started"))
        self._armed = self._lost_start = None


# -- frames in words, by the layout they were made for ------------------------------------------


@dataclass(frozen=True)
class LogLayouts:
    """Which board layout each robot's frames were made for, as the log's metadata records it
    (`layout`, and `robot.<name>.layout` in a show for several robots).

    The bytes of a play sequence differ between layouts (slots 0x38 apart, other stop and start
    frames, another status read), so a frame read with the wrong layout is a "not a motion slot"
    that never was. A log from before choreo recorded layouts was written for the seed layout,
    its only one then: it is read so, and `assumed` says so.
    """

    recorded: dict[str | None, str]  # robot (None: a one-robot log) -> the name its key holds, or ""

    @classmethod
    def of(cls, run_info: Mapping[str, str]) -> LogLayouts:
        robots = [name for name in str(run_info.get("robots", "")).split(",") if name]
        return cls({robot: str(run_info.get(layout_key(robot), "")) for robot in [None, *robots]})

    def name(self, robot: str | None) -> str:
        """The layout name the log gives the robot's frames (seed where it gives none)."""
        return self.recorded.get(robot, "") or DEFAULT_LAYOUT

    def layout(self, robot: str | None) -> Layout | None:
        """The robot's layout; None for a name this choreo does not know (a newer choreo's log)."""
        return LAYOUTS.get(self.name(robot))

    def assumed(self, robot: str | None) -> bool:
        """The log does not say: seed is assumed."""
        return not self.recorded.get(robot, "")

    def describe(self, robot: str | None) -> str:
        """`hth4-2.2`, or the name with why it is not simply the recorded one."""
        if self.assumed(robot):
            return f"{DEFAULT_LAYOUT} (not recorded: assumed)"
        return self.name(robot) if self.layout(robot) is not None else f"{self.name(robot)!r} (unknown)"

    def notes(self, robots: list[str]) -> list[str]:
        """What a review says of the layouts it read the frames with, where the log did not
        record one or recorded one this choreo does not know."""
        notes = []
        for robot in robots or [None]:
            whose = f"robot {robot}: " if robot is not None else ""
            if self.assumed(robot):
                notes.append(f"{whose}the log does not record a board layout: frames read with the "
                             f"{DEFAULT_LAYOUT} layout (what choreo used before it recorded layouts)")
            elif self.layout(robot) is None:
                notes.append(f"{whose}board layout {self.name(robot)!r} is unknown to this choreo: "
                             "motion slots named by whichever known layout they fit")
        return notes


def frame_meaning(tx: TxRecord, layouts: LogLayouts) -> str:
    """What a logged frame does, read with its robot's layout: `CALL 0x000b80: motion 0`."""
    if not isinstance(tx.hex, str):
        return f"not hex: {tx.hex!r}"
    return _frame_words(tx.hex, layouts.layout(tx.robot))


def reply_meaning(rx: RxRecord, tx: TxRecord | None, layouts: LogLayouts) -> str:
    """What came back for `tx` (None: its frame is not in the log), in words: `ACK`, `status
    0x23: executing`, `program counter 0x001380 (motion 1), ...: executing`, or why it was refused."""
    if rx.kind in ("timeout", "invalid"):
        error = rx.error or ("no reply" if rx.kind == "timeout" else "invalid reply")
        return f"{rx.kind}: {error}"
    if not isinstance(rx.hex, str):
        return f"not hex: {rx.hex!r}"
    return _reply_words(rx.hex, tx.hex if tx is not None and isinstance(tx.hex, str) else None,
                        layouts.layout(rx.robot))


# A run repeats a few frames and replies thousands of times: each is put in words once.
@lru_cache(maxsize=4096)
def _frame_words(hex_text: str, layout: Layout | None) -> str:
    try:
        return describe_frame(bytes.fromhex(hex_text), layout)
    except (TypeError, ValueError):
        return f"not hex: {hex_text!r}"


@lru_cache(maxsize=4096)
def _reply_words(hex_text: str, frame_hex: str | None, layout: Layout | None) -> str:
    try:
        data = bytes.fromhex(hex_text)
        frame = bytes.fromhex(frame_hex) if frame_hex is not None else None
    except (TypeError, ValueError):
        return f"not hex: {hex_text!r}"
    return describe_reply(data, frame, layout)


def describe_frame(data: bytes, layout: Layout | None) -> str:
    """A frame sent to the board, in words, as `layout` builds its frames (None: not known)."""
    try:
        command = p.parse_command(data)
    except ValueError as exc:
        return f"not a frame: {exc}"
    if data == p.sync_frame().data:
        return "ACK check"
    if data == p.version_frame().data:
        return "version query"
    if command.command == p.CMD_CALL:
        return f"CALL 0x{command.address:06x}: {_called(command.address or 0, layout)}"
    if command.move_type == p.MOV_COM_TO_RAM:
        return f"MOV COM->RAM 0x{command.address:04x} <- {p.hexbytes(command.payload)}: {_written(data, layout)}"
    if command.move_type == p.MOV_RAM_TO_COM:
        return f"MOV RAM->COM 0x{command.address:04x} x{command.count}: {_read_name(data, layout)}"
    return f"command {command.command:02x}"


def _called(address: int, layout: Layout | None) -> str:
    """`motion N` when the address starts one of the layout's slots; else whose slot it is."""
    slot = layout.slot_of(address) if layout is not None else None
    if slot is not None:
        return f"motion {slot}"
    fits = layout_of_call(address)
    if fits is None:
        return "not a motion slot"
    other, slot = fits
    if layout is None:
        return f"motion {slot} (a slot of the {other.name} layout)"
    return f"not a motion slot of the {layout.name} layout (motion {slot}'s slot in {other.name})"


def _written(data: bytes, layout: Layout | None) -> str:
    """Which frame of the layout's play sequence a write is (at any baud, from any config word:
    the layout builds them), or `write`."""
    kind = _sequence_kind(data, layout) if layout is not None else None
    if kind is None or layout is None:
        return "write"
    word = int.from_bytes(data[6:8], "little")
    if kind is p.FrameKind.COUNTER:
        return f"program counter to the main loop 0x{layout.main_loop:06x}"
    if not layout.reads_config:
        return "stop and save status" if kind is p.FrameKind.STOP else "restore status"
    return f"{'suspend' if kind is p.FrameKind.STOP else 'resume'}: config 0x{word:04x}"


def _sequence_kind(data: bytes, layout: Layout) -> p.FrameKind | None:
    word = int.from_bytes(data[6:8], "little") if len(data) >= 8 else 0
    for baud in p.BAUD_CODES:
        for frame in layout.play_sequence(0, word, baud):
            if frame.kind is not p.FrameKind.PLAY and frame.data == data:
                return frame.kind
    return None


def _read_name(data: bytes, layout: Layout | None) -> str:
    if layout is not None and data == layout.status.data:
        return "status query"
    if layout is not None and data == layout.start_read.data:
        return "program state read (did the motion start?)"
    if layout is not None and layout.reads_config and data == _CONFIG_READ:
        return "config word read"
    return "read"


_CONFIG_READ = p.read_frame(p.CONFIG_ADDRESS, 2).data  # the hth4-2.2 link reads it at open
# What the RAM a frame can read holds (address, bytes, name): the config word, then the program
# counter, the return address a CALL pushed, and the call depth.
_RAM_FIELDS = ((p.CONFIG_ADDRESS, 2, "config"), (p.PROGRAM_COUNTER_ADDRESS, 3, "program counter"),
               (0x0005, 3, "return address"), (0x0008, 1, "depth"))


def describe_reply(data: bytes, frame: bytes | None, layout: Layout | None) -> str:
    """A reply in words: `ACK`, `NAK`, a RAM read's fields (`config 0x821b`), and for the
    layout's status query whether a motion is executing. `frame`: what it answers (None: unknown)."""
    if not data:
        return "no reply"
    if len(data) == p.TYPE1_REPLY_SIZE and data[0] == len(data) and p.checksum(data[:3]) == data[3]:
        return {p.ACK_BYTE: "ACK", p.NAK_BYTE: "NAK"}.get(data[2], f"type 1 reply {data[2]:02x}")
    if data[0] != len(data) or p.checksum(data[:-1]) != data[-1]:
        return f"invalid: {p.hexbytes(data)}"
    try:
        command = p.parse_command(frame) if frame is not None else None
    except ValueError:
        command = None
    if command is None or command.move_type != p.MOV_RAM_TO_COM or len(data) != (command.count or 0) + 3:
        return f"{len(data)}-byte reply: {p.hexbytes(data)}"
    if layout is not None and frame == layout.status.data:
        return _status_words(data, frame, layout)
    return _ram_words(command.address or 0, data[2:-1], layout) or f"{len(data) - 3} bytes: {p.hexbytes(data[2:-1])}"


def _status_words(data: bytes, frame: bytes, layout: Layout) -> str:
    """The layout's status query answered: what it reads, and the layout's running rule on it."""
    executing = p.parse_reply(p.Frame(p.FrameKind.STATUS, frame), data).executing
    state = "executing" if executing else "not executing"
    if data[2:-1] and frame == p.status_frame().data:
        return f"status 0x{data[2]:02x}: {state}"  # the document's words for its config read
    command = p.parse_command(frame)
    return f"{_ram_words(command.address or 0, data[2:-1], layout)}: {state}"


def _ram_words(address: int, ram: bytes, layout: Layout | None) -> str:
    """The known fields of RAM read from `address`: `config 0x821b, program counter 0x001380
    (motion 1), ...`; empty if the read holds none whole."""
    words = []
    for start, size, name in _RAM_FIELDS:
        if address <= start and start + size <= address + len(ram):
            value = int.from_bytes(ram[start - address:start - address + size], "little")
            words.append(f"{name} {value}" if name == "depth" else
                         f"{name} 0x{value:0{size * 2}x}{_in_slot(value, layout) if size == 3 else ''}")
    return ", ".join(words)


def _in_slot(address: int, layout: Layout | None) -> str:
    """` (motion 1)` where a program address lies inside one of the layout's slots."""
    if layout is None:
        return ""
    offset = address - layout.first_slot
    if 0 <= offset < p.MOTION_SLOTS * p.SLOT_SIZE:
        return f" (motion {offset // p.SLOT_SIZE})"
    return ""
