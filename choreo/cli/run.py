"""`choreo run SHOW`: play a show, with a progress line, Ctrl-C handling and a log."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import closing, contextmanager, nullcontext
from typing import TYPE_CHECKING, TextIO

from choreo.cli.terminal import StatusWriter
from choreo.cli.terminal import columns as terminal_columns
from choreo.errors import ChoreoError, Interrupted, UsageError
from choreo.signals import STOP_SIGNALS
from choreo.wire.layouts import LAYOUT_NAMES
from choreo.wire.protocol import spell_bauds
from choreo.textfit import fit

if TYPE_CHECKING:  # the run's modules load when a run starts: `choreo validate` and --help stay light
    from choreo.events import CommandEvent, GoCue, RunResult, StopRequest
    from choreo.live.controls import Live
    from choreo.live.osc import OscServer
    from choreo.run.session import Session
    from choreo.show.model import Plan
    from choreo.run.settings import LinkSettings, RunSettings


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "run",
        help="play a show on the robot (or the built-in simulator)",
        description="Play a show file over the serial line and record every frame to an MCAP log. "
        "With no --port and no robot.port in the show, runs against the built-in simulator.",
    )
    parser.add_argument("show", help="the show file (YAML)")
    parser.add_argument("--port", action="append", metavar="URL|NAME=URL",
                        help="pyserial URL or device: /dev/ttyUSB0, COM3, socket://, rfc2217://, loop://, "
                        "spy://, sim:// (default: the show's robot.port, else sim://); with several robots, "
                        "NAME=URL for one robot (repeatable)")
    parser.add_argument("--baud", type=int, help=spell_bauds("or", mark_default=True))
    parser.add_argument("--layout", choices=LAYOUT_NAMES, help="the board's memory layout: seed "
                        "(the document's frames, default) or hth4-2.2 (motions written by Heart to "
                        "Heart 4 2.2 or later); default: the show's robot.layout, else seed")
    logs = parser.add_mutually_exclusive_group()
    logs.add_argument("--log", metavar="PATH", help="log file (default runs/<show>-<UTC time>.mcap; "
                      "never overwritten)")
    logs.add_argument("--no-log", action="store_true", help="do not record a log")
    parser.add_argument("--from", dest="from_step", metavar="STEP",
                        help="start at this step (index from `choreo plan`, or label)")
    parser.add_argument("--loop", metavar="FROM..TO", help="rehearse a section: play from step FROM to step TO "
                        "(labels or indices) again and again until stopped")
    parser.add_argument("--rehearse", action="store_true", help="every robot on the built-in simulator, in real "
                        "time (the show's ports are left alone), with the console on a terminal")
    parser.add_argument("--timeout", type=float, metavar="S",
                        help="seconds to wait for a reply, 0 < S <= 10 (default 0.2)")
    parser.add_argument("--retries", type=int, metavar="N",
                        help="retries of a failed frame or play sequence, 0..10 (default 2: 3 tries)")
    music = parser.add_mutually_exclusive_group()
    music.add_argument("--no-music", action="store_true", help="do not play the show's music: run "
                       "silent on the machine's clock")
    music.add_argument("--audio-device", metavar="OUTPUT", help="where the music plays: a number or "
                       "name from `choreo devices`, or null (silent, keeps the music's time); default: "
                       "the system's output")
    _live_options(parser)
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress output")
    parser.add_argument("--json", action="store_true", help="at the end, the run's result and log "
                        "path as one JSON object on stdout (also when it fails; stderr as without)")
    parser.set_defaults(handler=run, own_json_failure=True)  # its result record says the failure


def _live_options(parser: argparse.ArgumentParser) -> None:
    """GO cues, the console and OSC: the operator's controls of a run."""
    live = parser.add_argument_group("live control", "GO cues (`at: go`), the console and OSC; see "
                                     "docs/live.md")
    live.add_argument("--osc", metavar="PORT", help="take OSC commands (go, panic, start, stop, "
                      "cue/LABEL/go under /choreo) on this UDP and TCP (SLIP) port, and answer each with /reply/... "
                      "(QLab itself listens on 53000: choose another, e.g. 53200)")
    live.add_argument("--osc-host", metavar="HOST", default="127.0.0.1",
                      help="the address OSC listens on (default 127.0.0.1: this machine only)")
    live.add_argument("--osc-allow", action="append", metavar="ADDRESS", default=[],
                      help="a sender (IP address, or a network such as 192.168.1.0/24) OSC takes commands from "
                      "besides this machine (repeatable)")
    live.add_argument("--osc-notify", action="append", metavar="HOST:PORT", default=[],
                      help="send the show's progress there as OSC (step started, GO cue waiting, fault, done); "
                      "repeatable: every target gets it")
    live.add_argument("--wait-start", action="store_true", help="load, open the ports, then wait for "
                      "the OSC start command (or the console's GO) before the show starts")
    live.add_argument("--no-console", action="store_true", help="on a terminal, the plain progress "
                      "line instead of the console (GO then comes only over OSC)")


def run(args: argparse.Namespace) -> int:
    """With --json, a script gets the outcome and the log path on stdout whatever happens, the
    way it would read them off stderr otherwise."""
    report = _RunReport(args.show)
    try:
        code = _run(args, report)
    except ChoreoError as exc:
        report.failed(exc)
        raise
    except KeyboardInterrupt:
        report.failed(Interrupted("show interrupted"))
        raise
    finally:
        if args.json:
            from choreo.cli.jsonout import print_json

            print_json(report.record)
    return code


def _run(args: argparse.Namespace, report: "_RunReport") -> int:
    from choreo.events import ResultListener, StopRequest
    from choreo.run.session import Session
    from choreo.run.settings import RunRequest

    port, robot_ports = port_arguments(args.port)
    osc_port, notify = _check_osc_options(args)
    request = RunRequest(args.show, port=port, baud=args.baud, log_path=args.log,
                         no_log=args.no_log, from_step=args.from_step, timeout=args.timeout,
                         retries=args.retries, layout=args.layout, robot_ports=robot_ports,
                         no_music=args.no_music, audio_device=args.audio_device, loop=args.loop,
                         rehearse=args.rehearse)
    session = Session.prepare(request, args.time_source)
    report.prepared(session)
    console = _wants_console(args)
    _check_go_sources(session.settings, console, args)
    stop = StopRequest()
    live = _live(args, stop, console)
    # listening (not serving yet) before a line is said or anything opens
    osc = _bound_osc(args, osc_port, notify, live)
    say = _Say(sys.stderr, quiet=args.quiet)
    for line in _opening_lines(session.settings):
        say(line)
    progress = Progress(session, sys.stderr, live=sys.stderr.isatty() and not console, quiet=args.quiet or console)
    signals = _StopOnSignals(stop)
    try:
        with signals, _controls(live, osc, say, progress) as listeners, _log_named_on_failure(session, say), session:
            say(f"log: {session.log_path}" if session.log_path else "log: off (--no-log)")
            for note in session.stage.notes if session.stage is not None else ():
                say(f"warning: {note}")
            # the Live closed however the run ends, while the log is open: later commands are
            # refused, and those held back by the limits summed up into it
            with closing(live) if live is not None else nullcontext(), _console(session, live, console, listeners):
                result = session.run([progress, *listeners], stop, live)
                for listener in listeners:
                    if isinstance(listener, ResultListener):  # OSC notify: the run is over
                        listener.on_result(result)
        report.finished(result)
        progress.finish()
        say.quiet = args.quiet and result.outcome == "done"
        late = f", {result.late_steps} late" if result.late_steps else ""
        say(f"{result.outcome}: {result.steps_run} steps in {result.show_s:.3f} s{late}")
        if session.log_path:
            say(f"log: {session.log_path}")
        if result.outcome != "done":
            raise Interrupted("show stopped by panic: stop frames, then the abort motions"
                              if stop.panicked else f"show {stop.reason}")
        return 0
    finally:
        progress.finish()
        signals.restore()


def _wants_console(args: argparse.Namespace) -> bool:
    """The console runs where an operator can press its keys: a terminal on both ends."""
    return (not args.quiet and not args.json and not args.no_console and sys.stdin.isatty()
            and sys.stderr.isatty())


def _check_go_sources(settings: RunSettings, console: bool, args: argparse.Namespace) -> None:
    """A show with GO cues (or --wait-start) needs someone to give the GO: refused before any
    port opens, not a show that waits for ever."""
    if args.osc is None:
        given = [name for name, value in (("--osc-allow", args.osc_allow), ("--osc-notify", args.osc_notify),
                                          ("--osc-host", args.osc_host != "127.0.0.1")) if value]
        if given:
            raise UsageError(f"{given[0]}: it is for OSC: give --osc PORT too")
    if console or args.osc is not None:
        return
    where = ("leave out --quiet/--no-console/--json on a terminal (the console takes GO)" if sys.stdin.isatty()
             else "run on a terminal (the console) or with --osc PORT")
    if args.wait_start:
        raise UsageError(f"--wait-start: nothing can start the show: {where}")
    for plan in settings.plans.values():
        step = next((s for s in plan.steps[settings.sections.starts[plan.robot]:] if s.go), None)
        if step is not None:
            from choreo.run.runner import step_ref

            raise UsageError(f"{step_ref(step)} waits for GO, but nothing can give it: {where}")


def _check_osc_options(args: argparse.Namespace) -> tuple[int | None, tuple]:
    """The OSC options' values, checked before anything is loaded or opened (the port's binding
    and the notify targets' look-up come next, still before the session opens): --osc's port
    number (None: no OSC) and --osc-notify's targets."""
    from choreo.live.osc import parse_allow
    from choreo.live.oscnotify import parse_targets, port_number

    port = None if args.osc is None else port_number(args.osc, lowest=0)
    if args.osc is not None and port is None:
        raise UsageError(f"--osc {args.osc}: give a port number, 1..65535 (0: any free port)")
    if not args.osc_host.strip():
        raise UsageError("--osc-host '': give the address to listen on (127.0.0.1, 0.0.0.0, ::)")
    parse_allow(args.osc_allow)
    return port, parse_targets(args.osc_notify)


def _live(args: argparse.Namespace, stop: StopRequest, console: bool) -> Live | None:
    """The Live that GO cues wait on, when someone can command the show (the console, OSC);
    None for a show run as before."""
    if not console and args.osc is None:
        return None
    from choreo.live.controls import Live

    return Live(stop, wait_start=args.wait_start)


def _bound_osc(args: argparse.Namespace, port: int | None, notify: tuple, live: Live | None) -> OscServer | None:
    """With --osc, the OSC server listening and its notify targets looked up, serving nothing
    yet (`_controls` starts it): a port in use, a host it cannot listen on, a notify target that
    is this very port, end the run with one line before anything is said or opened."""
    if port is None or live is None:  # no --osc (with it, _live made a Live and the port is checked)
        return None
    from choreo.live.osc import OscServer

    server = OscServer(live, port, host=args.osc_host, allow=args.osc_allow, notify=notify)
    server.bind()
    return server


@contextmanager
def _controls(live: Live | None, osc: OscServer | None, say: _Say, progress: Progress) -> Iterator[list]:
    """The operator's controls for the run (none without a Live): the OSC server, bound
    already, serving before the session opens, which commands the Live and listens to the show
    (its notifications); the listeners the run should tell. The commands held back by the
    limits are summed up every `Limits.summary_every_s`, and once more at the end."""
    if live is None:
        yield []
        return
    from choreo.limits import LIMITS, Ticker

    # off the console, the plain lines say what waits and what was pressed: to the very end
    heard = live.subscribe(progress)
    listeners: list = []
    opened: list = [osc] if osc is not None else []
    try:
        if osc is not None:
            osc.start()
            opened.append(live.subscribe(osc))
            listeners.append(osc)
            say(osc.listening)
        opened.append(Ticker(live.flush_reports, LIMITS.summary_every_s).start())
        yield listeners
    finally:
        live.close()
        for control in reversed(opened):
            control.close()
        live.flush_reports(force=True)
        heard.close()


@contextmanager
def _console(session: Session, live: Live | None, console: bool, listeners: list) -> Iterator[None]:
    """The console, on a terminal, for the time of the show (it draws on the terminal and reads
    its keys: only once the session is open)."""
    if not console or live is None:  # a console always has its Live (_live)
        yield
        return
    from choreo.cli.console import Console

    screen = Console(session, live)
    screen.start()
    listeners.append(screen)
    try:
        with live.subscribe(screen):
            yield
    finally:
        screen.close()


def port_arguments(values: list[str] | None) -> tuple[str | None, dict[str, str]]:
    """`--port URL` (one robot) and `--port NAME=URL` (repeatable, one robot of several)."""
    from choreo.run.settings import split_robot_port

    plain: list[str] = []
    named: dict[str, str] = {}
    for value in values or []:
        split = split_robot_port(value)
        if value.startswith("="):
            raise UsageError(f"--port {value}: give the robot's name before '=' (--port NAME=URL)")
        _check_network_port(value if split is None else split[1], value)
        if split is None:
            plain.append(value)
        elif split[0] in named:
            raise UsageError(f"--port {value}: robot {split[0]} has a port already ({named[split[0]]})")
        else:
            named[split[0]] = split[1]
    if len(plain) > 1:
        raise UsageError(f"--port {plain[1]}: one --port URL for a one-robot show; for several robots "
                         "give --port NAME=URL")
    return (plain[0] if plain else None), named


def _check_network_port(url: str, given: str) -> None:
    """A network port's URL names a host and a port number (1..65535): a bad one is a bad
    argument (exit 2) found before anything opens, not a port that would not open (exit 3)."""
    from urllib.parse import urlsplit

    from choreo.board.link import NETWORK_URLS

    if not url.lower().startswith(NETWORK_URLS):
        return
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError:
        port, parts = None, None
    if parts is None or not parts.hostname or port is None or port == 0:
        scheme = url.split("://", 1)[0]
        raise UsageError(f"--port {given}: give {scheme}://HOST:PORT, a port number 1..65535 "
                         f"(e.g. {scheme}://192.168.1.50:4000)")


class _RunReport:
    """What `run --json` prints: filled in as the run goes, so a failure still names the log."""

    def __init__(self, show: str) -> None:
        self.show = show
        self.session: Session | None = None
        self.result: RunResult | None = None
        self.error: str | None = None
        self.exit_code = 0

    def prepared(self, session: Session) -> None:
        """The run's settings are settled: the record names its show, log and robots."""
        self.session = session

    def finished(self, result: RunResult) -> None:
        self.result = result

    def failed(self, exc: ChoreoError) -> None:
        from choreo.cli.jsonout import error_record

        failure = error_record(exc)
        self.error, self.exit_code = failure["error"], failure["exit"]

    @property
    def record(self) -> dict:
        record: dict = {"show": self.show, "ok": self.exit_code == 0, "exit": self.exit_code}
        record.update(_session_record(self.session) if self.session is not None else {"log": None})
        result = self.result
        if result is not None:
            record.update(outcome=result.outcome, steps_run=result.steps_run,
                          late_steps=result.late_steps, show_s=round(result.show_s, 6))
        else:
            record.update(outcome="failed")
        if self.error is not None:
            record["error"] = self.error
        return record


def _session_record(session: Session) -> dict:
    """What `run --json` says of the run's settings: the show, the log, each robot's link."""
    settings = session.settings
    record: dict = {"name": settings.show.name,
                    "log": str(session.log_path) if session.log_path and session.recorder else None}
    if not settings.show.ensemble:  # with several robots, the first one's would pass for the show's
        solo = _solo(settings)
        record.update(port=solo.port, baud=solo.baud, layout=solo.layout.name)
    record["robots"] = {link.robot: {"port": link.port, "baud": link.baud, "layout": link.layout.name}
                        for link in settings.links.values()}
    if settings.show.ensemble:
        record["dropouts"] = [{"robot": d.robot, "show_s": round(d.show_s, 6), "error": str(d.error)}
                              for d in session.dropouts]
    if settings.song is not None:
        record["music"] = {"file": settings.song.music.file, "start": settings.song.music.start,
                           "output": settings.output.name if settings.output is not None else None}
    return record


@contextmanager
def _log_named_on_failure(session: Session, say: _Say) -> Iterator[None]:
    """A run that failed before it said where its log is (the port would not open) still has
    a log, with the error in it: say where, before the error line."""
    try:
        yield
    except BaseException:
        if session.recorder is not None and session.stage is not None and not session.stage.opened:
            say(f"log: {session.log_path}")
        raise


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


class _Say:
    """Lines for the user on stderr, before and after the show (never from its threads: those
    go through `Progress`); on a terminal each is cut to its width, measured at each line; a
    closed pipe or terminal never stops the show."""

    def __init__(self, out: TextIO, quiet: bool) -> None:
        self.out = out
        self.quiet = quiet

    def __call__(self, line: str) -> None:
        if self.quiet:
            return
        try:
            width = terminal_columns(self.out) if self.out.isatty() else None
            print(fit(line, width), file=self.out, flush=True)
        except (OSError, ValueError):
            self.quiet = True


def _solo(settings: RunSettings) -> LinkSettings:
    """A one-robot show's robot."""
    return next(iter(settings.links.values()))


def _opening_lines(settings: RunSettings) -> list[str]:
    """What the run says before it opens anything: the ports and layouts, the show, the music."""
    lines = _robot_lines(settings) if settings.show.ensemble else [
        _port_line(_solo(settings)), _layout_line(_solo(settings))]
    lines.append(_show_line(settings))
    if settings.show.music is not None:
        lines.append(_music_line(settings))
    return lines


def _show_line(settings: RunSettings) -> str:
    show, sections = settings.show, settings.sections
    start = sections.starts[_solo(settings).robot]  # shared steps: every robot starts at this step
    first = f" from step {start}" if start and not show.tracks else ""
    if show.tracks and sections.origin:
        first = f" from {sections.origin:.3f} s"
    estimated = max(plan.estimated_s for plan in settings.plans.values())
    if not show.ensemble:
        steps = len(settings.plans[_solo(settings).robot].steps)
        return f"show: {show.name}: {steps} steps{first}, about {estimated:.1f} s"
    form = "tracks" if show.tracks else "shared steps"
    return f"show: {show.name}: {len(settings.links)} robots, {form}{first}, about {estimated:.1f} s"


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
    from choreo.music.player import output_name

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


# Ctrl-\\ stops a show as Ctrl-C does: killed by it, no robot would get its abort motion and the
# log would be left unfinished.
_QUIT = tuple(getattr(signal, name) for name in ("SIGQUIT",) if hasattr(signal, name))
# A show cannot be suspended: Ctrl-Z (SIGTSTP), or a background run writing to a terminal set
# to `stty tostop` (SIGTTOU), would freeze it mid-motion, every later cue late. Ignored while it runs.
_HELD = tuple(getattr(signal, name) for name in ("SIGTSTP", "SIGTTOU") if hasattr(signal, name))


class _StopOnSignals:
    """First Ctrl-C, Ctrl-\\ or SIGTERM: finish the frame in flight, play the abort motion,
    close the log. Second: leave at once (the log is still closed on the way out). Ctrl-Z does
    not suspend the show (`_HELD`)."""

    def __init__(self, stop: StopRequest) -> None:
        self.stop = stop
        self._previous: dict = {}
        self._signalled = False  # a stop the log asked for is not a first Ctrl-C

    def __enter__(self):
        for signum in (*STOP_SIGNALS, *_QUIT):
            self._previous[signum] = signal.signal(signum, self._handle)
        for signum in _HELD:
            self._previous[signum] = signal.signal(signum, signal.SIG_IGN)
        return self.stop

    def _handle(self, signum, frame) -> None:
        if self._signalled:
            raise KeyboardInterrupt
        self._signalled = True
        name = "interrupted (Ctrl-C)" if signum == signal.SIGINT else f"stopped ({signal.Signals(signum).name})"
        self.stop.request(name)

    def __exit__(self, *exc_info) -> None:
        # The run is over and its log closed: a late Ctrl-C must not cut the last lines short
        # or kill the process by signal, so signals are ignored until `restore`.
        for signum in self._previous:
            signal.signal(signum, signal.SIG_IGN)

    def restore(self) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)


def _own_steps(plan: Plan, start: int, robot: str) -> list[int]:
    """The indices of the steps a robot plays from `start`: the progress line counts those."""
    return [step.index for step in plan.steps[start:] if step.is_for(robot)]


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
        own = self.counts.get(event.robot, [])
        place = f" ({own.index(step.index) + 1}/{len(own)})" if step.index in own else ""
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
        if level < 3 or level >= 4:
            return  # errors reach the user once, as the command's final line
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
        self.writer.line(text)

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
