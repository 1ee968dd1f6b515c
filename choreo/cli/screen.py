"""What the live console draws: the screen as plain records (`Screen`, `CueLine`, `Row`,
`Note`), and `render`, which lays them out with rich to any width from 60 columns and, given the
terminal's height, to its lines (8 robots and a cue list fit 80x24).

Apart from `console` (which keeps the run's state, chooses when to draw and reads the keys):
a screen is a value, so what is drawn can be tested, and changed, without a run or a terminal.
"""

from __future__ import annotations

import bisect
import re
import sys
from dataclasses import dataclass

from rich.console import Group, RenderableType
from rich.rule import Rule
from rich.table import Table
from rich.text import Text

from choreo.textfit import ELLIPSIS, char_width, display_width, fit, visible

LEGEND = "Space/Enter GO · ↑↓ playhead · s skip · j jump · p pause · Esc panic · q stop"
SHORT_LEGEND = "Spc GO ↑↓ cue s skip j jump p pause Esc panic q stop"  # below NARROW columns
PAUSED_LEGEND = "Space/Enter GO · ↑↓ playhead · s skip · j jump · p RESUME · Esc panic · q stop"
SHORT_PAUSED_LEGEND = "Spc GO ↑↓ cue s skip j jump p RESUME Esc panic q stop"
SHORT = {LEGEND: SHORT_LEGEND, PAUSED_LEGEND: SHORT_PAUSED_LEGEND}  # each legend below NARROW columns
WAITING_STYLE = "bold black on yellow"
PLAYHEAD_STYLE = "bold reverse"
STATE_STYLES = {"waiting": WAITING_STYLE, "running": "green", "done": "dim", "skipped": "dim strike"}
MIN_QUOTED = 6  # a quoted name in a message is cut to no fewer columns than this

@dataclass(frozen=True)
class Note:
    """A line of the console's log pane: a run's log line or a command's answer."""

    text: str
    style: str = ""
    show_s: float | None = None
    aside: str = ""  # who sent the command (an OSC sender): said after it, and cut first


@dataclass(frozen=True)
class Row:
    """A robot's line: its step now, its next step, its link's health."""

    robot: str
    now: str
    next: str
    latency_ms: float | None  # the median of the last replies (None: no reply yet)
    retries: int = 0
    now_style: str = ""
    trouble: bool = False  # a retry or a failed reply so far


@dataclass(frozen=True)
class CueLine:
    """A cue of the list: number, label, robots, when the plan puts it, and its state."""

    number: str
    label: str
    robots: str
    when: str  # `GO ~12.0 s`, `@12.0 s`, `@12.0 s 5.1` (bar 5, beat 1)
    state: str  # ahead | waiting | running | done | skipped, or a countdown (`in 3.2 s`)
    style: str = ""


@dataclass(frozen=True)
class Screen:
    """Everything the console draws at one moment, taken under the lock and drawn outside it."""

    title: str
    show_s: float | None  # None: the show clock has not started
    clock: str  # which clock keeps the show, and whether it holds
    cue: str  # the countdown to the next timed cue
    go: str  # the next GO cue (waiting now, or coming)
    go_waiting: bool
    rows: tuple[Row, ...]
    notes: tuple[Note, ...]
    prompt: str | None = None  # a question the next key answers
    legend: str = LEGEND
    bar: tuple[int, int] | None = None  # bar and beat of the music now, in a show with `tempo:`
    cues: tuple[CueLine, ...] = ()  # a window of the cue list around the playhead
    playhead: int | None = None  # the playhead's place in `cues` (None: no cue under it)
    waits: tuple[str, ...] = ()  # robots sharing a GO cue they wait at: one line for them all


NARROW = 80  # below this many columns the link column is written short


def render(screen: Screen, width: int = NARROW, height: int | None = None) -> RenderableType:
    """The console as rich renderables: every line kept to one line of the terminal, whatever
    its width (cells cut with `…`, messages by `fit_message`, never wrapped), and, given the
    terminal's `height`, as many of the cues and notes as fit under it."""
    narrow = width < NARROW
    fixed = 4 + len(screen.waits) + (1 + len(screen.rows) if screen.rows else 0) + 1
    cues_n, notes_n = _shares(len(screen.cues), len(screen.notes), None if height is None else height - 1 - fixed)
    parts: list[RenderableType] = [_title(screen), _line(screen.cue, width=width),
                                   _line(screen.go, WAITING_STYLE if screen.go_waiting else "bold", width)]
    if screen.cues:
        parts.append(_cue_table(screen, cues_n, narrow))
    parts += [_line(wait, WAITING_STYLE, width) for wait in screen.waits]
    if screen.rows:
        parts.append(_robots(screen.rows, narrow))
    parts.append(Rule(style="dim"))
    notes = screen.notes[len(screen.notes) - notes_n:] if notes_n else ()
    parts += [_line(_note_text(note), note.style, width, note.aside) for note in notes] or \
        [_line("(no messages yet)", "dim")]
    if screen.prompt is not None:
        parts.append(_line(screen.prompt, "bold reverse", width))
    else:
        legend = SHORT.get(screen.legend, screen.legend) if narrow else screen.legend
        parts.append(_line(legend, "dim", width))
    return Group(*parts)


def _shares(cues: int, notes: int, room: int | None) -> tuple[int, int]:
    """How many cue lines and note lines fit in `room` lines (None: all); the cue list first,
    at least 3 of it (or all it has), and a note at least."""
    if room is None:
        return cues, notes
    shown = min(cues, max(3, room - min(notes, 3)))
    return shown, max(1, min(notes, room - shown))


def _cue_table(screen: Screen, rows: int, narrow: bool) -> Table:
    """The first cues of the window that fit, moved on if the playhead's line would fall
    past them (one cue after it shown then, when there is one)."""
    first = 0
    if screen.playhead is not None and screen.playhead >= rows - 1:  # kept in, with one after it
        first = max(0, min(screen.playhead - rows + 2, len(screen.cues) - rows))
    table = Table(expand=True, box=None, show_header=False, show_edge=False, pad_edge=False, padding=(0, 1, 0, 0))
    table.add_column("", no_wrap=True, width=1)
    table.add_column("cue", no_wrap=True, overflow="ellipsis", max_width=6)
    table.add_column("label", ratio=2, no_wrap=True, overflow="ellipsis")
    table.add_column("robots", ratio=1, no_wrap=True, overflow="ellipsis", max_width=18)
    table.add_column("when", no_wrap=True, overflow="ellipsis", max_width=16 if narrow else 20)
    table.add_column("state", no_wrap=True, overflow="ellipsis", max_width=9)
    for at in range(first, min(first + rows, len(screen.cues))):
        cue = screen.cues[at]
        head = at == screen.playhead
        table.add_row(_cell(">" if head else " "), _cell(cue.number), _cell(cue.label), _cell(cue.robots),
                      _cell(cue.when), _cell(cue.state, cue.style), style=PLAYHEAD_STYLE if head else "")
    return table


def fit_message(text: str, width: int, aside: str = "") -> str:
    """`text` made visible and fitted to `width` columns, keeping what tells the operator what
    to do: its tail (`_tail_at`: what follows a `: ` or `; `). `aside` (who sent a command)
    is written after it in brackets and cut first: down to MIN_QUOTED columns, then left out.
    Then the outside text (a cue's label, a file's name, an OSC address: `'...'`, `/...`) is
    cut, the longest first: before the tail to MIN_QUOTED columns, in the tail to TAIL_QUOTED
    (a suggested address stays whole), before the tail to 2; then the end of what comes
    before the tail, down to MIN_HEAD columns; then the tail's outside text to MIN_QUOTED; and
    last the middle of it all: both the start (what happened) and the end (what to do) stay.
    An address is cut to no fewer than MIN_ADDRESS columns (it names the command sent), and a
    message with no tail keeps twice as much of its start as of its end."""
    if len(text) > LONGEST_FITTED:  # a (hostile) message of any length costs no more than this
        text = text[:LONGEST_FITTED // 4] + ELLIPSIS + text[-(LONGEST_FITTED * 3 // 4):]
    text, aside = visible(text), visible(aside[:LONGEST_FITTED])
    if aside:
        whole = f"{text} ({aside})"
        room = width - display_width(text) - 3
        if display_width(whole) <= width or room >= MIN_QUOTED:
            return f"{text} ({fit(aside, room)})" if display_width(whole) > width else whole
    if display_width(text) <= width:
        return text
    tail_at = _tail_at(text, width - min(MIN_HEAD, width // 2))
    for floor, in_tail in ((MIN_QUOTED, False), (TAIL_QUOTED, True), (2, False)):
        text, tail_at = _cut_outside(text, width, tail_at, floor, in_tail)
    room = width - min(MIN_HEAD, width // 2)  # for the tail, a start of the message kept
    if display_width(text) > width and tail_at < len(text) and display_width(text[tail_at:]) > room:
        target = max(width, display_width(text[:tail_at]) + room)  # it fits, or its tail fits `room`
        text, tail_at = _cut_outside(text, target, tail_at, MIN_QUOTED, in_tail=True)
    if display_width(text) <= width:
        return text
    head, tail = text[:tail_at], text[tail_at:]
    if tail and display_width(tail) <= room:
        return fit(head, width - display_width(tail)) + tail
    return _middle_cut(text, width, 2 if not tail else 1)  # no tail: more of what happened (`unknown command /x`)


QUOTED = re.compile(r"'([^']{2,})'")
ADDRESS = re.compile(r"(?<![\w'/])(/[^\s'()]+[^\s'():;,.?!])")  # an OSC address, a path: outside text
TAIL = re.compile(r"[:;] ")  # one of them, outside quoted text, begins what a message says to do
LONGEST_FITTED = 1024  # characters of a message fitted: its start and its end beyond that
MIN_ADDRESS = 16  # an OSC address (or a path) is cut to no fewer columns: it names the command sent
MIN_HEAD = 16  # columns of a message's start kept before its tail (what happened)
TAIL_QUOTED = 16  # outside text in a message's tail is cut to no fewer columns than this first (a long label)


def _spans(text: str) -> list[tuple[int, int]]:
    """Where the outside text is (quoted, addresses), in order, none inside another."""
    quoted = [m.span(1) for m in QUOTED.finditer(text)]
    inside = [m.span(1) for m in ADDRESS.finditer(text) if _within(quoted, m.start(1)) is None]
    return sorted(quoted + inside)


def _within(spans: list[tuple[int, int]], at: int) -> tuple[int, int] | None:
    """The span of `spans` (in order, apart) that holds `at`, found by bisection."""
    found = bisect.bisect_right(spans, (at, sys.maxsize)) - 1
    return spans[found] if found >= 0 and spans[found][0] <= at < spans[found][1] else None


def _tail_at(text: str, room: int) -> int:
    """Where the message's tail begins: after the first `: ` or `; ` (outside the outside text)
    from which the rest fits `room` columns, else after the last `: ` (its end, when it has
    none: it is cut in its outside text, then its middle)."""
    spans = _spans(text)
    ends = [m.end() for m in TAIL.finditer(text) if _within(spans, m.start()) is None]
    left, at = display_width(text), 0  # the width from `at` on, measured once along the text
    for end in ends:
        left -= display_width(text[at:end])
        at = end
        if left <= room:
            return end
    return ends[-1] if ends else len(text)


def _cut_outside(text: str, width: int, tail_at: int, floor: int, in_tail: bool) -> tuple[str, int]:
    """`text` with its outside text (in its tail, or before it) cut, the longest first, down
    to `floor` columns each, until it fits; and where its tail now begins. One pass, however
    many pieces a (hostile) message holds."""
    excess = display_width(text) - width
    if excess <= 0:
        return text, tail_at
    spans = sorted(((display_width(text[a:b]), a, b) for a, b in _spans(text) if (a >= tail_at) == in_tail),
                   key=lambda span: -span[0])
    cuts: list[tuple[int, int, str]] = []
    for size, start, end in spans:
        least = max(floor, MIN_ADDRESS) if text[start] == "/" else floor  # an address says which command
        if excess <= 0:
            break
        if size <= least:
            continue
        cut = fit(text[start:end], max(least, size - excess))
        excess -= size - display_width(cut)
        cuts.append((start, end, cut))
    pieces, at = [], 0
    for start, end, cut in sorted(cuts):
        pieces += [text[at:start], cut]
        at = end
        if start < tail_at:
            tail_at -= (end - start) - len(cut)
    return "".join(pieces) + text[at:], tail_at


def _middle_cut(text: str, width: int, start_share: int = 1) -> str:
    """Its start and its end, with `…` between, in `width` columns: the start `start_share`
    times as wide as the end."""
    head = fit(text, (width * start_share + start_share) // (start_share + 1))
    tail_room = width - display_width(head)
    tail = ""
    for char in reversed(text):
        if display_width(tail) + char_width(char) > tail_room:
            break
        tail = char + tail
    return head + tail


def _line(text: str, style: str = "", width: int | None = None, aside: str = "") -> Text:
    """A line of the screen; given its `width`, fitted by `fit_message` (else rich cuts its end)."""
    shown = visible(text + (f" ({aside})" if aside else "")) if width is None else fit_message(text, width, aside)
    return Text(shown, style=style, no_wrap=True, overflow="ellipsis", end="\n")


def _cell(text: str, style: str = "") -> Text:
    """Every text drawn holds outside text (a show's names, an OSC address): made visible."""
    return Text(visible(text), style=style)


def _note_text(note: Note) -> str:
    return f"{seconds(note.show_s):>7} s  {note.text}" if note.show_s is not None else f"{'':11}{note.text}"


def seconds(value: float, digits: int | None = 1) -> str:
    """A time as the console writes it: `digits` decimals (None: as short as it goes, `4`,
    `12.5`), and never `-0.0` (a time a hair before zero, a show clock just started or a
    countdown just run out, is 0.0)."""
    if digits is not None:
        value = round(value, digits)
    value = value if value != 0 else 0.0  # -0.0 == 0
    return f"{value:g}" if digits is None else f"{value:.{digits}f}"


def _title(screen: Screen) -> Table:
    """The show's name, cut first; its time and clock, kept whole as long as they fit."""
    grid = Table.grid(expand=True)
    grid.add_column(ratio=1, no_wrap=True, overflow="ellipsis")
    grid.add_column(no_wrap=True, overflow="ellipsis", justify="right")
    time = f"{seconds(screen.show_s)} s" if screen.show_s is not None else "not started"
    bar = f" · bar {screen.bar[0]}.{screen.bar[1]}" if screen.bar is not None else ""  # 12.3: bar 12, beat 3
    grid.add_row(_cell(screen.title, "bold"), _cell(f" show {time}{bar} · {screen.clock}"))
    return grid


def _robots(rows: tuple[Row, ...], narrow: bool) -> Table:
    """A row a robot; `now` and `next` share what the name and link columns leave."""
    table = Table(expand=True, box=None, show_edge=False, pad_edge=False, padding=(0, 1, 0, 0),
                  header_style="dim")
    table.add_column("robot", no_wrap=True, overflow="ellipsis", max_width=12)
    table.add_column("now", ratio=1, no_wrap=True, overflow="ellipsis")
    table.add_column("next", ratio=1, no_wrap=True, overflow="ellipsis")
    table.add_column("link" if narrow else "link (median, retries)", no_wrap=True, overflow="ellipsis",
                     max_width=24)
    for row in rows:
        table.add_row(_cell(row.robot), _cell(row.now, row.now_style), _cell(row.next),
                      _cell(_link_text(row, narrow), "yellow" if row.trouble else ""))
    return table


def _link_text(row: Row, narrow: bool) -> str:
    """`1.6 ms, 0 retries`; narrow, `1.6ms r0`."""
    if narrow:
        latency = f"{row.latency_ms:.1f}ms" if row.latency_ms is not None else "-ms"
        return f"{latency} r{row.retries}"
    latency = f"{row.latency_ms:.1f} ms" if row.latency_ms is not None else "- ms"
    return f"{latency}, {row.retries} retr{'y' if row.retries == 1 else 'ies'}"
