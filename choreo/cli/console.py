"""The live console of `choreo run` on a terminal: where the show is, what comes next, how the
links are doing, and the operator's keys (GO, panic, stop).

It is a listener like the others (the run's steps and log lines, the operator's commands, each
link's frames and replies) and keeps only what it draws; the commands go through `Live`, so a
key is answered exactly as an OSC message would be, and the log records it the same way.

Two things it must never do. Delay the show: the runners call its listener methods on their
own path, so those only note what happened under a short lock; drawing happens in its own
thread, which also keeps clear of the moments a step falls due or a GO was just given (a redraw
holds Python's lock for a few milliseconds, and a runner woken then would wait for it), and
draws only what changed: while a GO cue waits, the clock holds and the screen stays still, so
the GO, when it comes, finds nothing drawing.
And leave the terminal unusable: the key mode (cbreak, no echo) is undone on every way out.

rich lays the screen out (a table whose columns share the width, every cell cut with `…`), so
it fits any width from 60 columns; everything goes to `out` (stderr): stdout is for --json.
"""

from __future__ import annotations

import os
import statistics
import sys
import termios
import threading
from collections import deque
from contextlib import suppress
from dataclasses import dataclass, field
from typing import TextIO, cast

from rich.console import Console as RichConsole
from rich.console import RenderableType
from rich.control import Control
from rich.file_proxy import FileProxy
from rich.live import Live as RichLive

from choreo.cli.keys import PASTE_OFF, PASTE_ON, KeyReader, TerminalMode, in_foreground
from choreo.cli.screen import LEGEND, NARROW, WAITING_STYLE, Note, Row, Screen, render
from choreo.cli.terminal import raw_stream, visible_stream
from choreo.events import Command, CommandEvent, GoCue, RxEvent, StepEvent, Subscription, TxEvent
from choreo.live.controls import HoldingShowClock, Live
from choreo.log.format import ERROR, INFO, WARNING
from choreo.show.model import SOLO, PlannedStep, StepKind, beat_text

REFRESH_S = 0.2  # five looks a second: the show time moves smoothly enough (and is drawn to 0.1 s)
QUIET_BEFORE_S = 0.06  # no redraw starts this close before a step falls due (a cue's lead included)
QUIET_AFTER_S = 0.03  # nor this soon after it, or after a GO (its frames go out then)
MAX_POSTPONE_S = 0.5  # cues closer together than this still let the screen move
NOTES = 5  # lines of log and answers on screen
LATENCIES = 20  # the replies link health is the median of

QUESTION = "stop the show? y/n"
STYLES = {ERROR: "bold red", WARNING: "yellow", INFO: ""}


# -- what the console keeps --------------------------------------------------------------------


@dataclass
class _Robot:
    """One robot as the console knows it: its steps, where it is in them, its link's replies."""

    name: str
    steps: tuple[PlannedStep, ...]  # its own steps, from where it starts
    at: int = -1  # position in `steps` of its current step (-1: none started)
    ended: bool = False  # the current step has ended
    started_s: float = 0.0  # show time the current step started
    latencies_ms: deque[float] = field(default_factory=lambda: deque(maxlen=LATENCIES))
    retries: int = 0
    failed: int = 0  # tries without a good reply

    @property
    def current(self) -> PlannedStep | None:
        return self.steps[self.at] if self.at >= 0 else None

    @property
    def ahead(self) -> tuple[PlannedStep, ...]:
        return self.steps[self.at + 1:]

    @property
    def done(self) -> bool:
        return self.ended and self.at == len(self.steps) - 1

    def moved_to(self, step: PlannedStep, show_s: float) -> None:
        self.at = next((i for i, s in enumerate(self.steps) if s.index == step.index), self.at)
        self.ended = False
        self.started_s = show_s

    def step_ended(self, step: PlannedStep) -> None:
        """A step ended: its own current one (another robot's shared step is not its end)."""
        if self.current is not None and self.current.index == step.index:
            self.ended = True

    def replied(self, latency_ms: float, ok: bool) -> None:
        if ok:
            self.latencies_ms.append(latency_ms)
        else:
            self.failed += 1

    def retried(self) -> None:
        self.retries += 1

    def dues_s(self) -> list[float]:
        """When, on the show clock, this robot's runner next wakes to send: the end of the wait
        it is in, and its next timed cue (a step after a play goes at once: no wake-up)."""
        step = self.current
        dues = [s.at for s in self.ahead if s.at is not None][:1]
        if step is not None and step.kind is StepKind.WAIT and not self.ended:
            dues.append(self.started_s + (step.seconds or 0.0))
        return dues


def _step_text(step: PlannedStep) -> str:
    label = f" '{step.label}'" if step.label else ""
    when = "GO " if step.go else f"@{step.at:g} s " if step.at is not None else ""
    return f"{when}{step.index}{label}: {step.describe()}"


@dataclass
class _LinkWatch:
    """A robot's link listener: reply latencies and retries, for the robot's link column."""

    console: Console
    robot: str

    def on_tx(self, event: TxEvent) -> None:
        if event.attempt > 1:
            self.console._note_retry(self.robot)

    def on_rx(self, event: RxEvent) -> None:
        self.console._note_reply(self.robot, event.latency_s * 1e3, event.reply.ok)


# -- the console -------------------------------------------------------------------------------


class Console:
    """The live console; see the module's docstring. Created by `choreo run` when stdin and
    stderr are terminals, started once the ports are open, closed when the run is over."""

    def __init__(self, session, live: Live, *, out: TextIO | None = None,
                 keys: TextIO | None = None, width: int | None = None) -> None:
        """`out`: where it draws (default stderr); `keys`: the terminal it reads (default
        stdin; one that is not a terminal gives no keys); `width`: fixed, for tests."""
        out = out if out is not None else raw_stream(sys.stderr)  # it draws: its escapes are its own
        self.session = session
        self.live = live
        self.out = out
        self.keys = keys if keys is not None else sys.stdin
        self._lock = threading.Lock()
        starts = session.settings.sections.starts
        self._robots = {name: _Robot(name, tuple(s for s in plan.steps[starts[name]:] if s.is_for(name)))
                        for name, plan in session.settings.plans.items()}
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
        self._reader = KeyReader(fd, self.on_key)
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
        stage = self.session.stage  # None until the session opens: no links to watch yet
        for name, link in (stage.links.items() if stage is not None else ()):
            self._watches.append(link.subscribe(_LinkWatch(self, name)))

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
            self._rich.update(render(screen, drawn[1]), refresh=True)
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
        with self._lock:
            windows = [(self._quiet_until - QUIET_AFTER_S, self._quiet_until)] + self._due_windows()
        until = now
        for start, end in sorted(windows):
            if start <= until < end:
                until = end
        return min(until - now, MAX_POSTPONE_S)

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
        """The lock is held. Monotonic windows around each robot's next due time."""
        show = self.live.show
        if show is None:
            return []
        windows = []
        for robot in self._robots.values():
            for due in robot.dues_s():
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
        """Esc panics whatever else is going on; a question takes the next key as its answer;
        Space or Enter is GO (which also starts a show loaded with --wait-start)."""
        if key == "escape":
            self._ask(False)
            self.live.command(Command("panic", "key"))
            return
        with self._lock:
            asking = self._asking
        if asking:
            self._ask(False)
            if key in ("y", "Y"):
                self.live.command(Command("stop", "key"))
            else:
                self._add(Note("stop cancelled: the show goes on", "dim", self._show_s()))
        elif key == "go":
            # before a show loaded with --wait-start, the operator's GO key starts it
            self.live.command(Command("go" if self.live.started else "start", "key"))
        elif key == "q":
            self._ask(True)

    def _ask(self, asking: bool) -> None:
        with self._lock:
            self._asking = asking

    # -- listeners -----------------------------------------------------------------------------

    def on_step(self, event: StepEvent) -> None:
        robot = self._robots.get(event.robot or SOLO)
        if robot is None:
            return
        with self._lock:
            if event.event == "start":
                robot.moved_to(event.step, event.actual_s)
            else:
                robot.step_ended(event.step)

    def on_log(self, level: int, message: str, time_ns: int | None = None) -> None:
        if level >= INFO:
            self._add(Note(message, STYLES.get(level, "bold red"), self._show_s()))

    def on_command(self, event: CommandEvent) -> None:
        command, answer = event.command, event.answer
        source = "" if command.source == "key" else f" ({command.source})"
        text = f"{answer.message}{source}"
        if answer.ok and command.name in ("go", "cue_go", "start"):
            with self._lock:  # the frames it releases go out now: no redraw in their way
                self._quiet_until = self.session.clock.mono() + QUIET_AFTER_S
        self._add(Note(text, "green" if answer.ok else "bold red", event.show_s))

    def on_play_out(self, end_s: float) -> None:
        self._add(Note(f"the steps are done; the music plays to its end at {end_s:.1f} s", "",
                       self._show_s()))

    def _note_retry(self, robot: str) -> None:
        with self._lock:
            self._robots[robot].retried()

    def _note_reply(self, robot: str, latency_ms: float, ok: bool) -> None:
        with self._lock:
            self._robots[robot].replied(latency_ms, ok)

    def _add(self, note: Note) -> None:
        with self._lock:
            self._notes.append(note)

    def _show_s(self) -> float | None:
        show = self.live.show
        return show.show_at(self.session.clock.mono()) if show is not None else None

    # -- drawing -------------------------------------------------------------------------------

    def renderable(self, width: int = NARROW) -> RenderableType:
        return render(self.screen(), width)

    def screen(self) -> Screen:
        """What to draw now."""
        stopping = self.live.stop()
        waiting = [] if stopping else self.live.waiting  # a stopped show's GO cues wait for nothing
        show_s = self._show_s()
        with self._lock:
            rows = tuple(self._row(robot, waiting) for robot in self._robots.values())
            cue = "next cue: none, the show is stopping" if stopping else self._cue_line(show_s)
            go, go_waiting = self._go_line(waiting, stopping)
            return Screen(self.session.settings.show.name, None if show_s is None else round(show_s, 1),
                          self._clock_text(stopping), cue, go, go_waiting, rows, tuple(self._notes),
                          QUESTION if self._asking else None,
                          self._final_line() if self._closing else LEGEND, self._bar(show_s))

    def _bar(self, show_s: float | None) -> tuple[int, int] | None:
        """Bar and beat now on the show's `tempo:` (through its map, if it has one)."""
        tempo = self.session.settings.show.tempo
        if tempo is None or show_s is None:
            return None
        bar, beat = tempo.position(show_s)
        return bar, int(beat)

    def _clock_text(self, stopping: bool) -> str:
        clock = "music" if self.session.settings.song is not None else "machine"
        show = self.live.show
        held = isinstance(show, HoldingShowClock) and show.held and not stopping
        return f"{clock} clock" + (", held for GO" if held else "")

    def _cue_line(self, show_s: float | None) -> str:
        """The lock is held. The next timed cue of any robot, and how long until it."""
        ahead = [(step.at, robot.name, step) for robot in self._robots.values()
                 for step in robot.ahead if step.at is not None]
        if not ahead:
            return "next cue: none ahead"
        at, name, step = min(ahead, key=lambda c: (c[0], c[2].index))
        who = f"{name}: " if self.session.settings.show.tracks else ""  # shared steps: everyone's cue
        label = f" '{step.label}'" if step.label else ""
        where = f"at {at:g} s" if step.at_beat is None else \
            f"at {at:g} s, bar {step.at_beat[0]} beat {beat_text(step.at_beat[1])}"  # as the show wrote it
        if show_s is None:
            return f"next cue: {who}step {step.index}{label} {where}"
        left = f"in {at - show_s:.1f} s" if at >= show_s else "due now"
        return f"next cue {left}: {who}step {step.index}{label} {where}"

    def _go_line(self, waiting: list[GoCue], stopping: bool) -> tuple[str, bool]:
        """The lock is held. The GO cue waiting now, else the next one coming; before a show
        run with --wait-start, the start it waits for."""
        if not self.live.started and not stopping:
            return "the show waits for its start: press Space or Enter", True
        if waiting:
            more = f" (+{len(waiting) - 1} more)" if len(waiting) > 1 else ""
            return f"GO waits: '{waiting[0].name}'{more}: press Space or Enter", True
        coming = [step for robot in self._robots.values() for step in robot.ahead if step.go]
        if not coming or stopping:
            return "next GO: none ahead", False
        step = min(coming, key=lambda s: (s.planned_s, s.index))
        return f"next GO: '{step.name}' (step {step.index})", False

    def _row(self, robot: _Robot, waiting: list[GoCue]) -> Row:
        cue = next((c for c in waiting if robot.name in c.robots), None)
        step = robot.current
        if cue is not None:
            now, style = f"waits for GO: '{cue.name}'", WAITING_STYLE
        elif step is None:
            now, style = "not started", "dim"
        elif robot.done:
            now, style = "done", "green"
        else:  # a step over is dim: the robot is between steps (a play's motion may still run)
            now, style = _step_text(step), "dim" if robot.ended else ""
        following = next(iter(robot.ahead), None)
        latency = statistics.median(robot.latencies_ms) if robot.latencies_ms else None
        return Row(robot.name, now, _step_text(following) if following is not None else "-", latency,
                   robot.retries, style, bool(robot.retries or robot.failed))

    def _final_line(self) -> str:
        stop = self.live.stop
        if self.live.panicked:
            return "the show was stopped by panic; keys off"
        if stop():
            return f"the show was {stop.reason}; keys off"
        return "the run is over; keys off"
