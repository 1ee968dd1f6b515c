"""What the live console draws: the screen as plain records (`Screen`, `CueLine`, `Row`,
`Note`), and `render`, which lays them out with rich to any width from 60 columns and, given the
terminal's height, to its lines (8 robots and a cue list fit 80x24).

Apart from `console` (which keeps the run's state, chooses when to draw and reads the keys):
a screen is a value, so what is drawn can be tested, and changed, without a run or a terminal.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from rich.console import Group, RenderableType
from rich.rule import Rule
from rich.table import Table
from rich.text import Text

from choreo.textfit import char_width, display_width, fit, visible

LEGEND = "Space/Enter GO · ↑↓ playhead · s skip · j jump · p pause · Esc panic · q stop"
SHORT_LEGEND = "Spc GO ↑↓ cue s skip j jump p pause Esc panic q stop"  # below NARROW columns
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
    parts += [_line(_note_text(note), note.style, width) for note in notes] or [_line("(no messages yet)", "dim")]
    if screen.prompt is not None:
        parts.append(_line(screen.prompt, "bold reverse", width))
    else:
        legend = SHORT_LEGEND if narrow and screen.legend == LEGEND else screen.legend
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


def fit_message(text: str, width: int) -> str:
    """`text` made visible and fitted to `width` columns, keeping what tells the operator what
    to do: the quoted parts (a cue's label, a file's name: outside text, `'...'`) are cut
    first, the longest first, down to MIN_QUOTED columns; if it is still too wide, its middle
    goes (`…`), so both the start (what happened) and the end (what to do) stay."""
    text = visible(text)
    while display_width(text) > width:
        quoted = [(display_width(m.group(1)), m) for m in QUOTED.finditer(text)]
        longest = max(quoted, key=lambda q: q[0], default=None)
        if longest is None or longest[0] <= MIN_QUOTED:
            break
        size, match = longest
        keep = max(MIN_QUOTED, size - (display_width(text) - width))
        text = text[:match.start(1)] + fit(match.group(1), keep) + text[match.end(1):]
    if display_width(text) <= width:
        return text
    head = fit(text, (width + 1) // 2)
    tail_room = width - display_width(head)
    tail = ""
    for char in reversed(text):
        if display_width(tail) + char_width(char) > tail_room:
            break
        tail = char + tail
    return head + tail


QUOTED = re.compile(r"'([^']{2,})'")


def _line(text: str, style: str = "", width: int | None = None) -> Text:
    """A line of the screen; given its `width`, fitted by `fit_message` (else rich cuts its end)."""
    shown = visible(text) if width is None else fit_message(text, width)
    return Text(shown, style=style, no_wrap=True, overflow="ellipsis", end="\n")


def _cell(text: str, style: str = "") -> Text:
    """Every text drawn holds outside text (a show's names, an OSC address): made visible."""
    return Text(visible(text), style=style)


def _note_text(note: Note) -> str:
    return f"{note.show_s:7.1f} s  {note.text}" if note.show_s is not None else f"{'':11}{note.text}"


def _title(screen: Screen) -> Table:
    """The show's name, cut first; its time and clock, kept whole as long as they fit."""
    grid = Table.grid(expand=True)
    grid.add_column(ratio=1, no_wrap=True, overflow="ellipsis")
    grid.add_column(no_wrap=True, overflow="ellipsis", justify="right")
    time = f"{screen.show_s:.1f} s" if screen.show_s is not None else "not started"
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
