"""The live console of `choreo run` on a terminal: where the show is, its cue list with the
playhead (the cue GO fires next), how the robots and their links are doing, and the operator's
keys (GO, playhead, skip, jump, pause, panic, stop).

It is a listener like the others (the run's log lines, the operator's commands) and keeps only
what it draws; where each robot is and how its link does it reads from the run's `ShowStatus`
(the record `/choreo/status` reads too), the cue list, each cue's state and the playhead from
`Live`. The keys' commands go through `Live` as well, so a key is answered exactly as an OSC
message would be, and the log records it the same way.

Two things it must never do. Delay the show: the runners call its listener methods on their
own path, so those only note what happened under a short lock; drawing happens in its own
thread, which also keeps clear of the moments a step falls due or a GO was just given (a redraw
holds Python's lock for a few milliseconds, and a runner woken then would wait for it), and
draws only what changed: while a GO cue waits or the show is paused, the clock holds and the
screen stays still, so the GO, when it comes, finds nothing drawing.
And leave the terminal unusable: the key mode (cbreak, no echo) is undone on every way out.

rich lays the screen out (a table whose columns share the width, every cell cut with `…`), so
it fits any width from 60 columns; everything goes to `out` (stderr): stdout is for --json.
"""

from __future__ import annotations

import math
import os
import sys
import termios
import threading
from collections import deque
from collections.abc import Callable
from contextlib import suppress
from typing import TextIO, cast

from rich.console import Console as RichConsole
from rich.console import RenderableType
from rich.control import Control
from rich.file_proxy import FileProxy
from rich.live import Live as RichLive

from choreo.cli.keys import PASTE_OFF, PASTE_ON, KeyReader, TerminalMode, in_foreground
from choreo.cli.screen import (
    LEGEND,
    NARROW,
    PAUSED_LEGEND,
    STATE_STYLES,
    WAITING_STYLE,
    CueLine,
    Note,
    Row,
    Screen,
    render,
    seconds,
)
from choreo.cli.terminal import raw_stream, visible_stream
from choreo.events import Command, CommandEvent, GoCue, StepEvent, Subscription
from choreo.live.controls import HoldingShowClock, Live
from choreo.live.status import RobotRow, ShowStatus
from choreo.log.format import ERROR, INFO, WARNING
from choreo.show.cues import Cue, CueList
from choreo.show.model import PlannedStep, beat_text
from choreo.sync.clock import LinkShowClock
from choreo.sync.session import peers_text
from choreo.textfit import fit

REFRESH_S = 0.2  # five looks a second: the show time moves smoothly enough (and is drawn to 0.1 s)
QUIET_BEFORE_S = 0.06  # no redraw starts this close before a step falls due (a cue's lead included)
QUIET_AFTER_S = 0.03  # nor this soon after it, or after a GO (its frames go out then)
MAX_POSTPONE_S = 0.5  # cues closer together than this still let the screen move
NOTES = 5  # lines of log and answers on screen
CUE_WINDOW = 9  # cues of the list on screen at most (render shows fewer on a short terminal)
MAX_TYPED = 40  # characters a cue reference typed after `j` may have
NAMES = 2  # robots named on a line they share (`left, right +3`)
NEXT_TIMED_LOOKS = 64  # timed cues looked at for the next one ahead (those before it ran or were skipped)

QUESTION = "stop the show? y/n"
JUMP = "jump to cue (number or label, Enter; Enter alone cancels): {typed}_"  # what is typed last: a cut keeps it
STYLES = {ERROR: "bold red", WARNING: "yellow", INFO: ""}


def _step_text(step: PlannedStep) -> str:
    """`GO cue 1 'bow': play 1`, `@4 s cue 2: play 2`: a cue's step by its number in the cue
    list (one number a cue on the whole screen); a step between cues by what it does."""
    label = f"'{step.label}'" if step.label else ""
    if step.cue is None:
        return f"{label}: {step.describe()}" if label else step.describe()
    when = "GO " if step.go else f"@{seconds(step.at, None)} s " if step.at is not None else ""
    return f"{when}cue {step.cue}{' ' + label if label else ''}: {step.describe()}"


def _names(robots: list[str] | tuple[str, ...]) -> str:
    """`left, right +3`: the first NAMES robots (each cut to 12 columns) and how many more."""
    shown = ", ".join(fit(name, 12) for name in robots[:NAMES])
    return shown + (f" +{len(robots) - NAMES}" if len(robots) > NAMES else "")


def _firsts(cues: CueList, kind: Callable[[Cue], bool]) -> tuple[int, ...]:
    """For each position in the list, the first cue of `kind` from it on (len: none)."""
    first, later = [len(cues.cues)] * (len(cues.cues) + 1), len(cues.cues)
    for at in range(len(cues.cues) - 1, -1, -1):
        later = at if kind(cues.cues[at]) else later
        first[at] = later
    return tuple(first)


# -- the console -------------------------------------------------------------------------------


class Console:
    """The live console; see the module's docstring. Created by `choreo run` when stdin and
    stderr are terminals, started once the ports are open, closed when the run is over."""

    def __init__(self, session, live: Live, *, status: ShowStatus | None = None, out: TextIO | None = None,
                 keys: TextIO | None = None, width: int | None = None, height: int | None = None) -> None:
        """`status`: the run's robot status (None: the console keeps its own, told the steps
        it hears and subscribed to the links at `start`); `out`: where it draws (default
        stderr); `keys`: the terminal it reads (default stdin; one that is not a terminal
        gives no keys); `width`, `height`: fixed, for tests."""
        out = out if out is not None else raw_stream(sys.stderr)  # it draws: its escapes are its own
        self.session = session
        self.live = live
        self.out = out
        self.keys = keys if keys is not None else sys.stdin
        self._lock = threading.Lock()
        settings = session.settings
        self._own_status = status is None  # then it is told the steps, and watches the links, itself
        self.status = status if status is not None else ShowStatus(settings.plans, settings.sections.starts)
        self._cues: CueList = live.cues  # the live controls keep the cue list and each cue's state
        self._timed = _firsts(self._cues, lambda cue: not cue.go and cue.at is not None)
        self._typed: str | None = None  # a cue reference being typed after `j`
        self._notes: deque[Note] = deque(maxlen=NOTES)
        self._asking = False
        self._closing = False
        self._quiet_until = 0.0  # monotonic time before which no redraw starts (a GO's frames)
        self._done = threading.Event()
        self._watches: list[Subscription] = []  # its listeners on the links, detached at `close`
        self._mode: TerminalMode | None = None
        self._reader: KeyReader | None = None
        self._redraw: threading.Thread | None = None
        self._width = width  # fixed (tests); None: the terminal's, measured at each redraw
        self._height = height
        # rich would read COLUMNS and LINES with int() (`²` or 5,000 digits: ValueError); the
        # console measures the terminal itself, so rich is given an environment without them
        environ = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
        self._screen = RichConsole(file=out, width=width, highlight=False, emoji=False, markup=False,
                                   _environ=environ)
        self._rich = RichLive(console=self._screen, auto_refresh=False, transient=False,
                              redirect_stdout=False, redirect_stderr=out is sys.__stderr__)
        self._drawn: tuple[Screen, int] | None = None  # what is on the terminal, at which width

    # -- starting and stopping -----------------------------------------------------------------

    def start(self) -> None:
        """Keys, link listeners and the screen; if any of them fails, the terminal is put back."""
        try:
            self._take_keys()
            self._watch_links()
            self._rich.start()
            # rich now prints what is written to stderr above the screen (its own print, which
            # leaves escape sequences raw): made visible first, until rich puts stderr back
            if isinstance(sys.stderr, FileProxy):
                sys.stderr = visible_stream(cast(TextIO, sys.stderr))  # rich's FileProxy is a text stream
            self._draw()
            self._redraw = threading.Thread(target=self._redraw_loop, name="choreo-console", daemon=True)
            self._redraw.start()
        except BaseException:
            self.close()
            raise

    def _take_keys(self) -> None:
        if not self.keys.isatty():
            return
        fd = self.keys.fileno()
        if not in_foreground(fd):
            self._add(Note("keys off: choreo runs in the background (bring it back with fg)", "yellow"))
            return
        self._mode = TerminalMode(fd)
        self._mode.enter()
        self._bracket_pastes(True)
        self._reader = KeyReader(fd, self.on_key, text_wanted=self.typing)
        self._reader.start()

    def close(self) -> None:
        """Stop reading keys and drawing, leave the last screen (saying how the show ended) and
        put the terminal back as it was, whatever fails on the way."""
        self._done.set()
        try:
            if self._reader is not None:
                self._reader.close()
            if self._redraw is not None and self._redraw is not threading.current_thread():
                self._redraw.join(1.0)
            for watch in self._watches:
                watch.close()
            self._watches.clear()
            with self._lock:
                self._closing = True
                self._asking = False
            for last in (self._draw, self._rich.stop):  # stop also shows the cursor again
                with suppress(OSError, ValueError):  # the terminal went away: nothing left to draw on
                    last()
        finally:
            self._restore_terminal()

    def _bracket_pastes(self, on: bool) -> None:
        """Ask the terminal to mark a paste's start and end (`KeyParser` skips what is between):
        unmarked, a pasted `qy` would stop the show and every space in it be a GO."""
        try:
            self.out.write(PASTE_ON if on else PASTE_OFF)
            self.out.flush()
        except (OSError, ValueError):
            pass  # no screen to ask: its keys are not read either

    def _restore_terminal(self) -> None:
        mode, self._mode = self._mode, None
        if mode is not None:
            self._bracket_pastes(False)
            with suppress(termios.error, OSError):  # the terminal is gone (hung up): no mode left to restore
                mode.restore()

    def _watch_links(self) -> None:
        """Its own status's links (the run's status is subscribed by whoever made it)."""
        stage = self.session.stage  # None until the session opens: no links to watch yet
        if not self._own_status or stage is None:
            return
        for name, link in stage.links.items():
            self._watches.append(link.subscribe(self.status.link_listener(name)))

    def _redraw_loop(self) -> None:
        """Redraw REFRESH_S apart, each put off past any moment a runner is about to send."""
        while not self._done.wait(REFRESH_S):
            if self._done.wait(self._quiet_left()):
                return
            try:
                self._draw()
            except (OSError, ValueError):
                return  # the terminal is gone; the show goes on without its screen

    def _draw(self) -> None:
        """Redraw, if anything on screen would change (the terminal's width included)."""
        screen = self.screen()
        self._fit_terminal()
        drawn = (screen, self._screen.width)
        if drawn != self._drawn:
            if self._drawn is not None and drawn[1] != self._drawn[1]:
                self._start_afresh()
            self._rich.update(render(screen, drawn[1], self._lines()), refresh=True)
            self._drawn = drawn

    def _start_afresh(self) -> None:
        """The terminal's width changed. Many terminals (tmux, VTE, iTerm2, kitty) re-wrap what
        is on screen then, so the lines drawn before no longer sit where a redraw would move
        up to: it would leave pieces of them, wider than the terminal, above the new screen.
        The screen is cleared and the console drawn from its top instead."""
        live_render = getattr(self._rich, "_live_render", None)
        if live_render is None or not hasattr(live_render, "_shape"):
            return  # a rich that keeps its shape elsewhere: leave it to rich
        with getattr(self._rich, "_lock", threading.RLock()):
            self._screen.control(Control.clear(), Control.home())
            live_render._shape = None  # nothing of the old screen left to move over

    def _quiet_left(self) -> float:
        """How long until no runner is about to send (0: now), at most MAX_POSTPONE_S."""
        now = self.session.clock.mono()
        dues = self._due_windows()
        with self._lock:
            windows = [(self._quiet_until - QUIET_AFTER_S, self._quiet_until)] + dues
        until = now
        for start, end in sorted(windows):
            if start <= until < end:
                until = end
        return min(until - now, MAX_POSTPONE_S)

    def _lines(self) -> int | None:
        """The terminal's height (the screen is cut to it), if known."""
        if self._height is not None or self._width is not None:
            return self._height
        return self._screen.size.height

    def _fit_terminal(self) -> None:
        """The terminal's own size, measured on `out`: it may be resized mid-show, and an
        exported COLUMNS or LINES (which rich would take over it) may say otherwise."""
        if self._width is not None:
            return
        try:
            size = os.get_terminal_size(self.out.fileno())
        except (OSError, ValueError, AttributeError):
            return  # not a terminal: rich's own guess
        if size.columns > 0 and size.lines > 0:
            self._screen.size = (size.columns, size.lines)

    def _due_windows(self) -> list[tuple[float, float]]:
        """Monotonic windows around each robot's next due time."""
        show = self.live.show
        if show is None:
            return []
        windows = []
        for robot in self.status.robots(self.live.skipped):
            for due in robot.due_s:
                mono = show.mono_at(due)
                windows.append((mono - QUIET_BEFORE_S, mono + QUIET_AFTER_S))
        return windows

    # -- keys ----------------------------------------------------------------------------------

    def on_key(self, key: str) -> None:
        """A key from the reader; a command that fails is said on screen, and the keys go on."""
        try:
            self._on_key(key)
        except Exception as exc:  # noqa: BLE001 - the next key must still work (Esc above all)
            self._add(Note(f"key {key!r} failed: {exc}", "bold red", self._show_s()))

    def _on_key(self, key: str) -> None:
        """Esc panics whatever else is going on; a question takes the next key as its answer,
        a cue reference being typed (`j`) the keys up to Enter; else each key is a command."""
        if key == "escape":
            self._ask(False)
            self._type(None)
            self.live.command(Command("panic", "key"))
            return
        if key == "paste":  # text pasted on a terminal that does not mark pastes: no key of it
            self._add(Note("a paste is no key: ignored (type a cue's number after j)", "yellow", self._show_s()))
            return
        with self._lock:
            asking, typed = self._asking, self._typed
        if asking:
            self._ask(False)
            if key in ("y", "Y"):
                self.live.command(Command("stop", "key"))
            else:
                self._add(Note("stop cancelled: the show goes on", "dim", self._show_s()))
        elif typed is not None:
            self._typing(key, typed)
        else:
            self._command_key(key)

    def _command_key(self, key: str) -> None:
        """Space or Enter is GO (which also starts a show loaded with --wait-start); a letter
        is its command in either case (Caps Lock on must not leave the operator without q)."""
        key = key.lower() if len(key) == 1 else key
        names = {"up": "playhead_previous", "down": "playhead_next", "s": "skip"}
        if key in ("space", "enter"):
            self.live.command(Command("go" if self.live.started else "start", "key"))
        elif key in names:
            self.live.command(Command(names[key], "key"))
        elif key == "p":
            self.live.command(Command("resume" if self.live.paused else "pause", "key"))
        elif key == "j":
            self._type("")
        elif key == "q":
            self._ask(True)

    def _typing(self, key: str, typed: str) -> None:
        """A key while a cue reference is typed: Enter jumps there (an empty one cancels),
        Backspace and Ctrl-U erase, printable characters (Space too) are typed, up to MAX_TYPED."""
        if key == "enter":
            self._type(None)
            if typed.strip():
                self.live.command(Command("playhead", "key", typed.strip()))
            else:
                self._add(Note("jump cancelled", "dim", self._show_s()))
        elif key == "backspace":
            self._type(typed[:-1])
        elif key == "ctrl-u":
            self._type("")
        elif len(typed) < MAX_TYPED and (key == "space" or len(key) == 1 and key.isprintable()):
            self._type(typed + (" " if key == "space" else key))

    def typing(self) -> bool:
        """Whether a cue reference is being typed after `j`: the reader then hands on what
        comes as typed (an input method commits a whole word in one write: no paste)."""
        with self._lock:
            return self._typed is not None

    def _ask(self, asking: bool) -> None:
        with self._lock:
            self._asking = asking

    def _type(self, typed: str | None) -> None:
        with self._lock:
            self._typed = typed

    # -- listeners -----------------------------------------------------------------------------

    def on_step(self, event: StepEvent) -> None:
        """Told to its own status only: the run's status hears the run itself."""
        if self._own_status:
            self.status.on_step(event)

    def on_log(self, level: int, message: str, time_ns: int | None = None) -> None:
        if level >= INFO:
            self._add(Note(message, STYLES.get(level, "bold red"), self._show_s()))

    def on_command(self, event: CommandEvent) -> None:
        command, answer = event.command, event.answer
        source = "" if command.source == "key" else command.source  # said after, cut first
        if answer.ok and command.name in ("go", "cue_go", "start", "resume", "skip"):
            with self._lock:  # the frames it releases go out now: no redraw in their way
                self._quiet_until = self.session.clock.mono() + QUIET_AFTER_S
        self._add(Note(answer.message, "green" if answer.ok else "bold red", event.show_s, source))

    def on_play_out(self, end_s: float) -> None:
        self._add(Note(f"the steps are done; the music plays to its end at {seconds(end_s)} s", "",
                       self._show_s()))

    def _add(self, note: Note) -> None:
        with self._lock:
            self._notes.append(note)

    def _show_s(self) -> float | None:
        show = self.live.show
        return show.show_at(self.session.clock.mono()) if show is not None else None

    # -- drawing -------------------------------------------------------------------------------

    def renderable(self, width: int = NARROW, height: int | None = None) -> RenderableType:
        return render(self.screen(), width, height)

    def screen(self) -> Screen:
        """What to draw now (the live controls and the status are asked outside the lock)."""
        stopping = self.live.stop()
        waiting = [] if stopping else self.live.waiting  # a stopped show's GO cues wait for nothing
        show_s = self._show_s()
        robots = self.status.robots(self.live.skipped)  # a skipped cue is no robot's next step
        head = None if stopping else self.live.playhead
        first = self._first_open(robots)
        window, at = self._window(head, first)
        states = {cue: self.live.cue_state(cue) for cue in (*window, *(() if head is None else (head,)))}
        groups = self._groups(waiting)
        shared = {name for names, _ in groups if len(names) > 1 for name in names}
        rows = tuple(self._row(robot, groups) for robot in robots if robot.robot not in shared)
        waits = tuple(f"{_names(names)} wait for GO: {name}" for names, name in groups if len(names) > 1)
        cue = "next cue: none, the show is stopping" if stopping else self._cue_line(show_s, first)
        go, go_waiting = self._go_line(head, states, stopping, groups[0][1] if groups else None)
        lines = tuple(self._cue_line_of(c, states.get(c, "done"), show_s) for c in window)
        with self._lock:
            prompt = QUESTION if self._asking else None if self._typed is None else JUMP.format(typed=self._typed)
            return Screen(self.session.settings.show.name, None if show_s is None else round(show_s, 1),
                          self._clock_text(stopping), cue, go, go_waiting, rows, tuple(self._notes), prompt,
                          self._legend(), self._bar(show_s), lines, at, waits)

    def _first_open(self, robots: tuple[RobotRow, ...]) -> int:
        """Where the show is in the cue list: the first cue a robot is on or comes to next
        (len: none). From the robots' rows, looked up: a show of 10,000 cues is not walked
        at each redraw, nor every cue's state asked of the live controls (their lock is the
        runners' too)."""
        cues, first = self._cues, len(self._cues.cues)
        for row in robots:
            step = row.cue_step
            cue = cues.of_step(row.robot, step.index) if step is not None else None
            if cue is not None:
                first = min(first, cues.position(cue))
        return first

    def _place(self, cue: Cue | None) -> int | None:
        """`cue`'s place in the list, looked up (None: none, or a cue made up for a show run
        without its list)."""
        try:
            return None if cue is None else self._cues.position(cue)
        except ValueError:
            return None

    def _window(self, head: Cue | None, active: int) -> tuple[tuple[Cue, ...], int | None]:
        """CUE_WINDOW cues from the one before `active` (the first not over yet; the last ones
        once all are), moved on if the playhead would fall past it; and the playhead's place."""
        cues = self._cues.cues
        first = max(0, active - 1)
        at = self._place(head)
        if at is not None:
            first = min(first, at - 1) if at >= 1 else 0
            if at - first >= CUE_WINDOW - 1:
                first = at - 2
        first = max(0, min(first, len(cues) - CUE_WINDOW))
        return cues[first:first + CUE_WINDOW], None if at is None else at - first

    def _groups(self, waiting: list[GoCue]) -> list[tuple[tuple[str, ...], str]]:
        """The robots waiting at each GO cue now, in cast order, and the cue's name."""
        order = list(self.session.settings.plans)
        groups = []
        for go in waiting:
            names = tuple(sorted(go.robots, key=lambda n: order.index(n) if n in order else len(order)))
            robot = names[0] if names else ""
            cue = self._cues.of_step(robot, go.step.index)
            groups.append((names, cue.name if cue is not None else f"'{go.name}'"))
        return groups

    def _bar(self, show_s: float | None) -> tuple[int, int] | None:
        """Bar and beat now on the show's `tempo:` (through its map, if it has one)."""
        tempo = self.session.settings.show.tempo
        if show_s is None:
            return None
        show = self.live.show
        if isinstance(show, LinkShowClock):  # the session's beat: a peer may have changed the tempo
            beats = show.show_beat(show.mono_at(show_s))
            bar, within = divmod(math.floor(beats), show.meter)
            return bar + 1, within + 1
        if tempo is None:
            return None
        bar, beat = tempo.position(show_s)
        return bar, int(beat)

    def _clock_text(self, stopping: bool) -> str:
        show = self.live.show
        if isinstance(show, LinkShowClock):
            snapshot = show.session.snapshot()
            return f"link clock, {snapshot.tempo:.2f} bpm, {peers_text(snapshot.peers)}"
        clock = "music" if self.session.settings.song is not None else "machine"
        if self.live.paused and not stopping:
            return f"{clock} clock, PAUSED"
        show = self.live.show
        held = isinstance(show, HoldingShowClock) and show.held and not stopping
        return f"{clock} clock" + (", held for GO" if held else "")

    def _next_timed(self, first: int) -> Cue | None:
        """The first timed cue ahead from position `first` on: timed cues looked up (`_timed`),
        those not ahead any more passed over, NEXT_TIMED_LOOKS of them at most."""
        cues, at = self._cues.cues, self._timed[first]
        for _ in range(NEXT_TIMED_LOOKS):
            if at >= len(cues):
                return None
            if self.live.cue_state(cues[at]) == "ahead":
                return cues[at]
            at = self._timed[at + 1]
        return None

    def _cue_line(self, show_s: float | None, first: int) -> str:
        """The next timed cue ahead, and how long until it."""
        cue = self._next_timed(first)
        if cue is None:
            return "next cue: none ahead"
        at = cue.at or 0.0
        who = f"{_names(cue.robots)}: " if self.session.settings.show.tracks else ""  # shared: everyone's cue
        where = f"at {seconds(at, None)} s" if cue.at_beat is None else \
            f"at {seconds(at, None)} s, bar {cue.at_beat[0]} beat {beat_text(cue.at_beat[1])}"  # as the show wrote it
        if show_s is None:
            return f"next cue: {who}{cue.name} {where}"
        left = f"in {seconds(at - show_s)} s" if at >= show_s else "due now"
        return f"next cue {left}: {who}{cue.name} {where}"

    def _go_line(self, head: Cue | None, states: dict[Cue, str], stopping: bool,
                 waits: str | None) -> tuple[str, bool]:
        """What GO does now: fire the cue under the playhead, or why not; before a show run
        with --wait-start, the start it waits for; paused, how to go on; with the playhead
        moved off a cue that waits (`waits`, the earliest), how to reach it."""
        if not self.live.started and not stopping:
            return "the show waits for its start: press Space or Enter", True
        if self.live.paused and not stopping:
            return "PAUSED: press p to resume (Esc panics)", True
        if head is None or stopping:
            return "next GO: none ahead", False
        if states.get(head) == "waiting":
            return f"GO fires {head.name}: press Space or Enter", True
        skipped = states.get(head) == "skipped"
        if waits is not None and (skipped or not head.go):  # GO then fires the earliest cue waiting (Live)
            why = "skipped" if skipped else "timed"
            return f"GO fires {waits} (the playhead's {head.name} is {why}): press Space or Enter", True
        if waits is not None:
            # GO would do nothing: the playhead's GO cue is not reached yet
            return f"playhead on {head.name}, not reached yet; {waits} waits: Up/Down to it", True
        if not head.go:
            return f"playhead on {head.name}: a timed cue, it runs at its time (GO does nothing)", False
        return f"next GO: {head.name} (not reached yet)", False

    def _cue_line_of(self, cue: Cue, state: str, show_s: float | None) -> CueLine:
        """A cue's line in the list: who (`all` when every robot of several), when, its state."""
        names = list(self.session.settings.plans)
        robots = "" if len(names) == 1 else "all" if sorted(cue.robots) == sorted(names) else _names(cue.robots)
        when = f"GO ~{seconds(cue.planned_s)} s" if cue.go else \
            f"@{seconds(cue.at if cue.at is not None else cue.planned_s, None)} s"
        tempo = self.session.settings.show.tempo
        if cue.at_beat is not None:
            when += f" {cue.at_beat[0]}.{beat_text(cue.at_beat[1])}"
        elif tempo is not None:
            bar, beat = tempo.position(cue.planned_s)
            when += f" {bar}.{int(beat)}"
        shown = state
        if state == "ahead" and not cue.go and cue.at is not None and show_s is not None and cue.at >= show_s:
            shown = f"in {seconds(cue.at - show_s)} s" if cue.at - show_s < 60 else state
        return CueLine(cue.number, cue.label or "", robots, when, shown, STATE_STYLES.get(state, ""))

    def _row(self, robot: RobotRow, groups: list[tuple[tuple[str, ...], str]]) -> Row:
        cue = next((name for names, name in groups if robot.robot in names), None)
        stopped = not robot.done and (robot.aborted or self._stopped())  # its steps will not all end
        now, style = self._stopped_now(robot) if stopped else self._now(robot, cue)
        following = None if stopped else robot.next_step
        return Row(robot.robot, now, _step_text(following) if following is not None else "-", robot.latency_ms,
                   robot.retries, style, bool(robot.retries or robot.failed))

    @staticmethod
    def _stopped_now(robot: RobotRow) -> tuple[str, str]:
        """A robot the stop or panic cut off (`aborted`, and its step) or kept from its steps."""
        if robot.aborted and robot.step is not None:
            return f"aborted: {_step_text(robot.step)}", "bold red"
        return "stopped", "bold red"

    @staticmethod
    def _now(robot: RobotRow, cue: str | None) -> tuple[str, str]:
        step = robot.step
        if cue is not None:
            return f"waits for GO: {cue}", WAITING_STYLE
        if step is None:
            return "not started", "dim"
        if robot.done:
            return "done", "green"
        # a step over is dim: the robot is between steps (a play's motion may still run)
        return _step_text(step), "dim" if robot.ended else ""

    def _stopped(self) -> bool:
        """The show was stopped (stop or panic): a robot not done will not go on."""
        return self.live.panicked or bool(self.live.stop())

    def _legend(self) -> str:
        """The keys (p says what it does now), or how the show ended."""
        if self._closing:
            return self._final_line()
        return PAUSED_LEGEND if self.live.paused else LEGEND

    def _final_line(self) -> str:
        stop = self.live.stop
        if self.live.panicked:
            return "the show was stopped by panic; keys off"
        if stop():
            return f"the show was {stop.reason}; keys off"
        return "the run is over; keys off"

