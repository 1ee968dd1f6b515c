"""`choreo run SHOW`: play a show, with a progress line, Ctrl-C handling and a log."""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Iterator
from contextlib import ExitStack, closing, contextmanager, nullcontext
from typing import TYPE_CHECKING

from choreo.errors import ChoreoError, Interrupted, UsageError
from choreo.show.model import CLOCKS, LINK, MACHINE
from choreo.signals import STOP_SIGNALS
from choreo.wire.layouts import LAYOUT_NAMES
from choreo.wire.protocol import spell_bauds

if TYPE_CHECKING:  # the run's modules load when a run starts: `choreo validate` and --help stay light
    from choreo.cli.progress import Progress, Say
    from choreo.events import RunResult, StopRequest
    from choreo.live.controls import Live
    from choreo.live.osc import OscServer
    from choreo.live.status import ShowStatus
    from choreo.run.session import Session
    from choreo.run.settings import RunSettings


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
    parser.add_argument("--host", metavar="NAME", help="in a show with `hosts:`, the host this computer is: "
                        "it drives that host's robots only (the others' hosts drive theirs)")
    parser.add_argument("--clock", choices=CLOCKS, help="the show clock, instead of the show's "
                        "`clock:`: link (the Ableton Link session's beat) or machine (a rehearsal of a Link show "
                        "on this computer's clock)")
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
    from choreo.cli.progress import Progress, Say, opening_lines
    from choreo.events import ResultListener, StopRequest
    from choreo.run.session import Session
    from choreo.run.settings import RunRequest

    port, robot_ports = port_arguments(args.port)
    osc_port, notify = _check_osc_options(args)
    request = RunRequest(args.show, port=port, baud=args.baud, log_path=args.log,
                         no_log=args.no_log, from_step=args.from_step, timeout=args.timeout,
                         retries=args.retries, layout=args.layout, robot_ports=robot_ports,
                         no_music=args.no_music, audio_device=args.audio_device, loop=args.loop,
                         rehearse=args.rehearse, host=args.host, clock=args.clock)
    session = Session.prepare(request, args.time_source)
    report.prepared(session)
    console = _wants_console(args)
    _check_go_sources(session.settings, console, args)
    stop = StopRequest()
    live, status = _live(args, stop, console, session)
    # listening (not serving yet) before a line is said or anything opens
    osc = _bound_osc(args, osc_port, notify, live)
    say = Say(sys.stderr, quiet=args.quiet)
    for line in opening_lines(session.settings):
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
            with closing(live) if live is not None else nullcontext(), _watching(session, status) as watchers, \
                    _console(session, live, console, listeners, status):
                result = session.run([progress, *watchers, *listeners], stop, live)
                for listener in listeners:
                    if isinstance(listener, ResultListener):  # OSC notify: the run is over
                        listener.on_result(result)
        report.finished(result)
        progress.finish()
        say.ended(result.outcome == "done")
        late = f", {result.late_steps} late" if result.late_steps else ""
        took = f"in {result.show_s:.3f} s" if result.show_s >= 0 else "before the show's start (its count-in)"
        say(f"{result.outcome}: {result.steps_run} steps {took}{late}")
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


def _live(args: argparse.Namespace, stop: StopRequest, console: bool,
          session: Session) -> tuple[Live | None, ShowStatus | None]:
    """The Live that GO cues wait on, when someone can command the show (the console, OSC),
    with the show's cue list and the one status of its robots both the console and
    `/choreo/status` read; (None, None) for a show run as before."""
    if not console and args.osc is None:
        return None, None
    from choreo.live.controls import Live
    from choreo.live.status import ShowStatus
    from choreo.show.cues import cue_list

    settings = session.settings
    status = ShowStatus(settings.plans, settings.sections.starts)
    clock = LINK if settings.link is not None else "music" if settings.song else MACHINE
    # a show for several hosts starts when the session's transport does (or this host's start)
    waits = args.wait_start or (settings.link is not None and bool(settings.show.hosts))
    return Live(stop, cues=cue_list(settings.plans), status=status, clock=clock, wait_start=waits,
                opening=True), status


@contextmanager
def _watching(session: Session, status: ShowStatus | None) -> Iterator[list]:
    """The robots' status for the run's time: a listener of the run (the listeners to add:
    none without it) and of every link, subscribed once the session has opened them and
    closed after."""
    if status is None or session.stage is None:
        yield []
        return
    with ExitStack() as links:
        for robot, link in session.stage.links.items():
            links.enter_context(link.subscribe(status.link_listener(robot)))
        yield [status]


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
def _controls(live: Live | None, osc: OscServer | None, say: Say, progress: Progress) -> Iterator[list]:
    """The operator's controls for the run (none without a Live): the OSC server, bound
    already, serving before the session opens, which commands the Live and listens to the show
    (its notifications); the listeners the run should tell. The commands held back by the
    limits are summed up every `Limits.summary_every_s`, and once more at the end."""
    if live is None:
        yield []
        return
    from choreo.live.limits import LIMITS, Ticker

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
def _console(session: Session, live: Live | None, console: bool, listeners: list,
             status: ShowStatus | None = None) -> Iterator[None]:
    """The console, on a terminal, for the time of the show (it draws on the terminal and reads
    its keys: only once the session is open); it reads the robots' `status` (the run's)."""
    if not console or live is None:  # a console always has its Live (_live)
        yield
        return
    from choreo.cli.console import Console

    screen = Console(session, live, status=status)
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
    from choreo.cli.progress import solo

    settings = session.settings
    record: dict = {"name": settings.show.name,
                    "log": str(session.log_path) if session.log_path and session.recorder else None}
    if not settings.show.ensemble:  # with several robots, the first one's would pass for the show's
        link = solo(settings)
        record.update(port=link.port, baud=link.baud, layout=link.layout.name)
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
def _log_named_on_failure(session: Session, say: Say) -> Iterator[None]:
    """A run that failed before it said where its log is (the port would not open) still has
    a log, with the error in it: say where, before the error line."""
    try:
        yield
    except BaseException:
        if session.recorder is not None and session.stage is not None and not session.stage.opened:
            say(f"log: {session.log_path}")
        raise


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
