"""A run's settings, settled once before anything opens: what the user asked for (`RunRequest`),
and what the show and the defaults make of it (`RunSettings`, a `LinkSettings` per robot).

Each setting is worked out here and nowhere else: the session, the stage that opens the ports,
`choreo replay` and the command line all read these objects. A link's settings say where each
value came from (the command line, the show, a default), because the run says it to the user.

A `sim://` port is opened with what its URL leaves unsaid filled in from the settings (the
show's motion durations, the run's baud and layout, a replay's speed): `port_url` builds that
URL from a `LinkSettings`, in one place, and nothing edits a URL string after it is built.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property, partial
from pathlib import Path
from typing import TypeVar

from choreo.board.link import DEFAULT_TIMEOUT_S, DEFAULT_TRIES
from choreo.clock import TimeSource
from choreo.errors import UsageError, did_you_mean
from choreo.log import LOG_DIR
from choreo.log.recorder import RobotInfo, RunInfo, default_log_path
from choreo.music.player import Output, Song, pick_output
from choreo.run.sections import Sections, select
from choreo.show.load import load_show
from choreo.show.model import (
    CLOCKS,
    DEFAULT_MOTION_S,
    LINK_METER,
    LINK_NO_GO,
    LINK_NO_MAP,
    LINK_NO_MUSIC,
    LINK_MIN_BPM,
    LINK_NO_OFFSET,
    MACHINE,
    SIM_URL,
    LinkClock,
    Plan,
    RobotSettings,
    Show,
    is_simulator,
    same_port,
)
from choreo.show.plan import compile_plans
from choreo.sim.options import SimUrl, durations_text, ms_text
from choreo.textfit import visible
from choreo.userfile import folder_problem
from choreo.wire.layouts import SEED, Layout, layout_named
from choreo.wire.protocol import BAUDS, DEFAULT_BAUD, baud_refusal

MAX_TIMEOUT_S = 10.0
MAX_RETRIES = 10

T = TypeVar("T")
Durations = tuple[tuple[int, float], ...]  # motion number -> seconds, in the order the plan uses them


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
    log_dir: str = LOG_DIR
    robot_ports: Mapping[str, str] = field(default_factory=dict)  # `--port NAME=URL`
    no_music: bool = False  # `--no-music`: silent, on the machine's clock
    audio_device: str | None = None  # `--audio-device`: an output from `choreo devices`
    loop: str | None = None  # `--loop FROM..TO`: labels (or indices) of a section to repeat until stopped
    rehearse: bool = False  # `--rehearse`: every robot on the simulator, whatever the show or --port say
    host: str | None = None  # `--host NAME`: the show's `hosts:` entry this run drives
    clock: str | None = None  # `--clock link|machine`: overrides the show's `clock:`


@dataclass(frozen=True)
class LinkSettings:
    """One robot's link, every setting resolved and where it came from.

    `given_port` is the port as the command line or the show named it; `port`, the one opened,
    is derived from it and the other settings (`port_url`): a simulator gets the show's
    `durations`, the baud, the board's layout and the `speed` its URL does not say itself.
    """

    robot: str
    given_port: str
    port_source: str  # command line | show | simulator | simulator (--rehearse)
    baud: int
    timeout: float
    tries: int
    layout: Layout = SEED
    layout_source: str = "default"  # command line | show | default (assumed)
    on_fault: str = "stop"
    durations: Durations | None = None  # the show's motion lengths, for a simulator (None: no show)
    board_layout: Layout | None = None  # a simulator's layout when it is not the link's (a replay's)
    speed: float = 1.0  # a replay's: a simulator runs its motions this many times faster

    @cached_property
    def port(self) -> str:
        """The port the link opens (UsageError for a `sim://` URL the simulator refuses)."""
        return port_url(self)

    @property
    def assumes_layout(self) -> bool:
        """Nobody said which layout, and a real board is on the port: the run must say so."""
        return self.layout_source == "default" and not is_simulator(self.given_port)


@dataclass(frozen=True)
class RunSettings:
    """A prepared run's settings: the checked show, each robot's plan and link, the section
    played, the music and the log, all settled before anything opens."""

    show: Show
    plans: Mapping[str, Plan]
    links: Mapping[str, LinkSettings]
    sections: Sections
    log_path: Path | None  # as asked, or the default name (None: --no-log)
    unique_log: bool = False  # a default log name already taken gets a suffix instead of a refusal
    song: Song | None = None  # the music that keeps the show clock (None: the machine's clock)
    output: Output | None = None  # where it plays (None: the default output)
    host: str | None = None  # the `hosts:` entry driven (its robots only); None: a show for one host
    link: LinkClock | None = None  # the Ableton Link clock's settings; None: not on the Link clock

    @classmethod
    def settle(cls, request: RunRequest, time_source: TimeSource | None = None, *,
               loaded: Show | None = None) -> RunSettings:
        """Load and check the show (unless `loaded` already) and settle every setting; opens
        nothing. A virtual `time_source` refuses music (it plays in real time)."""
        show = loaded if loaded is not None else load_show(request.show_path)
        host = _host(show, request.host)
        _check_robot_ports(show, request, host)
        cast = {name: robot for name, robot in show.cast.items() if host is None or name in show.hosts[host]}
        lone = _lone_robot(show, host) if request.port is not None else None
        drafts = {name: _link_settings(name, robot, request, show.ensemble and name != lone)
                  for name, robot in cast.items()}
        _check_shared_ports(drafts)
        every = compile_plans(show, {n: link.layout for n, link in drafts.items()},
                              {n: link.baud for n, link in drafts.items()})
        link = _link_clock(show, every, request)
        if link is not None and host is not None and request.loop is not None:
            # each host would end its pass on its own robots' last motion and start the next on
            # its own next bar line: the hosts would part
            raise UsageError(f"--loop {visible(request.loop)}: not on the Link clock with --host (each host would "
                             "start its next pass on a bar line of its own): rehearse the section with "
                             "--clock machine, or run it once with --from")
        plans = {name: every[name] for name in cast}  # another host's robots are its business
        links = {name: _for_robot(name, show, partial(_with_durations, show, plans[name], link))
                 for name, link in drafts.items()}
        sections = _only(select(show, every, request.from_step, request.loop), cast)
        song, output = _music(show, request, time_source) if link is None else (None, None)
        if song is not None and (request.loop is not None or request.from_step is not None):
            given = f"--loop {request.loop}" if request.loop is not None else f"--from {request.from_step}"
            _check_in_song(song, sections.origin, given)
        return cls(show, plans, links, sections, _log_path(show, request), unique_log=request.log_path is None,
                   song=song, output=output, host=host, link=link)

    def run_info(self, start_ns: int) -> RunInfo:
        """What the log's metadata says of the run: the show, the first robot's link (a one-robot
        show's only one) and, with several robots, each robot's."""
        show, first = self.show, next(iter(self.links.values()))
        robots = tuple(RobotInfo(name, link.port, link.baud, link.layout.name) for name, link in self.links.items()) \
            if show.ensemble else ()
        return RunInfo(show.path, show.name, show.source, first.port, first.baud, start_ns, first.layout.name, robots,
                       self.plans[first.robot].unison, show_host=self.host)


def _host(show: Show, given: str | None) -> str | None:
    """The host this run drives: `--host`, one of the show's `hosts:` (and only in a show that
    has them: every robot of it is some host's, so a run without --host would drive them all)."""
    names = ", ".join(show.hosts)
    if given is None:
        if show.hosts:
            raise UsageError(f"this show is played by several hosts ({names}): give --host NAME for the one "
                             "this computer drives")
        return None
    if not show.hosts:
        raise UsageError(f"--host {visible(given)}: the show names no `hosts:` (one computer drives all its "
                         "robots): leave out --host")
    if given not in show.hosts:
        raise UsageError(f"--host {visible(given)}: the show has no host {visible(given)!r}"
                         f"{did_you_mean(given, list(show.hosts))}; its hosts: {names}")
    return given


def _link_clock(show: Show, plans: Mapping[str, Plan], request: RunRequest) -> LinkClock | None:
    """The run's Link clock (None: the machine's, or the music's): the show's `clock:`, or
    `--clock`'s. `--clock link` takes a show written for the machine's clock onto the session's
    when nothing in it needs a clock that stops or a tempo of its own (the show's checks say the
    same of a show written `clock: link`); `--clock machine` rehearses a Link show without one."""
    clock = show.clock if request.clock is None else request.clock
    if clock not in CLOCKS:
        raise UsageError(f"--clock {visible(clock)}: give {' or '.join(CLOCKS)}")
    if clock == MACHINE:
        return None
    if show.link is not None:
        return show.link
    tempo = show.tempo
    refusal = (f"the show has `music:`; {LINK_NO_MUSIC}: add --no-music" if show.music and not request.no_music
               else f"the show has a tempo map; {LINK_NO_MAP}" if tempo is not None and tempo.bars
               else f"the show's bar 1 is at {tempo.offset:g} s; {LINK_NO_OFFSET}: make `tempo.offset` 0"
               if tempo is not None and tempo.offset
               else f"the show's tempo is {tempo.bpm:g} bpm; a Link session's is {LINK_MIN_BPM:g} at the least"
               if tempo is not None and tempo.bpm < LINK_MIN_BPM else _go_refusal(plans))
    if refusal is not None:
        raise UsageError(f"--clock link: {refusal} (or leave out --clock link)")
    return LinkClock(tempo.bpm, tempo.meter) if tempo is not None else LinkClock(None, LINK_METER)


def _go_refusal(plans: Mapping[str, Plan]) -> str | None:
    step = next((step for plan in plans.values() for step in plan.steps if step.go), None)
    if step is None:
        return None
    return f"step {step.name} (line {step.line}) waits for GO; {LINK_NO_GO}: cue it in bars and beats or in seconds"


def _only(sections: Sections, robots: Mapping[str, object]) -> Sections:
    """The section, chosen on every robot's plan (a label may be in another host's track), for
    this run's robots."""
    return replace(sections, starts={name: i for name, i in sections.starts.items() if name in robots},
                   ends={name: i for name, i in sections.ends.items() if name in robots})


def _log_path(show: Show, request: RunRequest) -> Path | None:
    """The log the run writes: --log's (in a folder that exists), else runs/<show>-<time>."""
    if request.no_log:
        return None
    if request.log_path:
        check_output_folder(Path(request.log_path), "--log")
        return Path(request.log_path)
    return default_log_path(show.name, request.log_dir)


def _link_settings(name: str, robot: RobotSettings, request: RunRequest, ensemble: bool) -> LinkSettings:
    """One robot's settings: the command line, else the show, else the defaults (no durations
    yet: they come from its plan, compiled for this baud and layout)."""
    baud = _pick(request.baud, robot.baud, DEFAULT_BAUD)
    if baud not in BAUDS:
        raise UsageError(baud_refusal(baud))
    layout, layout_source = _layout(request.layout, robot.layout)
    timeout = float(_pick(request.timeout, robot.timeout, DEFAULT_TIMEOUT_S))
    retries = int(_pick(request.retries, robot.retries, DEFAULT_TRIES - 1))
    check_timeout(timeout)
    if not 0 <= retries <= MAX_RETRIES:
        raise UsageError(f"--retries {retries}: give 0..{MAX_RETRIES} retries after a failed try")
    port, source = _port(request.robot_ports.get(name) if ensemble else request.port, robot, request)
    return LinkSettings(name, port, source, baud, timeout, retries + 1, layout, layout_source, robot.on_fault)


def _port(given: str | None, robot: RobotSettings, request: RunRequest) -> tuple[str, str]:
    """A robot's port and where it came from: --rehearse, --port (`given`), the show, else the
    simulator."""
    if request.rehearse:
        if given is not None and not is_simulator(given):
            raise UsageError(f"--rehearse runs every robot on the simulator: leave out --port {given}")
        return given or SIM_URL, "simulator (--rehearse)"
    if given is not None:
        if not given.strip():
            raise UsageError("--port: empty; give a device (/dev/ttyUSB0, COM3) or a URL (sim://)")
        return given, "command line"
    if robot.port:
        return robot.port, "show"
    return SIM_URL, "simulator"


def _with_durations(show: Show, plan: Plan, draft: LinkSettings) -> LinkSettings:
    """A robot's settings complete: its plan's motion durations for a simulator. Its port is
    built now: a `sim://` URL the simulator would refuse is refused before anything opens."""
    link = replace(draft, durations=show_durations(show, plan, show.abort_motion(draft.robot)))
    port_url(link)
    return link


def show_durations(show: Show | None, plan: Plan | None, abort: int | None = None) -> Durations | None:
    """How long each motion the plan plays (and the abort motion, `abort` else the show's
    `on_abort`) runs, as the show says or the default: what a simulator needs so that
    `wait: done` behaves as on the robot. None without a show."""
    if show is None or plan is None:
        return None
    abort = abort if abort is not None else show.on_abort
    motions = plan.motions_used() + ([abort] if abort is not None else [])
    return tuple((motion, show.duration_of(motion) or DEFAULT_MOTION_S) for motion in dict.fromkeys(motions))


def port_url(link: LinkSettings) -> str:
    """The port a link opens: a device or another URL as given; a `sim://` URL with what it
    leaves unsaid added from the settings (the show's durations unless it sets `durations` or
    `motion_s`, a baud and layout other than the defaults), then scaled to a replay's speed.

    `--port 'sim://?drop=5'` then still runs the show's motions for their expected lengths; a
    URL that says an option itself keeps its word (a sim with another layout than the run's
    shows what a wrong layout does: stray calls)."""
    if not is_simulator(link.given_port):
        return link.given_port
    given = simulator(link.given_port)
    added: dict[str, str] = {}
    if link.durations and not given.says("motion_s"):
        added["durations"] = durations_text(dict(link.durations))
    if link.baud != DEFAULT_BAUD:
        added["baud"] = str(link.baud)
    layout = link.board_layout or link.layout
    if layout is not SEED:
        added["layout"] = layout.name
    url = _scaled(given.unless_given(**added), link.speed)
    return link.given_port if url == given else str(url)


def at_speed(url: str, speed: float) -> str:
    """A `sim://` URL whose board runs `speed` times faster (see `_scaled`); any other port, or
    a URL the simulator would refuse (for the link to say what is wrong with it), as it is."""
    if speed == 1 or not is_simulator(url):
        return url
    try:
        given = SimUrl.parse(url)
    except ValueError:
        return url
    return str(_scaled(given, speed))


def _scaled(given: SimUrl, speed: float) -> SimUrl:
    """The board `speed` times faster: every slot's duration (`durations`), the default for
    the others (`motion_s`), the board's reply delay (`reply_ms`) and its status refresh
    (`refresh_ms`) divided by the speed, and, faster than 1, bytes that take no wire time.

    Without it a replay at speed 10 polls a motion ten times sooner after its start than the run
    did, finds it still executing where the run found it over, and `--strict` fails a clean log.
    The wire cannot run 10 times faster (the board has three bauds), and a 19-byte frame's
    1.7 ms at 115200 baud would be 17 ms of the run's time at speed 10: off is far closer to the
    run's timing than on. A URL that sets `wire` itself keeps it."""
    if speed == 1:
        return given
    options = given.options
    scaled = {"motion_s": f"{options.motion_s / speed:.9g}", "reply_ms": ms_text(options.reply_s / speed),
              "refresh_ms": ms_text(options.refresh_s / speed)}
    if options.durations:
        scaled["durations"] = durations_text({slot: seconds / speed for slot, seconds in options.durations.items()})
    faster = given.unless_given(wire="0") if speed > 1 else given
    return faster.with_text(**scaled)


def simulator(url: str) -> SimUrl:
    """A `sim://` URL's options; a bad one is exit 2 before anything opens, in `run`, `replay`
    and `choreo sim` alike, not a port that failed to open (exit 3)."""
    try:
        return SimUrl.parse(url)
    except ValueError as exc:
        raise UsageError(f"--port {url}: {exc}") from None


def _check_shared_ports(links: Mapping[str, LinkSettings]) -> None:
    """Two robots on one device, however each got its port (show, --port): refused before any
    port opens, not a lock error halfway through opening them."""
    seen: dict[str, LinkSettings] = {}
    for link in links.values():
        if is_simulator(link.given_port):
            continue
        first = seen.setdefault(same_port(link.given_port), link)
        if first is not link:
            raise UsageError(f"robot {link.robot}'s port {link.given_port} ({link.port_source}) is robot "
                             f"{first.robot}'s too ({first.port_source}): each robot needs its own port")


def _for_robot(name: str, show: Show, make: Callable[[], T]) -> T:
    """A usage error about one robot of several says which robot."""
    try:
        return make()
    except UsageError as exc:
        raise UsageError(f"robot {name}: {exc}") if show.ensemble else exc from None


ROBOT_PORT = re.compile(r"^([A-Za-z][A-Za-z0-9_-]{0,31})=(.*)$", re.S)


def _lone_robot(show: Show, host: str | None) -> str | None:
    """The one robot `--host` drives, if it drives one alone (a plain `--port URL` is its)."""
    robots = show.hosts.get(host, ()) if host is not None else ()
    return robots[0] if len(robots) == 1 else None


def split_robot_port(value: str) -> tuple[str, str] | None:
    """`--port left=/dev/ttyUSB0` -> ("left", "/dev/ttyUSB0"); a plain port (which may hold
    `=` itself, `sim://?drop=5`) -> None."""
    match = ROBOT_PORT.match(value)
    return (match.group(1), match.group(2)) if match else None


def _check_robot_ports(show: Show, request: RunRequest, host: str | None = None) -> None:
    """`--port URL` is for a one-robot show (or a host of one robot: `--host` drives it alone),
    `--port NAME=URL` for one of several (of this host's)."""
    if show.ensemble and request.port is not None and _lone_robot(show, host) is None:
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
        if host is not None and name not in show.hosts[host]:
            raise UsageError(f"--port {name}=...: robot {name} is driven by host {show.host_of(name)}, not by "
                             f"this run's (--host {host}: {', '.join(show.hosts[host])})")


def check_output_folder(path: Path, option: str) -> None:
    """An output given by name goes into a folder that exists: it is refused, never created (a
    typo would otherwise scatter files). Only the default log folder, runs/, is made."""
    folder = path.parent
    why = folder_problem(folder)
    if why is not None:
        raise UsageError(f"{option} {path}: cannot write: folder {folder} {why}")


def check_timeout(timeout: float) -> float:
    """A reply timeout a run can live with: a number of seconds, 0 < t <= 10."""
    if not math.isfinite(timeout) or not 0 < timeout <= MAX_TIMEOUT_S:
        raise UsageError(f"--timeout {timeout:g}: give the seconds to wait for a reply, "
                         f"more than 0 and at most {MAX_TIMEOUT_S:g}")
    return timeout


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


def _check_in_song(song: Song, origin: float, given: str) -> None:
    """In a music show, show time is the song's position: a start at or past its end would run
    the show in silence, on a clock that no longer moves with anything."""
    end = song.end_show_s
    if origin >= end - 1e-9:
        raise UsageError(f"{given}: it starts at {origin:.3f} s of show time, past the end of the music "
                         f"({song.path} ends at {max(end, 0.0):.3f} s): nothing would play; give an earlier "
                         "step, or --no-music to run on the machine's clock")


def given_layout(name: str) -> Layout:
    """The layout `--layout` names (UsageError, exit 2, for one this choreo does not know)."""
    try:
        return layout_named(name)
    except ValueError as exc:
        raise UsageError(f"--layout: {exc}") from None


def _layout(given: str | None, in_show: str | None) -> tuple[Layout, str]:
    """The run's layout and who chose it: `--layout`, the show's robot.layout, else seed."""
    if given is not None:
        return given_layout(given), "command line"
    if in_show is not None:
        return layout_named(in_show), "show"
    return SEED, "default"


def _pick(*values: T | None) -> T:
    """The first value given (the last is the default: always given)."""
    return next(v for v in values if v is not None)
