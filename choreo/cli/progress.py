"""What `choreo run` tells its user on stderr: the lines before the show (ports, layouts, the
show, the music), the progress a step (a live line on a terminal, a plain line otherwise), and
the lines after.

Apart from `cli/run` (the command: its arguments, the live controls and their wiring, the
signals, the --json report) because this is one job, text for a person, and it is loaded only
when a run starts: --help does not pay for the log's levels or the music's outputs.
"""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING, TextIO

from choreo.cli.terminal import StatusWriter
from choreo.cli.terminal import columns as terminal_columns
from choreo.errors import bounded
from choreo.log.format import ERROR, LINK_PREFIX, WARNING
from choreo.music.player import output_name
from choreo.textfit import fit
from choreo.wire.layouts import LAYOUT_NAMES

if TYPE_CHECKING:
    from choreo.events import CommandEvent, GoCue
    from choreo.run.settings import LinkSettings, RunSettings
    from choreo.show.model import Plan


def live_line(step: str, show_s: float, estimated_s: float, columns: int) -> str:
    """The live line, one character narrower than the terminal (a line that fills the last
    column wraps on many terminals, and every redraw would then leave a line behind): the show
    time is kept, then the bar as room allows, then the step, cut with `…`."""
    width = max(columns - 1, 1)
    clock = f"{show_s:.1f}/{estimated_s:.1f} s"
    bar_room = min(20, width - len(clock) - 12)  # keep about ten columns for the step
    bar = ""
    if bar_room >= 5:
        done = min(bar_room, int(bar_room * show_s / estimated_s)) if estimated_s > 0 else bar_room
        bar = f" [{'#' * done}{'-' * (bar_room - done)}]"
    tail = f"  {clock}{bar}"
    room = width - len(tail)
    if room < 1:
        return clock[:width]
    return fit(step, room) + tail


class Say:
    """Lines for the user on stderr, before and after the show (never from its threads: those
    go through `Progress`); on a terminal each is cut to its width, measured at each line; a
    closed pipe or terminal never stops the show."""

    def __init__(self, out: TextIO, quiet: bool) -> None:
        self.out = out
        self.asked_quiet = quiet  # --quiet
        self.quiet = quiet

    def ended(self, done: bool) -> None:
        """The show is over: --quiet still says how a run ended that did not end as done."""
        self.quiet = self.asked_quiet and done

    def __call__(self, line: str) -> None:
        if self.quiet:
            return
        try:
            width = terminal_columns(self.out) if self.out.isatty() else None
            # to a file or pipe whole, but never megabytes: a port or a name from outside may be
            print(bounded(fit(line, width)), file=self.out, flush=True)
        except (OSError, ValueError):
            self.quiet = True


def solo(settings: RunSettings) -> LinkSettings:
    """A one-robot show's robot."""
    return next(iter(settings.links.values()))


def opening_lines(settings: RunSettings) -> list[str]:
    """What the run says before it opens anything: the ports and layouts, the show, the music."""
    lines = _robot_lines(settings) if settings.show.ensemble else [
        _port_line(solo(settings)), _layout_line(solo(settings))]
    lines.append(_show_line(settings))
    if settings.host is not None:  # `--host`: the show's other robots are other computers' to drive
        others = [name for name in settings.show.cast if name not in settings.links]
        lines.append(f"host: {settings.host}, driving {', '.join(settings.links)}"
                     + (f"; other hosts drive {', '.join(others)}" if others else ""))
    if settings.link is not None:
        tempo = f"proposing {settings.link.bpm:g} bpm" if settings.link.bpm is not None else "the session's tempo"
        lines.append(f"clock: Ableton Link session, {settings.link.meter} beats a bar, {tempo}")
    elif settings.show.music is not None:
        lines.append(_music_line(settings))
    return lines


def _show_line(settings: RunSettings) -> str:
    show, sections = settings.show, settings.sections
    start = sections.starts[solo(settings).robot]  # shared steps: every robot starts at this step
    first = f" from step {start}" if start and not show.tracks else ""
    if show.tracks and sections.origin:
        first = f" from {sections.origin:.3f} s"
    estimated = max(plan.estimated_s for plan in settings.plans.values())
    if not show.ensemble:
        steps = len(settings.plans[solo(settings).robot].steps)
        return f"show: {show.name}: {steps} steps{first}, about {estimated:.1f} s"
    form = "tracks" if show.tracks else "shared steps"
    robots = f"{len(settings.links)} robot" + ("s" if len(settings.links) != 1 else "")
    return f"show: {show.name}: {robots}, {form}{first}, about {estimated:.1f} s"


def _robot_lines(settings: RunSettings) -> list[str]:
    """With several robots: a line per robot, its port and layout and where they came from."""
    lines = []
    for link in settings.links.values():
        source = {"simulator": "built-in simulator", "show": "from the show",
                  "simulator (--rehearse)": "built-in simulator, --rehearse"}.get(link.port_source, "from --port")
        assumed = ", layout assumed" if link.assumes_layout else ""
        lines.append(f"robot {link.robot}: {link.port} at {link.baud} baud ({source}), "
                     f"layout {link.layout.name}{assumed}")
    return lines


def _music_line(settings: RunSettings) -> str:
    """What keeps the show clock: the music (which file, from where, on which output) or, with
    --no-music, the machine."""
    song = settings.song
    if song is None:
        music = settings.show.music.file if settings.show.music is not None else ""
        return f"music: {music} not played (--no-music): the machine's clock keeps the show"
    start = song.music.start + settings.sections.origin
    where = output_name(settings.output)
    return f"music: {song.music.file} from {start:.1f} s of {song.duration_s:.1f} s, on {where}: the show clock"


def _port_line(link: LinkSettings) -> str:
    where = {
        "simulator": "the built-in simulator (no --port given and the show names no robot.port)",
        "simulator (--rehearse)": "the built-in simulator (--rehearse: in real time, the show's ports left alone)",
        "show": "the show's robot.port",
    }.get(link.port_source, "the command line")
    return f"port: {link.port} at {link.baud} baud, from {where}"


def _layout_line(link: LinkSettings) -> str:
    layout = link.layout
    line = f"layout: {layout.name} (motion 0 at 0x{layout.first_slot:04x})"
    if link.assumes_layout:
        other = next(name for name in LAYOUT_NAMES if name != layout.name)
        return (f"{line}, assumed: the show names no robot.layout; a board whose motions were "
                f"written by Heart to Heart 4 2.2 or later needs --layout {other} "
                "(`choreo probe` hints which)")
    return line + {"show": ", from the show", "command line": ", from --layout"}.get(link.layout_source, "")


def _own_steps(plan: Plan, start: int, robot: str) -> dict[int, int]:
    """The steps a robot plays from `start`, each index with its place among them (from 1): the
    progress line counts those (looked up, not searched: it is said on the runner's thread)."""
    own = (step.index for step in plan.steps[start:] if step.is_for(robot))
    return {index: place for place, index in enumerate(own, 1)}


class Progress:
    """The run on screen: a live line on a terminal, a plain line a step otherwise.

    Never on the show's path: the runners and the OSC server only note what happened; a
    `StatusWriter` thread writes (and redraws the live line every quarter second, so the show
    time moves during long waits). A terminal stopped with Ctrl-S or a full pipe holds up only
    that thread: lines past its queue are dropped, counted, and the count said later.
    """

    def __init__(self, session, out: TextIO, *, live: bool, quiet: bool) -> None:
        # each robot's steps from where it starts (a robot's own, in shared steps), by robot
        settings = session.settings
        self.counts = {name if settings.show.ensemble else None: _own_steps(plan, settings.sections.starts[name], name)
                       for name, plan in settings.plans.items()}
        self.estimated = max(plan.estimated_s for plan in settings.plans.values())
        self.live = live and not quiet
        self.quiet = quiet
        self._lock = threading.Lock()
        self._current = ""  # the step part of the live line
        self._zero: float | None = None  # monotonic time of the show clock's zero
        self.writer = None if quiet else StatusWriter(out, fit_lines=self.live,
                                                      status=self._live_line if self.live else None)

    def on_step(self, event) -> None:
        if self.quiet or event.event != "start":
            return
        step = event.step
        label = f" '{step.label}'" if step.label else ""
        robot = f"{event.robot}: " if event.robot else ""
        own = self.counts.get(event.robot, {})
        place = f" ({own[step.index]}/{len(own)})" if step.index in own else ""
        where = f"{robot}step {step.index}{label}{place}"
        if not self.live:
            self._say_line(f"[{event.actual_s:8.3f} s] {where}: {step.describe()}")
            return
        with self._lock:
            self._zero = time.monotonic() - event.actual_s
            self._current = f"{where}: {step.describe()}"
        if self.writer is not None:  # always, live (quiet has no writer and returned above)
            self.writer.redraw()

    def _live_line(self, columns: int) -> str:
        """The live line now (the writer's thread asks, at each draw)."""
        with self._lock:
            current, zero = self._current, self._zero
        if not current:
            return ""
        show_s = time.monotonic() - zero if zero is not None else 0.0
        return live_line(current, show_s, self.estimated, columns)

    def on_log(self, level: int, message: str, time_ns: int | None = None) -> None:
        if level >= ERROR:
            return  # errors reach the user once, as the command's final line
        if level < WARNING:
            if message.startswith(LINK_PREFIX):  # the Link session: whom the show waits for, tempo changes
                self._say_line(message)
            return
        self._say_line(f"warning: {message}")

    def on_waiting(self, cue: GoCue) -> None:
        """A GO cue is reached (live control): say so, it is what the operator waits for."""
        self._say_line(f"[{cue.reached_s:8.3f} s] waiting for GO: {cue.name}")

    def on_command(self, event: CommandEvent) -> None:
        """An operator's command (live control): its answer, with who gave it."""
        answer = event.answer
        verdict = "" if answer.ok or answer.message.startswith("refused") else "refused: "
        self._say_line(f"{event.command.name} ({event.command.source}): {verdict}{answer.message}")

    def _say_line(self, text: str, last_step_done: bool = False) -> None:
        """A line above the live one (which is drawn again below it, unless the steps are done)."""
        if self.writer is None:
            return
        if last_step_done:
            with self._lock:
                self._current = ""
        self.writer.line(bounded(text))

    def on_play_out(self, end_s: float) -> None:
        """The steps are done; the music plays on to its end."""
        self._say_line(f"music: the steps are done; the music plays to its end at {end_s:.1f} s (Ctrl-C stops it)",
                       last_step_done=True)

    def finish(self) -> None:
        """The live line cleared and every line written (an output that takes nothing for a
        second is left behind: the run's last lines will wait for it)."""
        with self._lock:
            self._current = ""
        if self.writer is not None:
            self.writer.close()
