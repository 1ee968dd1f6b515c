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
from collections.abc import Callable, Mapping
from functools import lru_cache
from dataclasses import MISSING, Field, dataclass, field, fields, replace
from typing import Any, ClassVar

from choreo.clock import HELD, PAUSED, RUNNING
from choreo.errors import MESSAGE_CHARS
from choreo.events import RunResult
from choreo.numtext import whole_number
from choreo.wire.framewords import describe_frame, describe_reply, is_slot
from choreo.wire.layouts import DEFAULT_LAYOUT, LAYOUTS, Layout, StartState

TX_TOPIC = "/rcb4/tx"
RX_TOPIC = "/rcb4/rx"
STEP_TOPIC = "/choreo/step"
LOG_TOPIC = "/choreo/log"
CLOCK_TOPIC = "/choreo/clock"
CLOCK_EVERY_S = 0.5  # how often (show time) /choreo/clock samples the show clock
CLOCK_STATES = (RUNNING, HELD, PAUSED)  # a /choreo/clock sample's `state`
CLOCK_SOURCES = ("machine", "music", "link")  # what keeps the show clock (a /choreo/clock sample's `source`)
# What a /choreo/clock sample on the Link clock marks (absent: a periodic sample): the show's
# start on a bar line, a peer's tempo change, peers joining or leaving, the session's transport
# stopping or playing, and a jump of the session's timeline (a peer's clock jumped, or the
# session was rejoined) that moved the beat by more than LINK_JUMP_BEATS.
LINK_EVENTS = ("start", "tempo", "peers", "stopped", "playing", "jump")
LINK_PREFIX = "link: "  # how the log's lines about the Link session begin (the progress output shows them)
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
    """`/rcb4/left/tx` -> `/rcb4/tx`, `/choreo/stage/log` -> `/choreo/log`: what kind of message
    a topic carries, whoever's it is (a robot's, or in a merged log a host's)."""
    parts = topic.split("/")
    if len(parts) == 4:
        joined = f"/{parts[1]}/{parts[3]}"
        if joined in PER_ROBOT or joined in PER_HOST:
            return joined
    return topic


# A merged log (`choreo log merge`): each host's shared topics on their own, `/choreo/stage/log`.
PER_HOST = (LOG_TOPIC, CLOCK_TOPIC, COMMAND_TOPIC)


def host_topic(topic: str, host: str) -> str:
    """A host's own shared topic in a merged log: `/choreo/clock` -> `/choreo/stage/clock`."""
    head, _, tail = topic.rpartition("/")
    return f"{head}/{host}/{tail}"


def clock_topic(run_info: Mapping[str, str]) -> str:
    """The clock topic the reviews read show time by: `/choreo/clock`, or in a merged log its
    first host's (the other hosts' clocks are kept, but one show is timed by one clock)."""
    hosts = LoggedRun(run_info).hosts
    return host_topic(CLOCK_TOPIC, hosts[0]) if hosts else CLOCK_TOPIC


def robot_message(topic: str, data: bytes, robot: str | None) -> tuple[str | None, bytes]:
    """A robot's message (tx, rx, step; `topic` its kind) as a merged log keeps it: the robot
    it names and the bytes to write. `robot` given (a one-robot log, whose records name none):
    the record is made to name it. ValueError, TypeError: not a JSON object, or a robot no name."""
    message = decode(data)
    if not isinstance(message, dict):
        raise TypeError(f"a JSON object, not {type(message).__name__}")
    if robot is None:
        named = message.get("robot")
        if named is not None and not isinstance(named, str):
            raise TypeError(f"field 'robot' holds {type(named).__name__}, not str")
        return named, data
    return robot, _encode({**message, "robot": robot}).encode()


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
UNLOGGED = "unlogged"  # the command name of a summary of commands not logged one by one (live/limits)
SHOW_MEDIA_TYPE = "application/yaml"  # how the run attaches its show file, and how a review finds it
SHOW_FALLBACK_NAME = "show.yaml"  # what a review and a replay call an attached show the log names not


class Info:
    """The keys of the `choreo` metadata: the run as it started (written by the recorder's
    RunInfo, read by the reviews and replay). Spelled as logs always have: older choreo reads
    a newer log by these names, and a newer choreo an older one."""

    VERSION = "version"
    SHOW = "show"
    SHOW_PATH = "show_path"
    SHOW_SHA256 = "show_sha256"
    PORT = "port"  # the first robot's, in a show for several
    BAUD = "baud"
    LAYOUT = "layout"
    START_TIME = "start_time"
    START_NS = "start_ns"
    HOST = "host"
    PYTHON = "python"
    PLATFORM = "platform"
    ROBOTS = "robots"  # a show for several: their names, comma-separated
    HOSTS = "hosts"  # a merged log (`choreo log merge`): its hosts, comma-separated; the first's time is its axis
    SHIFT_NS, SPREAD_NS, ALIGNED_BY = "shift_ns", "spread_ns", "aligned_by"  # host_key(host, ...): its alignment
    UNISON = "unison"  # YES or NO
    SHOW_HOST = "show_host"  # the show's `hosts:` entry this run drove (absent: a show for one host)
    YES, NO = "yes", "no"


class Result:
    """The keys of the `choreo.result` metadata: how the run ended (RunResult, the stage's
    outcome, the session's clock and music, a replay's source)."""

    OUTCOME = "outcome"  # done | aborted | interrupted | failed
    STEPS_RUN = "steps_run"
    LATE_STEPS = "late_steps"
    SHOW_S = "show_s"
    ERROR = "error"
    EXIT_CODE = "exit_code"
    STOP_REASON = "stop_reason"
    CLOCK = "clock"  # music | machine
    SHOW_ZERO_MONOTONIC_NS = "show_zero_monotonic_ns"
    SHOW_ZERO_WALL_NS = "show_zero_wall_ns"
    MUSIC_FILE = "music.file"
    MUSIC_START = "music.start"
    AUDIO_BACKEND = "audio.backend"
    REPLAY_OF = "replay_of"  # a replay's: the log it replayed, at what speed, what it found
    SPEED = "speed"
    FRAMES = "frames"
    DIFFERENCES = "differences"


def result_metadata(result: RunResult) -> dict[str, str]:
    """A finished run's result as its log's `choreo.result` metadata holds it."""
    return {Result.OUTCOME: result.outcome, Result.STEPS_RUN: str(result.steps_run),
            Result.LATE_STEPS: str(result.late_steps), Result.SHOW_S: f"{result.show_s:.6f}"}


def robot_key(robot: str, what: str) -> str:
    """A robot's key in a show for several (`robot.left.port`): MCAP metadata is flat text."""
    return f"robot.{robot}.{what}"


def host_key(host: str, what: str) -> str:
    """A host's key in a merged log's `choreo` metadata (`host.stage.shift_ns`)."""
    return f"host.{host}.{what}"


def layout_key(robot: str | None) -> str:
    """The metadata key of a robot's board layout (`layout` in a one-robot log)."""
    return Info.LAYOUT if robot is None else robot_key(robot, Info.LAYOUT)


def logged_robots(run_info: Mapping[str, str]) -> list[str]:
    """The robots a log's `choreo` metadata names, in the show's order (none: a one-robot log)."""
    return [name for name in str(run_info.get(Info.ROBOTS, "")).split(",") if name]


@dataclass(frozen=True)
class LoggedRun:
    """The `choreo` metadata read back as typed values (the reader's `info`). A log that lacks a
    key (older choreo's, a cut one, another program's) or holds a damaged number reads as empty
    or None, never as an error: a review says what it has."""

    text: Mapping[str, str]  # the record as stored (a review prints it as it is)

    @property
    def show(self) -> str:
        return self.text.get(Info.SHOW, "")

    @property
    def show_path(self) -> str:
        return self.text.get(Info.SHOW_PATH, "")

    @property
    def robots(self) -> list[str]:
        return logged_robots(self.text)

    @property
    def hosts(self) -> list[str]:
        """A merged log's hosts (`choreo log merge`), the first's time its axis; empty: one host's run."""
        return [name for name in str(self.text.get(Info.HOSTS, "")).split(",") if name]

    @property
    def unison(self) -> bool:
        """The robots shared their steps (an old or one-robot log does not say: no)."""
        return self.text.get(Info.UNISON) == Info.YES

    @property
    def start_ns(self) -> int | None:
        """The run's wall-clock start."""
        return whole_number(self.text.get(Info.START_NS) or "")

    def baud(self, robot: str | None = None) -> int | None:
        """The baud the log gives (the first robot's, or `robot`'s in a show for several)."""
        return whole_number(self.text.get(Info.BAUD if robot is None else robot_key(robot, Info.BAUD), ""))

DEBUG, INFO, WARNING, ERROR, FATAL = 1, 2, 3, 4, 5  # foxglove.Log levels
ABORT_LABEL = "on_abort"  # the label of the abort motion's frames (they belong to no step)

# A play is late when it starts more than this after its time, or when retries delay the play
# sequence that worked by more than this (the step's end event says by how much).
LATE_MS = 1.0


@lru_cache(maxsize=None)
def _field_names(cls: type) -> tuple[str, ...]:
    """A record type's field names, worked out once (the recorder serialises every frame)."""
    return tuple(f.name for f in fields(cls))


class _Record:
    """JSON form of a dataclass record: absent fields omitted, required ones checked on read."""

    topic: ClassVar[str]

    def to_json(self) -> dict:
        record_type: type = self.__class__  # as `type`: mypy takes a class's unbound __hash__ for unhashable
        names = _field_names(record_type)
        return {name: value for name in names if (value := getattr(self, name)) is not None}

    @classmethod
    def from_json(cls, message: Any) -> Any:
        if not isinstance(message, dict):
            raise TypeError(f"a JSON object, not {type(message).__name__}")
        try:
            record = cls(**message)  # what choreo wrote: exactly the record's fields (the fast path)
        except TypeError:
            pass
        else:
            return record._checked()
        given = {}  # a field missing, or one from another version of choreo: field by field
        for f in _fields(cls):
            if f.name in message:
                given[f.name] = message[f.name]
            elif f.default is MISSING and f.default_factory is MISSING:
                raise KeyError(f.name)
        return cls(**given)._checked()

    @classmethod
    def partial(cls, message: Any) -> Any:
        """As far as the message goes: a missing field is blank (0, "") instead of an error, for
        the views that show a log as it is (`log frames`, `log export`) even when another tool
        wrote part of it; the reviews that count (summary, timeline) use `from_json`."""
        if not isinstance(message, dict):
            raise TypeError(f"a JSON object, not {type(message).__name__}")
        given = {}
        for f in _fields(cls):
            if f.name in message:
                given[f.name] = message[f.name]
            elif f.default is MISSING and f.default_factory is MISSING:
                given[f.name] = _BLANK[str(f.type)]  # annotations are strings here (future import)
        return cls(**given)._checked()

    def _checked(self) -> Any:
        """The record if every field holds a value of its annotated type, in range; TypeError or
        ValueError naming the field if not. A log is a file from outside: a `motion` of 1e308,
        NaN or a list, or a 30-digit `latency_ms`, must fail here, in the one way every review
        turns into one line, not as an OverflowError or a format error deep in a review."""
        record_type: type = self.__class__  # as `type`, for mypy: see to_json
        cuts: dict[str, str] = {}  # text longer than choreo writes there, cut (the text shown, not its meaning)
        for name, kinds in _field_kinds(record_type):
            value = getattr(self, name)
            kind = _KIND_OF.get(type(value))
            if kind not in kinds:
                raise TypeError(f"field {name!r} holds {type(value).__name__}, not {' or '.join(kinds)}")
            if kind in ("int", "float") and not -_NUMBER_MAX <= value <= _NUMBER_MAX:  # NaN fails too
                raise ValueError(f"field {name!r} holds {value!r:.40}, out of range")
            if kind == "str" and len(value) > _FIELD_KEPT.get(name, FIELD_TEXT_KEPT):
                cuts[name] = _kept_text(value, _FIELD_KEPT.get(name, FIELD_TEXT_KEPT))
        return replace(self, **cuts) if cuts else self  # type: ignore[type-var]  # its subclasses are dataclasses


_BLANK = {"int": 0, "float": 0.0, "str": ""}  # a required field's blank, by its annotation
# A record's text as every review keeps it: a hostile log's 50 KB error or label (a few bytes
# compressed) was printed on every line of log frames and every row of an export. A robot's name
# is cut as the metadata's are (kept_metadata), bytes in hex at what no frame or set-aside reply
# reaches, any other text at MESSAGE_CHARS (choreo's own longest line, an error's).
FIELD_TEXT_KEPT = MESSAGE_CHARS  # and _FIELD_KEPT, by the metadata's bounds below
# A JSON value's Python type -> the annotations it may fill (bool is not a number here).
_KIND_OF = {int: "int", float: "float", str: "str", bool: "bool", dict: "dict", type(None): "None"}
_NUMBER_MAX = 2 ** 63  # nanoseconds since 1970 fit, with room; no field of a log holds more


def _fields(cls: type) -> tuple[Field[Any], ...]:
    """A record class's dataclass fields (`_Record` itself is no dataclass: its subclasses are)."""
    return fields(cls)


@lru_cache(maxsize=None)
def _field_kinds(cls: type) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """Each field and the kinds of value its annotation allows (`float` takes an int too)."""
    out = []
    for f in fields(cls):
        kinds = tuple(part.strip() for part in str(f.type).split("|"))
        out.append((f.name, kinds + (("int",) if "float" in kinds else ())))
    return tuple(out)


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
    event: str  # start | end | skip (a cue the operator skipped: the step never ran)
    actual_s: float
    planned_s: float = 0.0  # when it was due at run time
    estimated_s: float = 0.0  # where the compiled plan put it
    late_ms: float = 0.0  # start: how late it started; end of a play: how late its motion began
    path: str = ""
    label: str | None = None
    motion: int | None = None
    cue: float | None = None
    outcome: str | None = None  # end: ok | failed | aborted | timeout; skip: skipped
    robot: str | None = None  # whose step, in a show for several robots
    start_s: float | None = None  # end of a play: when the frame that started the motion was written
    lead_ms: float | None = None  # end of a cued play: how far ahead of its cue the first frame was due
    go: bool | None = None  # a GO cue (`at: go`): it waited for the operator's GO
    cue_number: str | None = None  # a cued step: its number in the cue list (`1`, `12.5`)

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
    source: str = "machine"  # machine | music | link: what keeps the show clock
    state: str | None = None  # running | held (a GO cue waits) | paused; absent: running (logs before pause)
    # On the Link clock (source link) only: the session as this host saw it at that instant
    link_us: int | None = None  # Link's clock in microseconds (CLOCK_MONOTONIC_RAW on Linux: not monotonic_ns's)
    beat: float | None = None  # the show's beat: 0 at show time 0 (bar 1 beat 1), the same on every host
    session_beat: float | None = None  # Link's own beat count on this host (a whole number of bars off others')
    tempo: float | None = None  # the session's tempo, beats a minute
    peers: int | None = None  # other Link peers seen
    event: str | None = None  # what the sample marks (LINK_EVENTS); absent: a periodic sample

    def _checked(self) -> Any:
        """As every record's, and a state, source and event that are the clock's (a review
        places time by them)."""
        _Record._checked(self)
        for name, allowed in (("state", CLOCK_STATES), ("source", CLOCK_SOURCES), ("event", LINK_EVENTS)):
            value = getattr(self, name)
            if value is not None and value not in allowed:
                raise ValueError(f"field {name!r} holds {value!r:.40}, none of {', '.join(allowed)}")
        return self


@dataclass(frozen=True, slots=True)
class CommandRecord(_Record):
    """An operator's command (GO, panic, start, stop, a cue's GO), where it came from (`key`,
    `osc udp 127.0.0.1:53001`), and what it did: a review shows who pressed what and when."""

    topic: ClassVar[str] = COMMAND_TOPIC
    command: str
    source: str
    status: str  # ok | error | denied (a sender not allowed)
    message: str = ""
    label: str | None = None  # the cue as typed or sent (number or label); unknown or refused: the OSC address
    show_s: float | None = None  # the show clock when it came (absent before the show started)
    count: int | None = None  # `unlogged`: how many commands it sums up (absent: this one)
    counts: dict | None = None  # `unlogged`: those commands by name (go, refused, unknown...)
    cue: str | None = None  # the cue it acted on, by its number in the cue list (whatever was typed)
    cue_label: str | None = None  # and that cue's label

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

    @property
    def what(self) -> str:
        """The command and its cue as the cue list names it, whatever was typed: `go cue 1
        'applause'`; what was typed too where it differs (`cue_go cue 1 'applause' (given as
        '01')`), or alone for a cue the command found none by (`cue_go 'nosuch'`). Every review
        names commands so; text from the log is quoted (escaped) and cut, as it is from outside."""
        if self.cue is not None:
            name = cue_name(self.cue, self.cue_label)
            given = self.label if self.label is not None and self.label not in (self.cue, self.cue_label) else None
            return f"{self.command} {name}" + (f" (given as {_quoted(given)})" if given is not None else "")
        if self.label is None:
            return self.command
        return f"{self.command} {_quoted(self.label) if self.command in CUE_COMMANDS else _cut(self.label)}"


CUE_COMMANDS = ("cue_go", "skip", "playhead")  # the commands whose label names a cue, as typed or sent
SHOWN_CHARS = 40  # a cue number, label or reference from a log, as a review shows it (then "…")


def _cut(text: str) -> str:
    return text if len(text) <= SHOWN_CHARS else text[:SHOWN_CHARS] + "…"


def _quoted(text: str) -> str:
    """`'applause'`, as `Cue.name` quotes a label; cut to SHOWN_CHARS."""
    return f"'{_cut(text)}'"


def cue_name(number: str, label: str | None) -> str:
    """A cue named from a log as `Cue.name` names it in the show (`cue 1 'applause'`), the log's
    text cut: how every review names a cue."""
    return f"cue {_cut(number)}" + (f" {_quoted(label)}" if label else "")


Record = TxRecord | RxRecord | StepRecord | LogRecord | ClockRecord | CommandRecord
RECORD_TYPES: dict[str, type[_Record]] = {TX_TOPIC: TxRecord, RX_TOPIC: RxRecord, STEP_TOPIC: StepRecord,
                                 LOG_TOPIC: LogRecord, CLOCK_TOPIC: ClockRecord, COMMAND_TOPIC: CommandRecord}


# The C scanner json.loads itself calls; typeshed leaves the attribute out of JSONDecoder's stub.
_scan_once: Callable[[str, int], tuple[Any, int]] = json.JSONDecoder().scan_once  # type: ignore[attr-defined]  # not in typeshed


_encode = json.JSONEncoder(separators=(",", ":")).encode  # as the recorder writes a message


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
    ended_by: str  # status | stop | state read (over when the board was asked) | end of log | not started

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
    unmeasured. A restore whose answer was lost is judged as the link judged it: by the answer
    to the read of the board's program state that followed, through the robot's layout
    (`Layout.start_state`): running, or already over (ended at the read, unmeasured), is a play
    started at the restore; never started is not, once the link sends the sequence again (it
    reads twice before it believes that: the second read may show the motion started). With a
    layout this choreo does not know (`layout` None) the link's next frame tells instead: the
    same sequence again from its stop frame, or not. An older log (no state read) is judged by a
    status reply saying executing.
    """

    def __init__(self, layout: Layout | None = None) -> None:
        self.layout = layout
        self.plays: list[MotionPlay] = []
        self._armed: _Armed | None = None
        self._running: _Armed | None = None
        self._lost_start: _Armed | None = None  # a restore with no answer: started, or not
        self._asked = False  # the state was read after it, and the layout could not judge it
        self._sent: dict[int, tuple[TxRecord, int]] = {}

    def tx(self, record: TxRecord, time_ns: int) -> None:
        self._sent[record.seq] = (record, time_ns)
        if len(self._sent) > 64:
            self._sent.pop(next(iter(self._sent)))
        armed: _Armed | None = self._armed  # this tracker's own record of the play it armed
        if record.kind == "play":
            if armed is None or (armed.step, armed.motion) != (record.step, record.motion):
                self._not_started()
                self._armed = _Armed(record.motion, record.step, record.label)
            else:
                armed.start_ns = armed.restore_seq = None  # the sequence tried again
        elif record.kind == "restore" and armed is not None:
            armed.start_ns, armed.restore_seq = time_ns, record.seq
        elif record.kind == "stop":
            lost = self._lost_start
            if lost is not None and self._asked and record.step != lost.step:
                self._start(lost)  # asked, and the link went on: it counted the play started
            self._lost_start = None  # else: the board was asked and the motion had not started
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
                self._lost_start, self._asked = armed, False  # carried out, or not: the board is asked next
        elif kind == "read" and record.kind == "status" and self._lost_start is not None:
            self._judge(self._lost_start, record, sent_ns)
        elif kind == "status" and record.kind == "status":
            if self._lost_start is not None and record.executing:
                self._start(self._lost_start)
            elif self._running is not None and record.executing is False:
                self._end(sent_ns, "status")

    def _judge(self, lost: _Armed, reply: RxRecord, read_ns: int) -> None:
        """The program state read after a lost restore reply, judged by the robot's layout."""
        motion = lost.motion
        if self.layout is None or motion is None or not is_slot(motion):
            self._asked = True
            return
        state = self.layout.start_state(motion, _hex_bytes(reply.hex))
        if not state.started:
            return  # a second read may yet show it started; else the retry's stop frame drops it
        self._start(lost)
        if state is StartState.DONE:
            self._end(read_ns, "state read")  # over before the read went out

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
        if armed is not None and armed is self._lost_start and self._asked:
            self._start(armed)  # asked, and not sent again: the link counted it started
        elif armed is not None:
            self.plays.append(MotionPlay(armed.motion, armed.step, armed.label, None, None, "not started"))
        self._armed = self._lost_start = None


def _hex_bytes(text: object) -> bytes:
    """A logged reply's bytes; b"" for hex no choreo wrote (a state no layout can judge)."""
    try:
        return bytes.fromhex(text) if isinstance(text, str) else b""
    except ValueError:
        return b""


# -- the metadata as a review keeps it ------------------------------------------------------------

# What a review keeps of a log's `choreo` metadata: a hostile log's 50 KB names, 100,000 robots
# or keys were printed whole by every review and copied into a merged log. Choreo writes within
# these (schemas/show.schema.json: at most 16 robots and 16 hosts, names of 32 characters, a
# show's name of 200 or a file's stem), so what it writes is kept whole.
ROBOTS_KEPT = 16  # robots (and hosts) of a show: its schema's maxProperties
NAME_KEPT = 32  # characters of a robot's or a host's name: the schema's pattern
SHOW_NAME_KEPT = 255  # characters of a show's name: the schema's 200, or a file's stem
VALUE_KEPT = 4096  # characters of any other value (a show's path, a port)
SHORT_KEPT = 64  # characters of a value choreo writes short (a version, a time, a number, the machine's name)
OTHER_KEYS_KEPT = 32  # keys choreo does not write (a newer choreo's): the first these
METADATA_RECORDS_KEPT = 64  # metadata records (a merged log's hosts' own among them) besides choreo's two
_FIELD_KEPT = {"robot": NAME_KEPT, "hex": VALUE_KEPT, "stale": VALUE_KEPT}  # a record's text (_Record._checked)
_ROBOT_WHATS = (Info.PORT, Info.BAUD, Info.LAYOUT)
_HOST_WHATS = (Info.SHIFT_NS, Info.SPREAD_NS, Info.ALIGNED_BY)
_SHORT_KEYS = frozenset((Info.VERSION, Info.SHOW_SHA256, Info.BAUD, Info.LAYOUT, Info.START_TIME, Info.START_NS,
                         Info.HOST, Info.PYTHON, Info.PLATFORM, Info.UNISON, Info.SHIFT_NS, Info.SPREAD_NS,
                         Info.ALIGNED_BY))
_INFO_KEYS = _SHORT_KEYS | {Info.SHOW, Info.SHOW_PATH, Info.PORT, Info.LAYOUT, Info.ROBOTS, Info.HOSTS, Info.SHOW_HOST}


def _kept_text(text: str, kept: int) -> str:
    return text if len(text) <= kept else text[:kept - 1] + "\u2026"


def _kept_chars(key: str) -> int:
    """How much of a `choreo` key's value a review keeps: what choreo writes there, whole."""
    if key in _SHORT_KEYS:
        return SHORT_KEPT
    return NAME_KEPT if key == Info.SHOW_HOST else SHOW_NAME_KEPT if key == Info.SHOW else VALUE_KEPT


@dataclass
class _Keeping:
    """One metadata record being bounded: what is kept so far, and what a review says it left out."""

    raw: Mapping[str, str]
    kept: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    values_cut: int = 0

    def value(self, text: str, kept: int = VALUE_KEPT) -> str:
        if len(text) > kept:
            self.values_cut += 1
        return _kept_text(text, kept)

    def names(self, key: str, whose: str, whats: tuple[str, ...], kept_as: Callable[[str], str]) -> None:
        """A list of names (`robots`, `hosts`): at most ROBOTS_KEPT, each cut to NAME_KEPT, with
        each one's own keys (`robot.NAME.port`) kept under the name as cut."""
        listed = [name for name in str(self.raw.get(key, "")).split(",") if name]
        names: dict[str, str] = {}
        for name in listed:
            names.setdefault(_kept_text(name, NAME_KEPT), name)
            if len(names) == ROBOTS_KEPT:
                break
        if len(listed) > ROBOTS_KEPT:
            self.notes.append(f"the log names {len(listed):,} {whose}s: the first {ROBOTS_KEPT} kept "
                              f"(a show has at most {ROBOTS_KEPT})")
        if any(len(name) > NAME_KEPT for name in names.values()):
            self.notes.append(f"{whose} names longer than {NAME_KEPT} characters (no show's) cut with \u2026")
        if key in self.raw:
            self.kept[key] = ",".join(names)
        for cut, name in names.items():
            for what in whats:
                if (value := self.raw.get(kept_as(name) + what)) is not None:
                    self.kept[kept_as(cut) + what] = self.value(value, _kept_chars(what))

    def rest(self, named: tuple[str, ...] = ()) -> None:
        """Choreo's other keys, values cut; keys it does not write, up to OTHER_KEYS_KEPT (those
        beginning with `named`, a robot's or a host's, were kept with their names or not at all)."""
        others = 0
        for key, value in self.raw.items():
            if key in _INFO_KEYS and key not in (Info.ROBOTS, Info.HOSTS):
                self.kept[key] = self.value(value, _kept_chars(key))
            elif key not in self.kept and not (named and key.startswith(named)):
                others += 1
                if others <= OTHER_KEYS_KEPT:
                    self.kept[self.value(key, NAME_KEPT)] = self.value(value)
        if others > OTHER_KEYS_KEPT:
            self.notes.append(f"the log's metadata has {others:,} keys choreo does not write: "
                              f"the first {OTHER_KEYS_KEPT} kept")
        if self.values_cut:
            self.notes.append(f"{self.values_cut:,} metadata text{'s' if self.values_cut > 1 else ''} longer than "
                              "choreo writes cut with \u2026")


def kept_metadata(name: str, raw: Mapping[str, str]) -> tuple[dict[str, str], list[str]]:
    """A metadata record as every review (and a merge) keeps it, and what it says it left out:
    the `choreo` record's robots, hosts, names, keys and values bounded (ROBOTS_KEPT, NAME_KEPT,
    VALUE_KEPT...); any other record's keys and values likewise. Shown text is still escaped
    where it is shown: this bounds what one log can cost, not what its characters are."""
    keeping = _Keeping(raw if name in (METADATA_NAME, RESULT_METADATA_NAME) else
                       dict(list(raw.items())[:OTHER_KEYS_KEPT]))
    if name == METADATA_NAME:
        keeping.names(Info.ROBOTS, "robot", _ROBOT_WHATS, lambda robot: robot_key(robot, ""))
        keeping.names(Info.HOSTS, "host", _HOST_WHATS, lambda host: host_key(host, ""))
        keeping.rest(("robot.", "host."))
    else:
        keeping.rest()
    return keeping.kept, keeping.notes


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
        robots = logged_robots(run_info)
        return cls({robot: _kept_layout_name(str(run_info.get(layout_key(robot), ""))) for robot in [None, *robots]})

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
        whom: list[str | None] = [*robots] or [None]
        for robot in whom:
            whose = f"robot {robot}: " if robot is not None else ""
            if self.assumed(robot):
                notes.append(f"{whose}the log does not record a board layout: frames read with the "
                             f"{DEFAULT_LAYOUT} layout (what choreo used before it recorded layouts)")
            elif self.layout(robot) is None:
                notes.append(f"{whose}board layout {self.name(robot)!r} is unknown to this choreo: "
                             "motion slots named by whichever known layout they fit")
        return notes


LAYOUT_NAME_KEPT = 40  # characters of a recorded layout name no choreo knows that a review keeps


def _kept_layout_name(name: str) -> str:
    """A recorded layout name as reviews keep it: a known one whole; another (a newer choreo's,
    or a hostile log's) is only ever shown, in every row of an export: cut to LAYOUT_NAME_KEPT."""
    if name in LAYOUTS or len(name) <= LAYOUT_NAME_KEPT:
        return name
    return name[:LAYOUT_NAME_KEPT - 1] + "\u2026"


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
    frame_hex = tx.hex if tx is not None and isinstance(tx.hex, str) else None
    asked = tx.motion if tx is not None and is_slot(tx.motion) else None  # a state read's motion
    return _reply_words(rx.hex, frame_hex, layouts.layout(rx.robot), asked)


# A run repeats a few frames and replies thousands of times: each is put in words once.
@lru_cache(maxsize=4096)
def _frame_words(hex_text: str, layout: Layout | None) -> str:
    try:
        return describe_frame(bytes.fromhex(hex_text), layout)
    except (TypeError, ValueError):
        return f"not hex: {hex_text!r}"


@lru_cache(maxsize=4096)
def _reply_words(hex_text: str, frame_hex: str | None, layout: Layout | None, motion: int | None) -> str:
    try:
        data = bytes.fromhex(hex_text)
        frame = bytes.fromhex(frame_hex) if frame_hex is not None else None
    except (TypeError, ValueError):
        return f"not hex: {hex_text!r}"
    return describe_reply(data, frame, layout, motion)
