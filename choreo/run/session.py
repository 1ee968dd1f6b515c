"""One `choreo run`: settle the settings, open the log then the port, run, close both.

The order is the safety contract: the show is loaded and checked before anything is opened
(a bad file never moves the robot), the log is created before the port (a log that cannot be
written stops the run before any frame), and whatever happens the log is finished with the
run's outcome in its metadata.
"""

from __future__ import annotations

import contextlib
import math
import re
import sys
import threading
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from choreo.clock import (MachineShowClock, RunClock, ShowClock, SystemTime, TimeSource, quick_thread_switches,
                          sleep_until_show)
from choreo.errors import ChoreoError, Interrupted, LinkError, UsageError, did_you_mean
from choreo.wire.layouts import SEED, Layout, layout_named
from choreo.board.link import BAUD_RATES, DEFAULT_BAUD, DEFAULT_TIMEOUT_S, DEFAULT_TRIES, Link
from choreo.live.controls import HoldingShowClock, Live
from choreo.log.format import CLOCK_EVERY_S, ERROR, INFO, WARNING, ClockRecord
from choreo.music.player import LEAD_IN_S, Output, Player, Song, pick_output
from choreo.log.recorder import Recorder, RobotInfo, RunInfo, default_log_path
from choreo.run.runner import RunListener, Runner, RunResult, StopRequest
from choreo.show.model import DEFAULT_MOTION_S, Plan, RobotSettings, Show
from choreo.sim.options import SimUrl, durations_text, is_simulator


@dataclass(frozen=True)
class RunRequest:
    """What the user asked for on the command line (None: not given)."""

    show_path: str
    port: str | None = None
    baud: int | None = None
    log_path: str | None = None
    no_log: bool = False
    from_step: str | None = None
    timeout: float | None = None
    retries: int | None = None
    layout: str | None = None
    log_dir: str = "runs"
    robot_ports: Mapping[str, str] = field(default_factory=dict)  # `--port NAME=URL`
    no_music: bool = False  # `--no-music`: silent, on the machine's clock
    audio_device: str | None = None  # `--audio-device`: an output from `choreo devices`
    loop: str | None = None  # `--loop FROM..TO`: labels (or indices) of a section to repeat until stopped
    rehearse: bool = False  # `--rehearse`: every robot on the simulator, whatever the show or --port say


@dataclass(frozen=True)
class RobotLink:
    """One robot's link, every setting resolved and where it came from."""

    robot: str
    port: str
    port_source: str  # command line | show | simulator
    baud: int
    timeout: float
    tries: int
    layout: Layout = SEED
    layout_source: str = "default"  # command line | show | default (assumed)
    on_fault: str = "stop"

    @property
    def assumes_layout(self) -> bool:
        """Nobody said which layout, and a real board is on the port: the run must say so."""
        return self.layout_source == "default" and not is_simulator(self.port)


@dataclass
class Session:
    """A prepared run: the checked show, each robot's plan and link, every setting resolved."""

    show: Show
    plans: dict[str, Plan]
    starts: dict[str, int]  # where each robot's plan starts (--from)
    links: dict[str, RobotLink]
    log_path: Path | None
    origin: float = 0.0  # show time of the first step played (--from), 0 for a whole show
    unique_log: bool = False  # a default log name already taken gets a suffix instead of a refusal
    clock: RunClock = field(default_factory=RunClock)
    stage: Stage | None = None
    result: RunResult | None = None
    dropouts: list = field(default_factory=list)  # robots that dropped out (on_fault: continue)
    song: Song | None = None  # the music that keeps the show clock (None: the machine's clock)
    output: Output | None = None  # where it plays (None: the default output)
    player: Player | None = None  # while it plays
    loop: tuple[str, str] | None = None  # `--loop FROM..TO`, as given
    ends: dict[str, int] = field(default_factory=dict)  # where each robot's plan stops (--loop), by robot

    @classmethod
    def prepare(cls, request: RunRequest, time_source: TimeSource | None = None) -> Session:
        """Load and check the show and settle the settings; opens nothing.

        `time_source`: what the run's clock reads, the machine's time unless given (virtual
        time drives only the in-process simulator: a real port is then refused at open)."""
        from choreo.show.load import load_show
        from choreo.show.plan import compile_plans

        show = load_show(request.show_path)
        _check_robot_ports(show, request)
        links = {name: _robot_link(name, settings, request, show) for name, settings in show.cast.items()}
        _check_shared_ports(links)
        plans = compile_plans(show, {n: link.layout for n, link in links.items()},
                              {n: link.baud for n, link in links.items()})
        links = {name: replace(link, port=_for_robot(name, show, lambda: with_show_durations(
                     link.port, show, plans[name], link.baud, link.layout, show.abort_motion(name))))
                 for name, link in links.items()}
        if request.loop is not None and request.from_step is not None:
            raise UsageError(f"--loop {request.loop}: it starts where it says; leave out --from")
        loop = _loop_range(request.loop) if request.loop is not None else None
        starts, origin = _starts(show, plans, loop[0] if loop else request.from_step, "--loop" if loop else "--from")
        ends = _ends(show, plans, loop[1], starts, "--loop") if loop else {}
        if loop:
            _check_loop_length(plans, starts, ends, origin, request.loop)
        song, output = _music(show, request, time_source)
        if song is not None and (loop or request.from_step is not None):
            _check_in_song(song, origin, f"--loop {request.loop}" if loop else f"--from {request.from_step}")
        log_path = None
        if request.log_path and not request.no_log:
            check_output_folder(Path(request.log_path), "--log")
        if not request.no_log:
            log_path = Path(request.log_path) if request.log_path else default_log_path(
                show.name, request.log_dir)
        return cls(show, plans, starts, links, log_path, origin, unique_log=request.log_path is None,
                   clock=RunClock(time_source or SystemTime()), song=song, output=output, loop=loop, ends=ends)

    # -- the first (or only) robot: what a one-robot run reports ------------------------------

    @property
    def first(self) -> RobotLink:
        return next(iter(self.links.values()))

    @property
    def plan(self) -> Plan:
        return self.plans[self.first.robot]

    @property
    def start(self) -> int:
        return self.starts[self.first.robot]

    @property
    def port(self) -> str:
        return self.first.port

    @property
    def port_source(self) -> str:
        return self.first.port_source

    @property
    def baud(self) -> int:
        return self.first.baud

    @property
    def layout(self) -> Layout:
        return self.first.layout

    @property
    def layout_source(self) -> str:
        return self.first.layout_source

    @property
    def timeout(self) -> float:
        return self.first.timeout

    @property
    def tries(self) -> int:
        return self.first.tries

    @property
    def assumes_layout(self) -> bool:
        return self.first.assumes_layout

    # -- opening and closing ---------------------------------------------------------------

    @property
    def recorder(self):  # type: ignore[no-untyped-def]
        return self.stage.recorder if self.stage is not None else None

    @property
    def link(self) -> Link | None:
        return self.stage.link if self.stage is not None else None

    def __enter__(self) -> Session:
        robots = tuple(RobotInfo(n, l.port, l.baud, l.layout.name) for n, l in self.links.items()) \
            if self.show.ensemble else ()
        info = RunInfo(self.show.path, self.show.name, self.show.source, self.port, self.baud,
                       self.clock.wall_anchor_ns, self.layout.name, robots, self.plan.unison)
        self.stage = Stage(info, self.log_path, self.clock, list(self.links.values()), unique_log=self.unique_log,
                           named=self.show.ensemble)
        self.stage.__enter__()
        self.log_path = self.stage.log_path
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self.stage is not None:
            self.stage.__exit__(exc_type, exc, tb)

    # -- running ---------------------------------------------------------------------------

    def run(self, listeners: list[RunListener] = (), stop: StopRequest | None = None,
            live: Live | None = None) -> RunResult:
        """Play the show (with --loop, its section again and again until stopped); a log that
        cannot take more stops it like a stop request (the exchange in flight, then the abort
        motion) and its LogError is the run's outcome. `live`: the operator's controls (GO cues
        wait on them; --wait-start waits for start)."""
        assert self.stage is not None, "open the session first (with session:)"
        stop = live.stop if live is not None else stop if stop is not None else StopRequest()
        everyone = ([self.recorder] if self.recorder else []) + list(listeners)
        if self.recorder is not None:
            self.recorder.on_stop = stop.request
            if live is not None:
                live.listeners.append(self.recorder)
        if live is not None and not live.await_start():
            self.result = RunResult("aborted", 0, 0, 0.0)
        else:
            self.result = self._run_passes(everyone, stop, live)
        if self.recorder is not None:
            self.recorder.check()
        self.stage.outcome = self.result.metadata()
        return self.result

    def _run_passes(self, everyone: list[RunListener], stop: StopRequest, live: Live | None) -> RunResult:
        """One pass of the show, or with --loop as many of its section as run before a stop."""
        result = self._run_pass(everyone, stop, live)
        passes, steps, late = 1, result.steps_run, result.late_steps
        # A loop ends only when stopped: a stop between passes is seen by the next pass's
        # runners, which play the abort motions as on any stop.
        while self.loop is not None and result.outcome == "done":
            passes += 1
            self._tell(everyone, INFO, f"loop: pass {passes} from {self.loop[0]!r} to {self.loop[1]!r}")
            if live is not None:
                live.new_pass()  # its GO cues wait again
            result = self._run_pass(everyone, stop, live)
            steps, late = steps + result.steps_run, late + result.late_steps
        return RunResult(result.outcome, steps, late, result.show_s)

    def _run_pass(self, everyone: list[RunListener], stop: StopRequest, live: Live | None) -> RunResult:
        """The runners from the start (or --from, --loop's first step) to the end (or --loop's
        last step), on a show clock started for them."""
        assert self.stage is not None
        runners = {name: Runner(self.plans[name], self.stage.links[name], clock=self.clock, listeners=everyone,
                                start=self.starts[name], on_abort=self.show.abort_motion(name), stop=stop,
                                robot=name if self.show.ensemble else None, live=live,
                                end=self.ends.get(name))
                   for name in self.links}
        ensemble = self._ensemble(runners, stop, everyone) if self.show.ensemble else None
        preroll = ensemble.preroll_s() if ensemble is not None else runners[self.first.robot].preroll_s()
        with contextlib.ExitStack() as music:
            show = self._start_show_clock(preroll, everyone, music, holding=live is not None)
            if live is not None:
                live.show = show
            sampler = ClockSampler(self.recorder, self.clock, show, "music" if self.player else "machine") \
                if self.recorder is not None else None
            for runner in runners.values():
                runner.on_idle = sampler
            if sampler is not None and isinstance(show, HoldingShowClock):
                # the log marks where show time goes on after a GO: the reviews place later frames by it
                show.on_resume.append(lambda: sampler.sample(force=True))
            if sampler is not None:
                sampler.sample(force=True)
            result = runners[self.first.robot].run(show) if ensemble is None else self._run_ensemble(ensemble, show)
            if result.outcome == "done" and self.loop is None:
                self._play_out(show, stop, sampler, everyone)
            elif result.outcome == "done":
                self._end_of_section(show, stop)
            if sampler is not None:
                sampler.sample(force=True)
            return result

    def _ensemble(self, runners: dict[str, Runner], stop: StopRequest, listeners: list):  # type: ignore[no-untyped-def]
        from choreo.run.ensemble import Ensemble, Part

        parts = [Part(name, runner, self.links[name].on_fault) for name, runner in runners.items()]
        return Ensemble(parts, self.clock, stop, unison=self.plan.unison, origin=self.origin,
                        log=lambda level, message: self._tell(listeners, level, message))

    def _run_ensemble(self, ensemble, show: ShowClock) -> RunResult:  # type: ignore[no-untyped-def]
        try:
            return ensemble.run(show).combined()
        finally:
            self.dropouts = ensemble.dropouts

    # -- the show clock --------------------------------------------------------------------

    def _start_show_clock(self, preroll: float, listeners: list[RunListener], music: contextlib.ExitStack,
                          holding: bool = False) -> ShowClock:
        """The music's clock, its song started a lead-in before the run's first moment (a play
        cued at the very start goes out ahead of the first sample by its lead) and stopped when
        `music` closes, else the machine's, with the run's first moment `preroll` from now. The
        log's metadata gets show time 0 as wall-clock and monotonic nanoseconds either way."""
        assert self.stage is not None
        if self.song is None:
            zero = self.clock.mono() - (self.origin - preroll)
            # live, the machine's clock holds while a GO cue waits
            show: ShowClock = HoldingShowClock(zero, self.clock.mono, self.clock.source.notify) if holding else MachineShowClock(zero)
        else:
            self.player = Player(self.song, self.output, self.origin, max(LEAD_IN_S, preroll + LEAD_IN_S))
            show = self.player.start()
            music.callback(self._stop_music, listeners)
            # The audio thread shares the interpreter: spinning towards a cue yields to it, and
            # Python hands its lock over quickly.
            self.clock.source.admit(1)
            music.callback(self.clock.source.leave)
            music.enter_context(quick_thread_switches())
            if self.player.note is not None:
                self._tell(listeners, WARNING, self.player.note)
            self._tell(listeners, INFO, f"music: {self.player.describe()}")
        zero_ns = round(show.mono_at(0.0) * 1e9)
        self.stage.outcome_extra.update({
            "clock": "music" if self.player else "machine", "show_zero_monotonic_ns": str(zero_ns),
            "show_zero_wall_ns": str(self.clock.wall_ns(zero_ns))})
        if self.song is not None:
            self.stage.outcome_extra.update({"music.file": self.song.music.file, "music.start": f"{self.song.music.start:g}",
                                             "audio.backend": self.player.backend if self.player else ""})
        return show

    def _play_out(self, show: ShowClock, stop: StopRequest, sampler: ClockSampler | None,
                  listeners: list[RunListener]) -> None:
        """The show's last step is done: its music plays to the end (Ctrl-C stops it there; the
        show itself is done). Listeners with `on_play_out(end_s)` hear when it will end."""
        if self.player is None:
            return
        end = self.player.end_show_s
        if show.show_at(self.clock.mono()) < end:
            for listener in listeners:
                if hasattr(listener, "on_play_out"):
                    listener.on_play_out(end)
        while show.show_at(self.clock.mono()) < end and not stop():
            self.clock.sleep(min(0.05, max(0.0, show.mono_at(end) - self.clock.mono())))
            if sampler is not None:
                sampler()

    def _end_of_section(self, show: ShowClock, stop: StopRequest) -> None:
        """A --loop pass lasts until the step after its last one is planned (or the last
        motion's expected end): the section's last motion plays out before the next pass."""
        sleep_until_show(self.clock, show, _section_end(self.plans, self.ends), stop)

    def _stop_music(self, listeners: list[RunListener]) -> None:
        if self.player is None:
            return
        self.player.close()
        problem = self.player.feed.problem if self.player.feed is not None else None
        if problem is not None:
            self._tell(listeners, WARNING, f"music: {self.player.song.music.file} stopped decoding early "
                                           f"({problem}); the show clock ran on in silence")
        self.player = None

    def _tell(self, listeners: list[RunListener], level: int, message: str) -> None:
        for listener in listeners:
            listener.on_log(level, message, self.clock.wall_ns())


@dataclass
class Stage:
    """What a run opens and must close: its log, then its ports; closed in reverse, the log
    finished with the run's outcome in its metadata whatever happened.

    `choreo run` and `choreo replay` both open through it, so their logs say the same things
    the same way: a port that will not open is an error line in a log that exists, and an
    interrupted or failed run is said so with its exit code. With several robots (`named`),
    each link's frames go to its robot's topics.
    """

    info: RunInfo
    log_path: Path | None  # None: no log
    clock: RunClock
    robots: list[RobotLink]
    unique_log: bool = False
    opening_note: str | None = None  # logged before the port opens (what this run is)
    named: bool = False  # several robots: topics and messages name each robot
    outcome: dict[str, str] | None = None  # the finished run's metadata, set by whoever ran it
    recorder: Recorder | None = None
    links: dict[str, Link] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)  # what the user should hear once the ports are open
    opened: bool = False  # every port opened
    outcome_extra: dict[str, str] = field(default_factory=dict)  # what the run adds to the outcome (its clock)

    @property
    def link(self) -> Link | None:
        """The first (or only) robot's link."""
        return next(iter(self.links.values()), None)

    def __enter__(self) -> Stage:
        try:
            self._open()
        except BaseException:
            self.__exit__(*sys.exc_info())
            raise
        return self

    def _open(self) -> None:
        if self.log_path is not None:
            self.recorder = Recorder(self.log_path, self.info, unique=self.unique_log)
            self.log_path = self.recorder.path
            if self.opening_note:
                self.recorder.on_log(INFO, self.opening_note, self.clock.wall_ns())
        for robot in self.robots:
            self.links[robot.robot] = self._open_link(robot)
            note = self.links[robot.robot].latency_note
            if note is not None:
                self.notes.append(f"robot {robot.robot}: {note}" if self.named else note)
                if self.recorder is not None:
                    self.recorder.on_log(WARNING, self.notes[-1], self.clock.wall_ns())
        self.opened = True

    def _open_link(self, robot: RobotLink) -> Link:
        listeners = []
        if self.recorder is not None:
            listeners.append(self.recorder.for_robot(robot.robot) if self.named else self.recorder)
        try:
            return Link.open(robot.port, robot.baud, timeout=robot.timeout, tries=robot.tries, clock=self.clock,
                             listeners=listeners, layout=robot.layout)
        except LinkError as exc:
            if self.named:
                exc = LinkError(f"robot {robot.robot}: {exc}")
            if self.recorder is not None:
                self.recorder.on_log(ERROR, str(exc), self.clock.wall_ns())
            raise exc from None

    def __exit__(self, exc_type, exc, tb) -> None:
        for link in self.links.values():
            link.close()
        if self.recorder is not None:
            self.recorder.close({**outcome_metadata(self.outcome, exc), **self.outcome_extra})


def _music(show: Show, request: RunRequest, time_source: TimeSource | None) -> tuple[Song | None, Output | None]:
    """The song that keeps the show clock, and its output; (None, None) on the machine's clock.
    A song that will not decode, or an output that is not there, stops the run here (exit 2)."""
    if show.music is None or request.no_music:
        if request.audio_device is not None and show.music is None:
            raise UsageError(f"--audio-device {request.audio_device}: the show has no `music:` to play")
        return None, None
    if time_source is not None and time_source.virtual:
        raise UsageError("music plays in real time, not on virtual time: run with --no-music")
    return Song.open(show.music, show.path), pick_output(request.audio_device)


class ClockSampler:
    """Samples the show clock against the monotonic clock into the log's /choreo/clock every
    CLOCK_EVERY_S of show time; it rides on the runners' idle time (when they sleep towards a
    step), so it never delays a frame, and with the log's own idle work after it."""

    def __init__(self, recorder: Recorder, clock: RunClock, show: ShowClock, source: str,
                 every_s: float = CLOCK_EVERY_S) -> None:
        self.recorder = recorder
        self.clock = clock
        self.show = show
        self.source = source
        self.every_s = every_s
        self._last: float | None = None
        self._lock = threading.Lock()

    def __call__(self) -> None:
        self.sample()
        self.recorder.on_idle()

    def sample(self, force: bool = False) -> None:
        with self._lock:
            mono_ns = self.clock.mono_ns()
            show_s = self.show.show_at(mono_ns / 1e9)
            if not force and self._last is not None and show_s - self._last < self.every_s:
                return
            self._last = show_s
        self.recorder.on_clock(ClockRecord(round(show_s, 6), mono_ns, self.source), self.clock.wall_ns(mono_ns))


def _robot_link(name: str, robot: RobotSettings, request: RunRequest, show: Show) -> RobotLink:
    """One robot's settings: the command line, else the show, else the defaults."""
    baud = _pick(request.baud, robot.baud, DEFAULT_BAUD)
    if baud not in BAUD_RATES:
        raise UsageError(f"baud {baud}: the RCB-4 runs at {', '.join(map(str, BAUD_RATES))}")
    layout, layout_source = _layout(request.layout, robot.layout)
    timeout = float(_pick(request.timeout, robot.timeout, DEFAULT_TIMEOUT_S))
    retries = int(_pick(request.retries, robot.retries, DEFAULT_TRIES - 1))
    check_timeout(timeout)
    if not 0 <= retries <= MAX_RETRIES:
        raise UsageError(f"--retries {retries}: give 0..{MAX_RETRIES} retries after a failed try")
    given = request.robot_ports.get(name) if show.ensemble else request.port
    if request.rehearse:
        if given is not None and not is_simulator(given):
            raise UsageError(f"--rehearse runs every robot on the simulator: leave out --port {given}")
        port, source = given or "sim://", "simulator (--rehearse)"
    elif given is not None:
        if not given.strip():
            raise UsageError("--port: empty; give a device (/dev/ttyUSB0, COM3) or a URL (sim://)")
        port, source = given, "command line"
    elif robot.port:
        port, source = robot.port, "show"
    else:
        port, source = "sim://", "simulator"
    return RobotLink(name, port, source, baud, timeout, retries + 1, layout, layout_source, robot.on_fault)


def _check_shared_ports(links: dict[str, RobotLink]) -> None:
    """Two robots on one device, however each got its port (show, --port): refused before any
    port opens, not a lock error halfway through opening them."""
    from choreo.show.load import same_port

    seen: dict[str, RobotLink] = {}
    for link in links.values():
        if is_simulator(link.port):
            continue
        first = seen.setdefault(same_port(link.port), link)
        if first is not link:
            raise UsageError(f"robot {link.robot}'s port {link.port} ({link.port_source}) is robot {first.robot}'s "
                             f"too ({first.port_source}): each robot needs its own port")


def _for_robot(name: str, show: Show, make):  # type: ignore[no-untyped-def]
    """A usage error about one robot of several says which robot."""
    try:
        return make()
    except UsageError as exc:
        raise UsageError(f"robot {name}: {exc}") if show.ensemble else exc from None


ROBOT_PORT = re.compile(r"^([A-Za-z][A-Za-z0-9_-]{0,31})=(.*)$", re.S)


def split_robot_port(value: str) -> tuple[str, str] | None:
    """`--port left=/dev/ttyUSB0` -> ("left", "/dev/ttyUSB0"); a plain port (which may hold
    `=` itself, `sim://?drop=5`) -> None."""
    match = ROBOT_PORT.match(value)
    return (match.group(1), match.group(2)) if match else None


def _check_robot_ports(show: Show, request: RunRequest) -> None:
    """`--port URL` is for a one-robot show, `--port NAME=URL` for one of several."""
    if show.ensemble and request.port is not None:
        names = ", ".join(show.cast)
        raise UsageError(f"--port {request.port}: this show has several robots ({names}): "
                         f"give --port NAME=URL for each robot to move off its show port")
    if not show.ensemble and request.robot_ports:
        name = next(iter(request.robot_ports))
        raise UsageError(f"--port {name}=...: this show is for one robot (it names no `robots:`): give --port URL")
    for name in request.robot_ports:
        if name not in show.cast:
            raise UsageError(f"--port {name}=...: the show has no robot {name!r}"
                             f"{did_you_mean(name, list(show.cast))}; its robots: {', '.join(show.cast)}")


def outcome_metadata(finished: dict[str, str] | None, exc: BaseException | None) -> dict[str, str]:
    """The log's last word: what the run said when it finished, else why it did not."""
    if finished is not None and exc is None:
        meta = dict(finished)
    elif isinstance(exc, (Interrupted, KeyboardInterrupt)):
        meta = {"outcome": "interrupted"}
    else:
        meta = {"outcome": "failed"}
    if isinstance(exc, ChoreoError):
        meta["error"] = str(exc)
        meta["exit_code"] = str(exc.exit_code)
    elif isinstance(exc, KeyboardInterrupt):
        meta["exit_code"] = "130"
    elif exc is None:
        meta.setdefault("exit_code", "130" if meta["outcome"] == "aborted" else "0")
    return meta


def simulator_url(show: Show, plan: Plan, baud: int = DEFAULT_BAUD, layout: Layout = SEED) -> str:
    """`sim://` with the show's motion durations (so `wait: done` behaves as on the robot), the
    run's baud (a board at another baud would not answer) and layout."""
    return with_show_durations("sim://", show, plan, baud, layout)


def check_output_folder(path: Path, option: str) -> None:
    """An output given by name goes into a folder that exists: it is refused, never created (a
    typo would otherwise scatter files). Only the default log folder, runs/, is made."""
    folder = path.parent
    if not folder.is_dir():
        what = "is not a folder" if folder.exists() else "does not exist"
        raise UsageError(f"{option} {path}: cannot write: folder {folder} {what} (create it first)")


def simulator(url: str) -> SimUrl:
    """A `sim://` URL's options; a bad one is exit 2 before anything opens, in `run`, `replay`
    and `choreo sim` alike, not a port that failed to open (exit 3)."""
    try:
        return SimUrl.parse(url)
    except ValueError as exc:
        raise UsageError(f"--port {url}: {exc}") from None


def with_show_durations(url: str, show: Show | None, plan: Plan | None,
                        baud: int = DEFAULT_BAUD, layout: Layout = SEED, on_abort: int | None = None) -> str:
    """A `sim://` port gets what its URL does not say: the show's durations (when there is a
    show), the run's baud and the run's layout, wherever the URL came from.

    `--port 'sim://?drop=5'` then still runs the show's motions for their expected lengths; a
    URL that sets `durations`, `motion_s`, `baud` or `layout` itself is left to say so (a sim
    with another layout than the run's shows what a wrong layout does: stray calls).
    """
    if not is_simulator(url):
        return url
    given = simulator(url)
    added: dict[str, str] = {}
    if show is not None and plan is not None and not given.says("motion_s"):
        abort = on_abort if on_abort is not None else show.on_abort
        durations = {motion: show.duration_of(motion) or DEFAULT_MOTION_S
                     for motion in plan.motions_used() + ([abort] if abort is not None else [])}
        if durations:
            added["durations"] = durations_text(durations)
    if baud != DEFAULT_BAUD:
        added["baud"] = str(baud)
    if layout is not SEED:
        added["layout"] = layout.name
    amended = given.unless_given(**added)
    return url if amended == given else str(amended)


MAX_TIMEOUT_S = 10.0
MIN_LOOP_S = 0.1  # a --loop pass's least show time: its motions restart at most 10 times a second
MAX_RETRIES = 10


def check_timeout(timeout: float) -> float:
    """A reply timeout a run can live with: a number of seconds, 0 < t <= 10."""
    if not math.isfinite(timeout) or not 0 < timeout <= MAX_TIMEOUT_S:
        raise UsageError(f"--timeout {timeout:g}: give the seconds to wait for a reply, "
                         f"more than 0 and at most {MAX_TIMEOUT_S:g}")
    return timeout


def _starts(show: Show, plans: dict[str, Plan], ref: str | None,
            option: str = "--from") -> tuple[dict[str, int], float]:
    """Where each robot's plan starts with `--from`, and that step's show time.

    Shared steps: the step by index or label, for every robot. Tracks: the labelled step's
    planned time, and each track from its first step planned at or after it (a label names a
    moment of the show, whichever track it is written in)."""
    if ref is None:
        return dict.fromkeys(plans, 0), 0.0
    if not show.tracks:
        first = next(iter(plans.values()))
        index = _start_index(first, ref, option)
        return dict.fromkeys(plans, index), first.steps[index].planned_s if index < len(first.steps) else 0.0
    moment = _moment(plans, ref, f"{option} {ref}")
    return {name: next((s.index for s in plan.steps if s.planned_s >= moment - 1e-9), len(plan.steps))
            for name, plan in plans.items()}, moment


def _moment(plans: dict[str, Plan], ref: str, given: str) -> float:
    """The show time of the step labelled `ref` in any track: tracks are named by labels."""
    moment = next((step.planned_s for plan in plans.values() for step in plan.steps if step.label == ref), None)
    if moment is None:
        labels = [s.label for plan in plans.values() for s in plan.steps if s.label]
        raise UsageError(f"{given}: no step with that label in any track{did_you_mean(ref, labels)}"
                         f"{'; labels: ' + ', '.join(labels[:12]) if labels else ''} (tracks are named by labels, "
                         "not indices)")
    return moment


def _loop_range(text: str) -> tuple[str, str]:
    """`--loop verse..chorus` -> ("verse", "chorus")."""
    first, sep, last = text.partition("..")
    if not sep or not first.strip() or not last.strip():
        raise UsageError(f"--loop {text}: give FROM..TO, two labels (or step indices from `choreo plan`), "
                         "e.g. --loop verse..chorus")
    return first.strip(), last.strip()


def _ends(show: Show, plans: dict[str, Plan], ref: str, starts: dict[str, int], option: str) -> dict[str, int]:
    """Where each robot's plan stops for --loop's TO (that step included): shared steps by index
    or label; tracks, each at its last step planned at or before the labelled moment."""
    if not show.tracks:
        first = next(iter(plans.values()))
        index = _start_index(first, ref, f"{option} ..") + 1
        if index <= starts[first.robot]:
            raise UsageError(f"{option} ..{ref}: it comes before the loop's first step")
        return dict.fromkeys(plans, index)
    moment = _moment(plans, ref, f"{option} ..{ref}")
    ends = {name: 1 + max((s.index for s in plan.steps if s.planned_s <= moment + 1e-9), default=-1)
            for name, plan in plans.items()}
    if all(ends[name] <= starts[name] for name in plans):
        raise UsageError(f"{option} ..{ref}: it comes before the loop's first step")
    return ends


def _section_end(plans: dict[str, Plan], ends: dict[str, int]) -> float:
    """The show time a --loop pass ends at: where the step after the section is planned (the
    show's expected end after the last step), the latest of every robot's."""
    return max(plan.steps[ends[name]].planned_s if ends[name] < len(plan.steps) else plan.estimated_s
               for name, plan in plans.items())


def _check_loop_length(plans: dict[str, Plan], starts: dict[str, int], ends: dict[str, int], origin: float,
                       given: str) -> None:
    """A pass over (nearly) no show time would restart its motions as fast as the port allows
    (a section of plays and zero-length waits: 1,899 restarts in 2.3 s); a GO cue in it paces it
    by hand, anything else must last MIN_LOOP_S."""
    if any(step.go for name, plan in plans.items() for step in plan.steps[starts[name]:ends[name]]):
        return
    length = _section_end(plans, ends) - origin
    if length < MIN_LOOP_S - 1e-9:
        raise UsageError(f"--loop {given}: one pass lasts {max(length, 0.0):.3f} s of show time; a loop needs "
                         f"{MIN_LOOP_S:g} s at least (its motions would restart {_rate(length)}): end it at a "
                         "later step (a `wait: done` after its last play), or add a GO cue to pace it")


def _rate(length: float) -> str:
    return "without pause" if length <= 0 else f"{1 / length:.0f} times a second"


def _check_in_song(song: Song, origin: float, given: str) -> None:
    """In a music show, show time is the song's position: a start at or past its end would run
    the show in silence, on a clock that no longer moves with anything."""
    end = song.end_show_s
    if origin >= end - 1e-9:
        raise UsageError(f"{given}: it starts at {origin:.3f} s of show time, past the end of the music "
                         f"({song.path} ends at {max(end, 0.0):.3f} s): nothing would play; give an earlier "
                         "step, or --no-music to run on the machine's clock")


def _start_index(plan: Plan, ref: str | None, option: str = "--from") -> int:
    if ref is None:
        return 0
    try:
        return plan.find(ref)
    except KeyError:
        labels = [s.label for s in plan.steps if s.label]
        shown = ", ".join(labels[:12]) + (", ..." if len(labels) > 12 else "")
        known = f"; labels: {shown}" if labels else ""
        raise UsageError(f"{option}{'' if option.endswith('..') else ' '}{ref}: no step with that index (0..{len(plan.steps) - 1}) "
                         f"or label{did_you_mean(ref, labels)}{known}") from None


def _layout(given: str | None, in_show: str | None) -> tuple[Layout, str]:
    """The run's layout and who chose it: `--layout`, the show's robot.layout, else seed."""
    if given is not None:
        try:
            return layout_named(given), "command line"
        except ValueError as exc:
            raise UsageError(f"--layout: {exc}") from None
    if in_show is not None:
        return layout_named(in_show), "show"
    return SEED, "default"


def _pick(*values):
    return next(v for v in values if v is not None)
