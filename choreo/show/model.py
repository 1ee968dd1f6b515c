"""The records a checked show compiles to: what the runner, `choreo plan` and the log share.

A show file is loaded and checked into a `Show`, then flattened (repeats expanded) into a
`Plan`: a list of `PlannedStep`s, each with its planned start on the show clock. The runner
never looks at YAML; it walks the plan.
"""

from __future__ import annotations

import bisect
import math
import os
import statistics
import unicodedata
from dataclasses import dataclass, field
from enum import Enum
from itertools import pairwise
from pathlib import Path

from choreo.numtext import whole_number
from choreo.wire.layouts import DEFAULT_LAYOUT
from choreo.wire.protocol import Frame
from choreo.textfit import is_hidden

DEFAULT_MOTION_S = 1.0  # a motion's expected length when the show does not say (the simulator's default)
DEFAULT_DONE_TIMEOUT_S = 60.0  # `wait: done` gives up after this long unless the step says otherwise
MOTION_NAME_MAX = 64  # characters; the schema's `maxLength` for a motion name says the same
MOTION_NAME_FORMAT = "motion-name"  # the schema's `format` for motion names, checked by `is_motion_name`


def is_motion_name(name: str) -> bool:
    """Whether `name` can name a motion: a letter of any script or `_`, then letters, digits, `_`, `-`.

    Heart to Heart 4 users name motions in their own language (`歩く`, `ウェーブ`), so letters are
    Unicode's (categories L* and Nl, e.g. `々`, `ー`, `〇`); combining marks and decimal digits may
    follow. Spaces, punctuation (`（`, `・`), symbols (`→`) and control characters may not: a
    name stays one word that reads the same in a step, a message and a log. Length is the
    schema's to check (`MOTION_NAME_MAX`), so that a long name gets its own message.
    """
    if not name or not (name[0] == "_" or _is_letter(name[0])) or hidden_character(name) is not None:
        return False
    return all(ch in "_-" or _is_letter(ch) or unicodedata.category(ch) in _NAME_TAIL for ch in name[1:])


def hidden_character(text: str) -> str | None:
    """The first character of `text` no one reading it could see or trust, if any: a control,
    a line break, a bidi override, a zero-width or otherwise invisible character
    (`choreo.textfit.is_hidden`), a private-use or unassigned one. A show's name, a label or an
    `hth4_name` is shown to people: one holding such a character is refused where it is written
    (`choreo validate`) and cleaned where it is made (`choreo import`)."""
    return next((ch for ch in text if is_hidden(ch) or unicodedata.category(ch) in _UNKNOWN), None)


_UNKNOWN = frozenset(("Co", "Cn"))  # private use, unassigned


_NAME_TAIL = frozenset(("Mn", "Mc", "Nd"))  # combining marks, decimal digits


def _is_letter(ch: str) -> bool:
    category = unicodedata.category(ch)
    return category[0] == "L" or category == "Nl"


SOLO = "robot"  # the name a one-robot show's robot goes by (`robot:`)
MACHINE, LINK = "machine", "link"  # `clock:`: the machine's clock (or the music's), or the Ableton Link session's
CLOCKS = (MACHINE, LINK)
LINK_MIN_BPM = 20.0  # the slowest tempo an Ableton Link session takes (Link's own range: 20-999 bpm)
NOMINAL_BPM = 120.0  # `tempo: {bpm: link}`: the tempo a plan is drawn at (the session's is known only at run time)
HOST_NAME_MAX = 32  # characters of a `hosts:` name; the schema's pattern says the same
LINK_METER = 4  # beats a bar (Link's quantum) of a show on the Link clock without `tempo:`
ON_FAULT = ("stop", "continue")  # what the show does when one robot's link fails
GO = "go"  # `at: go`: the cue that waits for the operator's GO, not a time


@dataclass(frozen=True)
class RobotSettings:
    """`robot:`, or one entry of `robots:`; every field optional (the command line overrides
    the link settings)."""

    port: str | None = None
    baud: int | None = None
    timeout: float | None = None  # seconds to wait for one reply
    retries: int | None = None  # extra tries after a failed one (default 2: 3 tries in all)
    layout: str | None = None  # one of `choreo.wire.layouts.LAYOUT_NAMES`; None: not said (the run assumes seed)
    on_abort: int | None = None  # this robot's abort motion; None: the show's `on_abort`
    on_fault: str = "stop"  # `ON_FAULT`: stop the show, or let the other robots go on


SIM_URL = "sim://"  # the built-in simulator's port: a show may name it, a run without a port plays on it
SIM_SCHEME = SIM_URL.removesuffix("://")  # pyserial finds the simulator's handler (sim.protocol_sim) by it


def is_simulator(port: str) -> bool:
    """A port that is the built-in simulator (`sim://...`), not a device or another URL: the
    show's checks, the run's settings, the doctor and the replay ask this one question."""
    return port.lower().startswith(SIM_URL)


def same_port(port: str) -> str:
    """A port as compared for sharing: a device path normalised (`/dev/../dev/ttyUSB0`, a
    trailing space), a URL as written. The show's checks and the run's (a port given on the
    command line) must agree on when two robots would share one device."""
    port = port.strip()
    return os.path.normpath(port) if "://" not in port else port


@dataclass(frozen=True)
class Motion:
    """An entry of the show's `motions:` table."""

    name: str
    number: int
    duration: float | None = None  # expected length in seconds, if the author gave it


@dataclass(frozen=True)
class Step:
    """A `play`, `wait` or `wait: done` step as written in the show, before repeats expand.

    `load_show` resolves motion names to numbers and fills in defaults, so the planner never
    needs the YAML or the `motions:` table.
    """

    path: str  # where it is in the file, e.g. `steps[3].steps[1]`
    kind: StepKind
    line: int = 0  # 1-based line and column of the step, for messages
    column: int = 0
    label: str | None = None
    at: float | None = None  # the cue, if the step has one (seconds, bars and beats resolved)
    at_beat: tuple[int, float] | None = None  # the cue as written in bars and beats, if it was
    go: bool = False  # `at: go`: waits for the operator's GO
    cue: str | None = None  # `cue: 12.5`: the cue's number as written (a cued step; None: numbered in show order)
    motion: int | None = None  # PLAY: the slot
    motion_name: str | None = None  # PLAY: the name it was played by, if any
    seconds: float | None = None  # WAIT: how long; WAIT_DONE: the timeout
    robots: tuple[str, ...] | None = None  # in `steps:` of several robots: who does it (None: all)


@dataclass(frozen=True)
class Repeat:
    """`repeat: N` with nested `steps:`, as written; `compile_plan` expands it N times."""

    path: str
    count: int
    steps: tuple[Step | Repeat, ...]
    line: int = 0
    column: int = 0
    label: str | None = None  # names the first step of the first iteration
    at: float | None = None  # cues the first step of the first iteration
    at_beat: tuple[int, float] | None = None  # that cue as written in bars and beats, if it was
    go: bool = False  # `at: go`: the first step of the first iteration waits for GO
    cue: str | None = None  # `cue:`: the number of that cue, as written
    robots: tuple[str, ...] | None = None  # the robots its steps are for, unless a step says


MAX_TEMPO_BARS = 100_000  # entries of a tempo map (`tempo.bars`); the schema's `maxItems` says the same
MAX_BPM = 400.0  # `tempo.bpm`'s maximum in the schema, and the fastest bar of a tempo map
POSITION_DIGITS = 6  # `Tempo.position` reads beats to a millionth: 150 ns at 400 bpm, far above a cue's 1 ns rounding
MAX_CUE_S = 86400.0  # a day: the latest cue, in seconds (`at`'s maximum in the schema) or in bars and beats


@dataclass(frozen=True)
class Tempo:
    """`tempo:`: where the music's bars and beats fall on the show clock.

    One tempo (`bpm`, `offset` to bar 1) is a straight line. A song played live drifts, and a
    ritardando slows down: for those, `bars` is a tempo map, the show time of each bar's beat 1
    (bar 1 first), and a cue follows the map. Within a bar the beats are evenly spaced; before
    bar 1 and after the last bar the nearest bar's length goes on, as a sequencer carries its
    last tempo on past the end of its tempo track. With a map, `bpm` is its median tempo and
    `offset` its bar 1: figures to show, not to place beats by.
    """

    bpm: float
    offset: float = 0.0  # seconds to bar 1, beat 1
    meter: int = 4  # beats a bar
    bars: tuple[float, ...] = ()  # a tempo map: each bar's beat 1 in show seconds, bar 1 first; () for one tempo

    def __post_init__(self) -> None:
        """A map that runs back or stops, or whose bar 1 is not its first entry, is a bug where
        it was made (a show's mistakes are said by its checks): plans and `--json` would show
        one bar 1 and cue by another, and two equal maps would compare unequal."""
        if self.bars:
            _check_map(self.bars)
        if self.bars and self.offset != self.bars[0]:
            raise ValueError(f"a tempo map's offset is its bar 1 ({self.bars[0]}), not {self.offset}")

    @classmethod
    def of_bars(cls, bars: tuple[float, ...], meter: int = 4) -> Tempo:
        """A tempo map from its bars' starts, with the figures shown for it: bar 1, and the
        median of its bars' tempi, not the mean, so that one odd bar (a fermata, a beat the
        tracker missed) does not move the tempo a plan and `--json` report."""
        _check_map(bars)
        return cls(round(statistics.median(_bar_tempi(bars, meter)), 3), bars[0], meter, tuple(bars))

    def seconds(self, bar: int, beat: float = 1.0) -> float:
        """Bar and beat (counted from 1) on the show clock, to the nanosecond. One tempo keeps
        its own arithmetic, operation for operation: a show written before maps existed gets
        the very same cue times (dividing by the meter and multiplying back moves one in a
        hundred thousand by a nanosecond)."""
        if not self.bars:
            return round(self.offset + ((bar - 1) * self.meter + (beat - 1)) * 60.0 / self.bpm, 9)
        where = (bar - 1) + (beat - 1) / self.meter  # in bars from bar 1's downbeat
        index = min(max(math.floor(where), 0), len(self.bars) - 2)  # the bar whose length counts
        start, end = self.bars[index], self.bars[index + 1]
        return round(start + (where - index) * (end - start), 9)

    def position(self, seconds: float) -> tuple[int, float]:
        """(bar, beat) at a show time, both from 1: the inverse of `seconds`. Before bar 1 the
        bars count down from 0, as a count-in's do. Counted in beats and rounded to a millionth
        of one (`POSITION_DIGITS`), so that a cue's own time, which `seconds` rounded to the
        nanosecond, reads back as the very bar and beat written (`{bar: 5, beat: 2.75}`), never
        a hair before it (`(5, 2.749999996)`, or the bar before at a downbeat)."""
        if not self.bars:
            beats = (seconds - self.offset) * self.bpm / 60.0
        else:
            index = min(max(bisect.bisect_right(self.bars, seconds) - 1, 0), len(self.bars) - 2)
            start, end = self.bars[index], self.bars[index + 1]
            beats = (index + (seconds - start) / (end - start)) * self.meter
        bar, within = divmod(round(beats, POSITION_DIGITS), self.meter)
        return int(bar) + 1, round(within + 1, POSITION_DIGITS)

    def past_map(self, bar: int, beat: float = 1.0) -> bool:
        """Whether a tempo map places this beat after its last bar's downbeat, where it has no
        anchor and its last bar's length goes on (never, for one tempo)."""
        return bool(self.bars) and (bar - 1) + (beat - 1) / self.meter > len(self.bars) - 1

    @property
    def bar_bpm(self) -> tuple[float, ...]:
        """The tempo of each bar of a map (the last has no end: it is not counted); () for one tempo."""
        return _bar_tempi(self.bars, self.meter)


def _bar_tempi(bars: tuple[float, ...], meter: int) -> tuple[float, ...]:
    return tuple(60.0 * meter / (b - a) for a, b in pairwise(bars))


def _check_map(bars: tuple[float, ...]) -> None:
    """Refuses bars no tempo could be worked out from, before a division by zero would."""
    if len(bars) < 2 or any(b <= a for a, b in pairwise(bars)):
        raise ValueError("a tempo map needs two or more bars, each after the one before")


def beat_text(beat: float) -> str:
    """A cue's beat as written, `3` or `2.5`, for plans and the console; in full when six digits
    would round it (`4.9999999` is not beat 5, which a bar of 4 does not have)."""
    text = f"{beat:g}"
    return text if float(text) == beat else repr(beat)


MUSIC_FORMATS = (".wav", ".mp3", ".flac", ".ogg")  # what miniaudio decodes
MUSIC_FORMATS_TEXT = ", ".join(f[1:] for f in MUSIC_FORMATS[:-1]) + " or " + MUSIC_FORMATS[-1][1:]  # in messages


@dataclass(frozen=True)
class Music:
    """`music:`: the soundtrack whose playback position is the show clock."""

    file: str  # as written in the show, relative to the show file's folder
    start: float = 0.0  # seconds into the file at show time 0
    folder: str = "."  # the show file's folder, where `file` is looked up

    @property
    def path(self) -> Path:
        return Path(self.folder) / self.file


@dataclass(frozen=True)
class LinkClock:
    """A show on the Ableton Link clock (`clock: link`): the tempo it proposes to the session
    and its meter, which is Link's quantum (the show starts on a bar line of the session)."""

    bpm: float | None  # the tempo proposed; None: the session's (`tempo: {bpm: link}`)
    meter: int = LINK_METER


# Why a show on the Link clock cannot have these, for the located checks and `--clock link` alike.
LINK_NO_GO = "the Link session's beat never stops: a GO cue cannot hold it"
LINK_NO_MUSIC = "the session's beat keeps the show clock, and music is not stretched to a tempo another peer sets"
LINK_NO_MAP = "a tempo map follows a recording's drift, and on the Link clock the session sets the tempo"
LINK_NO_OFFSET = "on the Link clock bar 1 starts at show time 0, on a bar line of the session"


@dataclass(frozen=True)
class Show:
    """A loaded, checked show file."""

    path: str
    name: str
    source: bytes  # the file as read: hashed into the log's metadata and attached to it
    robot: RobotSettings = RobotSettings()  # `robot:`; with `robots:`, the first robot's
    motions: dict[str, Motion] = field(default_factory=dict)
    on_abort: int | None = None  # motion number played when a run is aborted
    steps: tuple[Step | Repeat, ...] = ()  # the steps as written; `compile_plan` flattens them
    robots: dict[str, RobotSettings] = field(default_factory=dict)  # `robots:`, in file order; {} for `robot:`
    tracks: dict[str, tuple[Step | Repeat, ...]] = field(default_factory=dict)  # `tracks:`, by robot
    tempo: Tempo | None = None  # with `bpm: link`, at `NOMINAL_BPM`: the plan's, not the run's
    music: Music | None = None
    clock: str = MACHINE  # `clock:`, one of `CLOCKS`
    link: LinkClock | None = None  # the Link clock's settings (None: not `clock: link`)
    hosts: dict[str, tuple[str, ...]] = field(default_factory=dict)  # `hosts:`: each host's robots; {}: one host

    @property
    def ensemble(self) -> bool:
        """Written for several robots (`robots:`): its robots have names, its log per-robot topics."""
        return bool(self.robots)

    @property
    def cast(self) -> dict[str, RobotSettings]:
        """Every robot by name: `robots:`, or the one robot of a `robot:` show as `robot`."""
        return dict(self.robots) if self.robots else {SOLO: self.robot}

    def host_of(self, robot: str) -> str | None:
        """The host (`hosts:`) that drives `robot`; None in a show for one host."""
        return next((host for host, robots in self.hosts.items() if robot in robots), None)

    def abort_motion(self, robot: str) -> int | None:
        """What `robot` plays when the show is stopped: its own `on_abort`, else the show's."""
        own = self.cast[robot].on_abort
        return own if own is not None else self.on_abort

    def duration_of(self, motion: int) -> float | None:
        """The expected duration the show gives a motion number (by any of its names)."""
        for entry in self.motions.values():
            if entry.number == motion and entry.duration is not None:
                return entry.duration
        return None


class StepKind(str, Enum):
    PLAY = "play"
    WAIT = "wait"
    WAIT_DONE = "wait_done"


@dataclass(frozen=True)
class PlannedStep:
    """One step of the flat plan.

    `planned_s` is the start on the show clock with every motion taking its expected duration;
    at run time `wait: done` re-anchors the clock to when the motion really ended, so the runner
    recomputes due times with the same rule: a step is due at max(`at`, the end of the step
    before it); a play ends when it starts, a wait SECONDS after it starts, a wait-done when the
    board says the motion is over.
    """

    index: int  # 0-based position in the plan
    path: str  # where it comes from, e.g. `steps[3].steps[1]` (repeat iterations: `steps[3]#2.steps[1]`)
    kind: StepKind
    line: int = 0  # 1-based line of the step in the show file, for messages
    label: str | None = None
    motion: int | None = None  # PLAY: the slot; WAIT_DONE: the motion it waits for
    motion_name: str | None = None
    seconds: float | None = None  # WAIT: how long; WAIT_DONE: the timeout
    at: float | None = None  # the cue: not before this many seconds after the show's start
    at_beat: tuple[int, float] | None = None  # the cue as written in bars and beats, if it was
    go: bool = False  # `at: go`: waits for the operator's GO (planned as if it came at once)
    cue: str | None = None  # a cued step (`at:`): its cue number, `1`, `12.5` (show/cues numbers them)
    planned_s: float = 0.0
    expected_s: float = 0.0  # how long the step is expected to take (WAIT_DONE: the motion's rest)
    frames: tuple[Frame, ...] = ()  # what it sends (WAIT_DONE: one status query, repeated)
    robots: tuple[str, ...] | None = None  # in steps for several robots: who does it (None: every robot)

    def is_for(self, robot: str) -> bool:
        return self.robots is None or robot in self.robots

    @property
    def name(self) -> str:
        """How a user refers to the step: its label, else `#index`."""
        return self.label or f"#{self.index}"

    def describe(self) -> str:
        """What the step does, in a show author's words."""
        if self.kind is StepKind.PLAY:
            named = f" ({self.motion_name})" if self.motion_name else ""
            return f"play {self.motion}{named}"
        if self.kind is StepKind.WAIT:
            return f"wait {self.seconds:g} s"
        return f"wait until motion {self.motion} is done (timeout {self.seconds:g} s)"


@dataclass(frozen=True)
class Plan:
    """The flat, timed list of steps a show compiles to."""

    steps: tuple[PlannedStep, ...]
    estimated_s: float  # estimated total duration on the show clock
    layout: str = DEFAULT_LAYOUT  # the board layout whose frames the steps carry
    robot: str = SOLO  # whose plan it is
    unison: bool = False  # shared steps: each starts when every robot it is for is through the one before

    def motions_used(self) -> list[int]:
        return sorted({s.motion for s in self.steps
                       if s.kind is StepKind.PLAY and s.motion is not None and s.is_for(self.robot)})

    def find(self, ref: str) -> int:
        """The index of a step named by `--from`: an index or a label. KeyError if none."""
        index = whole_number(ref) if ref == ref.strip() else None  # `１` and ` 5` are labels
        if index is not None and index < len(self.steps):  # 5,000 digits: no index (int() refuses them)
            return index
        for step in self.steps:
            if step.label == ref:
                return step.index
        raise KeyError(ref)
