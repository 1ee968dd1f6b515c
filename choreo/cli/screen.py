"""What the live console draws: the screen as plain records (`Screen`, `Row`, `Note`), and
`render`, which lays them out with rich to any width from 60 columns.

Apart from `console` (which keeps the run's state, chooses when to draw and reads the keys):
a screen is a value, so what is drawn can be tested, and changed, without a run or a terminal.
"""

from __future__ import annotations

from dataclasses import dataclass

from rich.console import Group, RenderableType
from rich.rule import Rule
from rich.table import Table
from rich.text import Text

from choreo.textfit import visible

LEGEND = "Space/Enter GO · Esc panic · q stop · Ctrl-C stop"
WAITING_STYLE = "bold black on yellow"

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


NARROW = 80  # below this many columns the link column is written short


def render(screen: Screen, width: int = NARROW) -> RenderableType:
    """The console as rich renderables: every line kept to one line of the terminal, whatever
    its width (cells cut with `…`, never wrapped)."""
    parts: list[RenderableType] = [_title(screen), _line(screen.cue),
                                   _line(screen.go, WAITING_STYLE if screen.go_waiting else "bold"),
                                   _robots(screen.rows, width < NARROW), Rule(style="dim")]
    parts += [_line(_note_text(note), note.style) for note in screen.notes] or [_line("(no messages yet)", "dim")]
    if screen.prompt is not None:
        parts.append(_line(screen.prompt, "bold reverse"))
    else:
        parts.append(_line(screen.legend, "dim"))
    return Group(*parts)


def _line(text: str, style: str = "") -> Text:
    return Text(visible(text), style=style, no_wrap=True, overflow="ellipsis", end="\n")


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
