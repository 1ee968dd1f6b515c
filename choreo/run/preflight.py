"""`choreo doctor SHOW`: everything a show needs, checked before the doors open, without moving
a robot.

The show is settled as `choreo run` would settle it (the same `RunRequest`, so the same ports,
bauds and layouts), then each thing the run will need is checked on its own, so that one
problem does not hide the next: every robot's port opens and its board answers the read-only
probe (`choreo.board.probe`: nothing is written to the board) at the show's baud, with no motion
running and a program counter that does not contradict the show's layout; a real device's
permission and USB latency timer; the music opens as the run opens it (`Song.open`) and decodes
as far as the show needs it (its header's length is only a claim: a file cut short keeps the
whole one's) past the show's last cue; its output opens; the OSC port is free (the run's own
`OscServer.bind`, then closed) and its allow-list parses; the log's folder takes a file and has
room for what the recorder holds as it writes the plan's log (`log_estimate`: more than the
finished log, or the run stops on a full disk). On the Link clock the session is joined as the
run joins it (its quantum; a joiner takes the session's tempo), its peers waited for a moment,
and left: its tempo and transport against the show's proposal, and whether Link's discovery
(multicast) has a way out of this host; with `hosts:`, which robots this host drives.

A port that hangs (a driver stuck in open, a network port that never answers) cannot hang the
preflight: on the machine's time each robot's port is checked on a thread of its own and
whatever has not answered by `Machine.deadline_s` is a problem; so are a sound output that hangs
as it opens and a song that hangs as it decodes, and a Link check (always on the machine's time,
on a thread of its own beside the boards' probes) still at it after `Machine.link_deadline_s`.
On virtual time (the in-process simulator only, which cannot hang) the other checks run in turn,
deterministic.

What the checks read of the machine (the probe, the port's open, free space, the audio output)
comes in through `Machine`, so tests give them a machine of their own.
"""

from __future__ import annotations

import ipaddress
import math
import os
import shlex
import shutil
import socket
import sys
import tempfile
import threading
from functools import partial
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from choreo.board.doctor import NOTE, OK, PROBLEM, BoardWanted, Finding, audio_output, board_checks, device_checks
from choreo.board.probe import BoardInfo
from choreo.board.usb import LOW_LATENCY_MS, SYSFS
from choreo.clock import RunClock, TimeSource
from choreo.errors import ChoreoError, ShowError, UsageError
from choreo.log.format import CLOCK_EVERY_S, channels_for
from choreo.log.recorder import (BATCH, CHUNK_BOUND, CHUNK_BUDGET, CHUNK_SIZE, FLUSH_EVERY_S, IN_FLIGHT, MESSAGE_BUDGET,
                                 RESERVE_AHEAD, SUMMARY_SLACK, schema_text)
from choreo.run.runner import POLL_S
from choreo.run.settings import LinkSettings, RunRequest, RunSettings
from choreo.show.model import LINK, LinkClock, Plan, Show, StepKind, is_simulator
from choreo.show.read import MAX_BYTES
from choreo.show.report import format_path
from choreo.sync.session import DISCOVERY_MAX_S, INSTALL_HINT, LinkSession, LinkSnapshot
from choreo.userfile import folder_problem
from choreo.wire.protocol import BAUDS

if TYPE_CHECKING:  # the music loads when the show has some
    from choreo.music.player import Song

# Every port's checks together: a probe of a dead board tries 3 bauds, 2 ACK checks of 2 tries each,
# each try waiting the show's reply timeout, at most PROBE_TIMEOUT_S (12 s at worst; 2.4 s by default);
# a board that answers, then LINE_MISSES missed ACK checks of the line at most (3 s at worst).
PROBE_TIMEOUT_S = 1.0
PORT_DEADLINE_S = 15.0  # and for the music's output and decoding, each
DECODE_SPEED = 20  # seconds of song decoded a second at the least (mp3 on this machine: 500)
LINE_CHECKS = 20  # ACK checks that measure the line once the board answered (20 ms on a good line)
LINE_MISSES = 3  # stop at this many misses: each waits its timeout
T = TypeVar("T")
HEARD_SLACK_S = 0.05  # a decoded length this close to what was asked is all of it (resampling rounds)
# What a log costs in the file (MCAP, uncompressed), measured on the simulator's logs: a message
# is its JSON (a frame ~88 bytes, its reply ~84, a step ~170 and its label, a clock sample ~85,
# a command ~130) and 47 bytes of record header and index entry; the recorder closes a chunk
# every quarter second of a show that sends (~120 bytes and 25 a channel of indexes each); the
# schemas are written twice (in the first chunk and in the summary); header, metadata, channels
# and footer ~6 KiB. A hold or a pause adds next to nothing: the clock is sampled on show time.
FRAME_AND_REPLY_BYTES = 300
STEP_EVENT_BYTES = 240
CLOCK_SAMPLE_BYTES = 140
COMMAND_BYTES = 200  # a GO (and a sample of the clock forced as it releases the show)
CHUNK_BYTES = 120
CHUNK_CHANNEL_BYTES = 25
START_BYTES = 6 * 1024
MUSIC_FILE = format_path(("music", "file"))  # where a show's problem with its music file is
ROOM_MARGIN = 2  # less free space than twice the run's reserve is a note: little to spare for another writer
LINK_GROUP, LINK_PORT = "224.76.78.75", 20808  # where Link's peers discover each other (UDP multicast)
LINK_DEADLINE_S = 8.0  # the whole Link check: joining gives up at 5 s (session.OPEN_TIMEOUT_S)
ECHO_WAIT_S = 0.3  # this host's own multicast comes back in microseconds when it does at all
TEMPO_SAME = 0.01  # bpm: a session at the show's tempo, as Link rounds it
ROUTES = Path("/proc/net/route")  # Linux's main routing table
ROUTE_UP = 0x1  # RTF_UP


@dataclass(frozen=True)
class OscAsk:
    """The run's OSC options as given (`--osc`, `--osc-host`, `--osc-allow`, `--osc-notify`)."""

    port: str | None = None
    host: str = "127.0.0.1"
    allow: tuple[str, ...] = ()
    notify: tuple[str, ...] = ()


def _probe(url: str, bauds: Sequence[int], timeout: float, time_source: TimeSource | None) -> BoardInfo:
    from choreo.board.probe import probe

    return probe(url, bauds=bauds, timeout=timeout, time_source=time_source)


def _open(url: str, baud: int, timeout: float, time_source: TimeSource | None) -> None:
    from choreo.board.link import open_port

    open_port(url, baud, timeout=timeout, clock=RunClock(time_source) if time_source else None).close()


def _line(url: str, baud: int, timeout: float, time_source: TimeSource | None) -> tuple[int, int]:
    """ACK checks sent one by one without retry (the probe's own read-only frame), stopped at
    LINE_MISSES: (sent, unanswered or garbled)."""
    from choreo.board.link import Link
    from choreo.wire.protocol import ReplyKind, sync_frame

    link = Link.open(url, baud, timeout=timeout, tries=1, clock=RunClock(time_source) if time_source else None)
    sent = missed = 0
    try:
        while sent < LINE_CHECKS and missed < LINE_MISSES:
            sent += 1
            missed += link.send(sync_frame(), 1).kind is not ReplyKind.ACK
    finally:
        link.close()
    return sent, missed


def _audio(asked: str | None) -> str:
    from choreo.music.player import pick_output, try_output

    return try_output(pick_output(asked))


def _free(folder: Path) -> int:
    return shutil.disk_usage(folder).free


def _link_binding() -> str:
    """aalink's version (ImportError: not installed)."""
    import importlib.metadata

    import aalink  # noqa: F401 - imported to know it loads (a wheel for another Python does not)

    try:
        return importlib.metadata.version("aalink")
    except importlib.metadata.PackageNotFoundError:
        return "(version unknown)"


@dataclass(frozen=True)
class Machine:
    """What the checks read of the machine (tests give their own). `talk`: False leaves the
    boards alone (`--no-probe`): no port is opened."""

    time_source: TimeSource | None = None
    talk: bool = True
    probe: Callable[[str, Sequence[int], float, TimeSource | None], BoardInfo] = _probe
    open_port: Callable[[str, int, float, TimeSource | None], None] = _open
    line: Callable[[str, int, float, TimeSource | None], tuple[int, int]] = _line
    audio: Callable[[str | None], str] = _audio
    free_bytes: Callable[[Path], int] = _free
    sysfs: Path = SYSFS
    deadline_s: float = PORT_DEADLINE_S
    link_binding: Callable[[], str] = _link_binding
    multicast: Callable[[], Multicast] = lambda: _multicast_path()
    link_wait_s: float = DISCOVERY_MAX_S  # the longest wait for a Link session's peers (a run's discovery is less)
    link_deadline_s: float = LINK_DEADLINE_S

    @property
    def virtual(self) -> bool:
        return self.time_source is not None and self.time_source.virtual


@dataclass(frozen=True)
class LogEstimate:
    """What the plan will log: its records, the file's size, and the disk space the recorder
    holds at most as it writes (`room`: the log so far, the chunk being built, what a stopping
    run still reports and the summary; a disk without it stops the run, `choreo.log.recorder`)."""

    frames: int  # frames sent, each with its reply
    step_events: int
    clock_samples: int
    bytes: int
    room: int

    def text(self) -> str:
        return (f"about {size(self.bytes)} ({self.frames} frames and replies, {self.step_events} step events, "
                f"{self.clock_samples} clock samples); the run holds up to {size(self.room)} as it writes")


@dataclass(frozen=True)
class Preflight:
    """Every check's finding, in the order a user fixes things, and the log's estimate."""

    show: str
    findings: tuple[Finding, ...]
    log: LogEstimate | None = None

    @property
    def exit_code(self) -> int:
        """1 if anything would stop the show (notes do not)."""
        return 1 if any(f.level == PROBLEM for f in self.findings) else 0


def preflight(request: RunRequest, osc: OscAsk = OscAsk(), machine: Machine = Machine()) -> Preflight:
    """Check everything the show `request` names needs (see the module's docstring)."""
    settings, findings = _settle(request)
    estimate = None
    if settings is not None:
        estimate = run_log_estimate(settings)
        link = _link_started(settings, machine) if settings.link is not None else None
        findings += _host(settings)
        findings += _robots(settings, machine)
        findings += link() if link is not None else []
        if not any(f.check == "music" for f in findings):  # a music file not found is said already
            findings += _music(settings, request, machine)
    findings += _osc(osc, settings)
    findings += _log(request, estimate, machine)
    return Preflight(request.show_path, tuple(findings), estimate)


def _settle(request: RunRequest) -> tuple[RunSettings | None, list[Finding]]:
    """The show as `run` settles it, less what the other checks look at (the music, the log).
    A show whose only problem is its music file is the music's problem: the show is settled
    without looking for the file, so the robots are still checked."""
    # on the Link clock (--clock link) the music is refused unless --no-music: left to the run's own refusal
    no_music = request.no_music if request.clock == LINK else True
    asked = replace(request, no_music=no_music, no_log=True, log_path=None, audio_device=None)
    music: list[Finding] = []
    try:
        settings = RunSettings.settle(asked)
    except ShowError as exc:
        if not exc.problems or any(p.path != MUSIC_FILE for p in exc.problems):
            return None, [_unloaded(exc, request)]
        music = [Finding(PROBLEM, "music", exc.lines()[0], "music.file in the show: a wav, mp3, flac or ogg "
                         "file, its path relative to the show file")]
        try:
            settings = RunSettings.settle(asked, loaded=_without_music_check(request.show_path))
        except ChoreoError as again:
            return None, [_unloaded(again, request)]
    except ChoreoError as exc:
        return None, [_unloaded(exc, request)]
    steps = sum(len(plan.steps) for plan in settings.plans.values())
    longest = max(plan.estimated_s for plan in settings.plans.values())
    robots = f"{len(settings.links)} robot{'s' if len(settings.links) > 1 else ''}"
    shown = Finding(OK, "show", f"{settings.show.name!r} loads: {robots}, {steps} steps, about {longest:.1f} s")
    return settings, [shown, *music]


def _unloaded(exc: ChoreoError, request: RunRequest) -> Finding:
    lines = exc.lines()
    more = f" (and {len(lines) - 1} more)" if len(lines) > 1 else ""
    if isinstance(exc, ShowError) and all(p.line == 0 and not p.path for p in exc.problems):  # no file to read
        fix = "the path of the show's YAML file"
    elif isinstance(exc, ShowError):
        fix = f"choreo validate {shlex.quote(request.show_path)} lists every problem"
    else:
        fix = "change the option or the show as the message says"
    return Finding(PROBLEM, "show", lines[0] + more, fix)


def _without_music_check(path: str) -> Show:
    """The show, its music file not looked for (as a show attached to a log is loaded)."""
    from choreo.show.load import load_show_bytes
    from choreo.userfile import read_input

    return load_show_bytes(read_input(Path(path), "show file", MAX_BYTES), path, folder=None)


# --------------------------------------------------------------------------- robots


def _robots(settings: RunSettings, machine: Machine) -> list[Finding]:
    """Each robot's device (a real one's permission and latency timer), its port and board."""
    ensemble = settings.show.ensemble
    found: list[Finding] = []
    talk: list[LinkSettings] = []
    for link in settings.links.values():
        robot = link.robot if ensemble else None
        device = [] if _is_url(link.port) else device_checks(link.port, machine.sysfs)
        device = [_in_show(replace(f, robot=robot)) for f in device]
        found += device
        if machine.talk and not any(f.check == "device" for f in device):  # a device that is not there
            talk.append(link)
    if not machine.talk:
        found.append(Finding(NOTE, "board", "not probed (--no-probe): no port was opened"))
    results = _each(talk, lambda link: _board(link, machine, ensemble), machine)
    return found + [replace(f, robot=f.robot if ensemble else None) for link in talk for f in results[link.robot]]


def _in_show(finding: Finding) -> Finding:
    """A slow latency timer does not stop a show: the run asks the driver for low latency as it
    opens the port (and says so if the timer stays slow), so it is a note here."""
    if finding.check != "latency" or finding.level != PROBLEM:
        return finding
    return replace(finding, level=NOTE, text=f"{finding.text}; choreo run asks the driver for "
                   f"{LOW_LATENCY_MS} ms as it opens the port, and says so if the timer stays above")


def _is_url(port: str) -> bool:
    return is_simulator(port) or "://" in port


def _board(link: LinkSettings, machine: Machine, ensemble: bool) -> list[Finding]:
    """The port opens at the show's baud; the board answers the probe (the show's baud first).
    What the port's errors say is said of the port as the user named it (`given_port`), not of
    the URL the run derives from it (a simulator's with the show's durations and layout)."""
    robot = link.robot if ensemble else None
    port = shlex.quote(link.given_port)
    try:
        machine.open_port(link.port, link.baud, link.timeout, machine.time_source)
    except ChoreoError as exc:
        return [Finding(PROBLEM, "port", _named(exc, link), "choreo ports lists the serial ports; check the "
                        "cable and that no other program holds the port", robot)]
    found = [Finding(OK, "port", f"{link.given_port} opens at {link.baud} baud", None, robot)]
    if is_simulator(link.port):  # all clear on the simulator says nothing of the robot on the night
        found.append(Finding(NOTE, "simulator", f"{link.given_port} is choreo's simulator: no robot moves on it",
                             "give the robot's port (--port, or `port:` in the show); choreo ports lists them",
                             robot))
    bauds = (link.baud, *(b for b in BAUDS if b != link.baud))
    try:
        info = machine.probe(link.port, bauds, min(link.timeout, PROBE_TIMEOUT_S), machine.time_source)
    except ChoreoError as exc:
        return found + [Finding(PROBLEM, "board", _named(exc, link), f"choreo probe --port {port} says more; "
                                "check the board's power, the cable and its baud", robot)]
    info = replace(info, notes=[note.replace(link.port, link.given_port) for note in info.notes])
    wanted = BoardWanted(link.given_port, link.baud, link.layout, link.layout_source == "default", robot)
    checked = found + board_checks(info, wanted)
    return checked + [_line_check(link, machine, robot)] if info.baud == link.baud else checked


def _line_check(link: LinkSettings, machine: Machine, robot: str | None) -> Finding:
    """A board that answers the probe's few questions may still sit on a line that loses or
    garbles one frame in a few (a loose cable, a noisy adapter): the run retries a frame, then
    stops. LINE_CHECKS ACK checks, none retried, tell: LINE_MISSES lost is a problem (a line that
    loses one frame in a few loses a frame's every try in a show), fewer a note."""
    fix = ("check the cable and the adapter, and that no other program talks on the port; then "
           f"choreo probe --port {shlex.quote(link.given_port)}")
    try:
        sent, missed = machine.line(link.port, link.baud, min(link.timeout, PROBE_TIMEOUT_S), machine.time_source)
    except ChoreoError as exc:
        return Finding(PROBLEM, "line", _named(exc, link), fix, robot)
    said = f"{missed} of {sent} ACK checks at {link.baud} baud went unanswered or garbled"
    if missed >= LINE_MISSES:
        return Finding(PROBLEM, "line", f"{said}: the run tries a frame {link.tries} times, then stops", fix, robot)
    if missed:
        return Finding(NOTE, "line", f"{said}: the run's retries cover a frame lost now and then, but a good "
                       "line loses none", fix, robot)
    return Finding(OK, "line", f"{sent} ACK checks at {link.baud} baud, every one answered", None, robot)


def _named(exc: ChoreoError, link: LinkSettings) -> str:
    return exc.lines()[0].replace(link.port, link.given_port) if link.port else exc.lines()[0]


def _each(links: list[LinkSettings], check: Callable[[LinkSettings], list[Finding]],
          machine: Machine) -> dict[str, list[Finding]]:
    """`check` for every link: in turn on virtual time; else each on a thread of its own, and a
    link still at it after `machine.deadline_s` is a problem (its thread is left behind: a
    daemon, holding only its port)."""
    if machine.virtual:
        return {link.robot: _guarded(check, link) for link in links}
    waits = {link.robot: _on_thread(partial(_guarded, check, link), f"doctor {link.robot}") for link in links}
    end = time.monotonic() + machine.deadline_s
    found: dict[str, list[Finding]] = {}
    for link in links:
        try:
            found[link.robot] = waits[link.robot](max(0.0, end - time.monotonic()))
        except Exception:  # noqa: BLE001 - no answer in time, or a check that died unforeseen: as before, no answer
            found[link.robot] = [_hung(link, machine)]
    return found


def _guarded(check: Callable[[LinkSettings], list[Finding]], link: LinkSettings) -> list[Finding]:
    """A check that fails in a way nobody foresaw (an OSError from a driver) is one finding."""
    try:
        return check(link)
    except (OSError, ValueError) as exc:
        return [Finding(PROBLEM, "port", f"{link.given_port}: {exc}", "choreo probe --port "
                        f"{shlex.quote(link.given_port)} says more", link.robot)]


def _hung(link: LinkSettings, machine: Machine) -> Finding:
    return Finding(PROBLEM, "port", f"{link.given_port}: no answer within {machine.deadline_s:g} s (the port "
                   "or its driver hangs)", "unplug the adapter and plug it in again; then choreo probe --port "
                   f"{shlex.quote(link.given_port)}", link.robot)


# --------------------------------------------------------------------------- Link


def _host(settings: RunSettings) -> list[Finding]:
    """A show for several hosts: which robots this host (--host) drives, and who drives the rest."""
    if settings.host is None:
        return []
    others = [f"{name}: {', '.join(robots)}" for name, robots in settings.show.hosts.items() if name != settings.host]
    return [Finding(OK, "host", f"this computer is host {settings.host}: it drives {', '.join(settings.links)}; "
                    f"the others drive theirs ({'; '.join(others) or 'none'})")]


@dataclass(frozen=True)
class Multicast:
    """Whether Link's discovery can leave and reach this host: the interface the kernel routes
    Link's group through (None: no route; `why` says so), and this host hearing its own
    multicast on it (`echo`: None if heard, else why not)."""

    interface: str | None
    address: str | None
    why: str | None
    echo: str | None

    @property
    def loopback(self) -> bool:
        return self.interface in ("lo", "lo0") or (self.address or "").startswith("127.")

    def where(self) -> str:
        named = [part for part in (self.interface, self.address) if part and part != "0.0.0.0"]
        return f"{named[0]} ({named[1]})" if len(named) == 2 else named[0] if named else "an interface"


@dataclass(frozen=True)
class LinkSeen:
    """What the Link check saw: aalink's version (None: not installed), the session as joined
    and how long its peers took to show (`snapshot` None: not joined, `failure` says why), and
    the multicast path."""

    version: str | None
    snapshot: LinkSnapshot | None = None
    waited_s: float = 0.0
    failure: str | None = None
    multicast: Multicast | None = None


def _link_started(settings: RunSettings, machine: Machine) -> Callable[[], list[Finding]]:
    """The Link check, started now on a thread of its own (its discovery wait overlaps the boards'
    probes); the returned call gives its findings, the check's thread abandoned at its deadline
    (Link in a wedged network stack, a binding that hangs: doctor never does)."""
    assert settings.link is not None
    clock = settings.link
    wait = _on_thread(lambda: _look(clock, machine), "doctor link")

    def findings() -> list[Finding]:
        try:
            seen = wait(machine.link_deadline_s)
        except _NoAnswer:
            return [Finding(PROBLEM, "link session", f"no answer from the Link session within "
                            f"{machine.link_deadline_s:g} s (the binding or the network stack hangs)",
                            "choreo doctor SHOW again; if it hangs again, reinstall aalink: "
                            f"{INSTALL_HINT}")]
        except Exception as exc:  # noqa: BLE001 - a check failing in a way nobody foresaw is one finding
            seen = LinkSeen("", failure=f"{type(exc).__name__}: {exc}")
        return _link_findings(settings, seen)
    return findings


def _look(clock: LinkClock, machine: Machine) -> LinkSeen:
    """Join the session as the run would (its quantum, its tempo proposed to nobody: a joiner
    takes the session's), wait for peers up to `machine.link_wait_s`, leave; and the multicast path."""
    try:
        version = machine.link_binding()
    except ImportError:
        return LinkSeen(None)
    multicast = machine.multicast()
    start = time.monotonic()
    try:
        session = LinkSession(clock.meter, clock.bpm).open()
    except ChoreoError as exc:
        return LinkSeen(version, failure=exc.lines()[0], multicast=multicast)
    try:
        # the peers found as a run finds them before it decides how to start (LinkSession.discover)
        found = session.discover(stop=lambda: time.monotonic() - start >= machine.link_wait_s)
        return LinkSeen(version, found, time.monotonic() - start, multicast=multicast)
    finally:
        session.close()


def _link_findings(settings: RunSettings, seen: LinkSeen) -> list[Finding]:
    """The binding, the session joined and its peers, its tempo against the show's, the multicast path."""
    if seen.version is None:
        return [Finding(PROBLEM, "link", "the show runs on the Ableton Link clock and the aalink package (its "
                        "binding) is not installed", INSTALL_HINT)]
    found = [Finding(OK, "link", f"aalink {seen.version} (Ableton Link) is installed")] if seen.version else []
    if seen.snapshot is None:
        return found + [Finding(PROBLEM, "link session", f"could not join: {seen.failure}",
                                f"reinstall the binding ({INSTALL_HINT}); check that UDP sockets can be opened")]
    snapshot = seen.snapshot
    assert settings.link is not None
    return [*found, _peers(settings, snapshot, seen.waited_s), _tempo(settings.link, snapshot),
            *([_multicast(seen.multicast, snapshot.peers)] if seen.multicast is not None else [])]


def _peers(settings: RunSettings, snapshot: LinkSnapshot, waited_s: float) -> Finding:
    assert settings.link is not None
    joined = f"joined (a bar is {settings.link.meter} beats)"
    if snapshot.peers:
        plural = "s" if snapshot.peers > 1 else ""
        return Finding(OK, "link session", f"{joined}: {snapshot.peers} peer{plural}, seen after {waited_s:.2f} s")
    if settings.host is not None:
        others = ", ".join(host for host in settings.show.hosts if host != settings.host)
        alone = (f"no other host ({others}) is in the session yet: this host would wait for the session's start "
                 "(a peer's, another host's, or its own)")
    else:
        alone = "this host would start the session alone, as its first peer"
    return Finding(NOTE, "link session", f"{joined}: no peer within {waited_s:.1f} s: {alone}",
                   f"other hosts and apps must be on this host's subnet with multicast allowed (UDP {LINK_PORT})")


def _tempo(clock: LinkClock, snapshot: LinkSnapshot) -> Finding:
    """The session's tempo and transport against the tempo the show proposes (when this host
    starts the transport: a show joining a session that plays keeps the session's tempo)."""
    transport = "its transport plays" if snapshot.playing else "its transport is stopped"
    said = f"the session's tempo is {snapshot.tempo:.2f} bpm, {transport}"
    if not snapshot.peers and not snapshot.playing:  # the session is this host's own
        taken = "the show's" if clock.bpm is not None else "Link's default: the show takes the session's"
        return Finding(OK, "link tempo", f"alone, this host would start the session at {snapshot.tempo:.2f} bpm "
                       f"({taken})")
    if clock.bpm is None:
        return Finding(OK, "link tempo", f"{said}; the show takes the session's tempo")
    if abs(clock.bpm - snapshot.tempo) < TEMPO_SAME:
        return Finding(OK, "link tempo", f"{said}, as the show proposes")
    if snapshot.playing:
        return Finding(NOTE, "link tempo", f"{said}; the show proposes {clock.bpm:g} bpm, but a show joining a "
                       f"session that plays keeps its tempo: its bars and beats at {snapshot.tempo:.2f} bpm",
                       f"set the session's tempo to {clock.bpm:g} bpm (Live's tempo field), or tempo: {{bpm: link}}")
    return Finding(NOTE, "link tempo", f"{said}; the show proposes {clock.bpm:g} bpm: this host's start moves "
                   f"every peer to {clock.bpm:g} bpm", "tempo: {bpm: link} in the show keeps the session's tempo")


def _multicast(multicast: Multicast, peers: int) -> Finding:
    """Whether Link's discovery (multicast to LINK_GROUP) leaves this host. Peers found say it
    does; with none, a missing route, a silent echo or the loopback only say why none may come."""
    group = f"{LINK_GROUP}:{LINK_PORT}"
    if peers:
        return Finding(OK, "multicast", f"Link's discovery ({group}) reaches {peers} peer{'s' if peers > 1 else ''}"
                       + (f", through {multicast.where()}" if multicast.interface or multicast.address else ""))
    fix = f"a route for multicast on the stage network's interface (Linux: ip route add 224.0.0.0/4 dev IFACE); " \
          f"a firewall letting UDP {LINK_PORT} in and out"
    if multicast.why is not None:
        return Finding(NOTE, "multicast", f"this host has no route for Link's discovery ({group}: "
                       f"{multicast.why}): peers on other computers may not find this one", fix)
    if multicast.echo is not None:
        return Finding(NOTE, "multicast", f"{group} goes out through {multicast.where()}, but this host does not hear "
                       f"its own multicast there: {multicast.echo}", fix)
    if multicast.loopback:
        return Finding(NOTE, "multicast", f"{group} goes out through {multicast.where()}, the loopback: only peers "
                       "on this computer can be found", fix)
    return Finding(OK, "multicast", f"{group} goes out through {multicast.where()}, and this host hears its own "
                   "multicast there (no peer answered: see link session)")


def _multicast_path() -> Multicast:
    """The kernel's route for Link's group (a UDP connect sends nothing), then one datagram to
    the group on a port of this host's own with a TTL of 0 (never leaves the host), heard back."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect((LINK_GROUP, LINK_PORT))
            address = probe.getsockname()[0]
    except OSError as exc:
        return Multicast(_route_interface(LINK_GROUP), None, exc.strerror or str(exc), None)
    return Multicast(_route_interface(LINK_GROUP), address, None, _echo(address))


def _echo(address: str) -> str | None:
    """None if a datagram to LINK_GROUP comes back to this host, else why not."""
    token = os.urandom(8)
    group = socket.inet_aton(LINK_GROUP)
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as ear, \
                socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as mouth:
            ear.bind(("", 0))
            ear.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, group + socket.inet_aton(address))
            mouth.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
            mouth.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            mouth.sendto(token, (LINK_GROUP, ear.getsockname()[1]))
            ear.settimeout(ECHO_WAIT_S)
            for _ in range(8):  # another program's datagram to the same port is not ours
                if ear.recv(64) == token:
                    return None
            return "only others' datagrams came back"
    except TimeoutError:
        return f"nothing came back within {ECHO_WAIT_S:g} s"
    except OSError as exc:
        return exc.strerror or str(exc)


def _route_interface(address: str, table: Path = ROUTES) -> str | None:
    """The interface Linux routes `address` through (the longest prefix, then the lowest
    metric, in the main table); None where there is no such table (macOS, Windows) or no route."""
    try:
        rows = [line.split() for line in table.read_text(errors="replace").splitlines()[1:]]
    except OSError:
        return None
    target = int.from_bytes(socket.inet_aton(address), sys.byteorder)
    best: tuple[tuple[int, int], str] | None = None
    for row in rows:
        try:
            name, destination, flags = row[0], int(row[1], 16), int(row[3], 16)
            metric, mask = int(row[6]), int(row[7], 16)
        except (IndexError, ValueError):
            continue
        rank = (bin(mask).count("1"), -metric)
        if flags & ROUTE_UP and target & mask == destination and (best is None or rank > best[0]):
            best = (rank, name)
    return best[1] if best is not None else None


# --------------------------------------------------------------------------- music


def _music(settings: RunSettings, request: RunRequest, machine: Machine) -> list[Finding]:
    """The song decodes and lasts past the last cue; its output opens."""
    show = settings.show
    if show.music is None:
        if request.audio_device is None:
            return []
        return [Finding(PROBLEM, "audio", f"--audio-device {request.audio_device}: the show has no `music:` to "
                        "play (the run refuses it)", "leave out --audio-device")]
    if request.no_music:
        return [Finding(NOTE, "music", "not played (--no-music): the machine's clock keeps time")]
    from choreo.music.player import Song

    try:
        song = Song.open(show.music, show.path)
    except ChoreoError as exc:
        return [Finding(PROBLEM, "music", exc.lines()[0], "music.file in the show: a wav, mp3, flac or ogg "
                        "file next to it (choreo beats SONG decodes it too)")]
    try:
        end, said, cut = _heard(settings, song, machine)
    except ChoreoError as exc:
        return [Finding(PROBLEM, "music", f"{song.path}: {exc.lines()[0]}", "a sound file that decodes to its "
                        "end (choreo beats SONG decodes it too)")]
    return [_song_length(settings, end, said, cut),
            audio_output(lambda: _in_time(lambda: machine.audio(request.audio_device), machine.deadline_s, machine,
                                          "the sound system hangs"), request.audio_device)]


def _heard(settings: RunSettings, song: Song, machine: Machine) -> tuple[float, str, bool]:
    """Where the song really ends in show time, how to say so, and whether it was cut short: its
    header's length is only a claim (a file cut short keeps the header of the whole), so the
    song is decoded as far as the show needs it (a second past its end), no further."""
    start = song.music.start
    needed = max(plan.estimated_s for plan in settings.plans.values()) + start + 1.0
    until = min(song.duration_s, needed)
    seconds = machine.deadline_s + until / DECODE_SPEED  # a long song on a slow machine is no hang
    heard = _in_time(lambda: _decoded_s(song.path, song.sample_rate, until), seconds, machine, "decoding hangs")
    if heard >= until - HEARD_SLACK_S:
        return song.end_show_s, f"{song.path} decodes", False
    return heard - start, (f"{song.path} decodes only to {heard:.3f} s of its {song.duration_s:.3f} s (cut short "
                           "or damaged)"), True


def _decoded_s(path: str, rate: int, until_s: float) -> float:
    """Seconds of the file that decode, reading no further than `until_s`."""
    import miniaudio

    wanted = math.ceil(until_s * rate)
    frames = 0
    try:
        for block in miniaudio.stream_file(path, output_format=miniaudio.SampleFormat.SIGNED16, nchannels=1,
                                           sample_rate=rate, frames_to_read=rate):
            frames += len(block)
            if frames >= wanted:
                break
    except (miniaudio.DecodeError, OSError) as exc:
        raise ChoreoError(f"stops decoding after {frames / rate:.3f} s ({exc})") from None
    return frames / rate


def _in_time(call: Callable[[], T], seconds: float, machine: Machine, hangs: str) -> T:
    """`call` on a thread of its own on the machine's time: a sound system that hangs as an
    output opens (or a file that hangs as it decodes) is a ChoreoError after `seconds` (its
    thread is left behind); `hangs` says what then."""
    if machine.virtual:
        return call()
    try:
        return _on_thread(call, "doctor music")(seconds)
    except _NoAnswer:
        raise ChoreoError(f"no answer within {seconds:g} s ({hangs})") from None


class _NoAnswer(Exception):
    """A check on a thread of its own did not answer in time."""


def _on_thread(call: Callable[[], T], name: str) -> Callable[[float], T]:
    """`call` started now on a thread of its own; the returned wait gives its result within the
    seconds given it, its exception raised on the waiting thread, or _NoAnswer (the thread left
    behind: a check that hangs never hangs doctor)."""
    done: list[T] = []
    failed: list[BaseException] = []

    def work() -> None:
        try:
            done.append(call())
        except BaseException as exc:  # noqa: BLE001 - handed to the waiting thread, raised there
            failed.append(exc)

    thread = threading.Thread(target=work, daemon=True, name=name)
    thread.start()

    def wait(seconds: float) -> T:
        thread.join(seconds)
        if failed:
            raise failed[0]
        if not done:
            raise _NoAnswer
        return done[0]
    return wait


def _song_length(settings: RunSettings, end: float, decodes: str, cut: bool = False) -> Finding:
    last = last_cue(settings.plans)
    show_end = max(plan.estimated_s for plan in settings.plans.values())
    origin = settings.sections.origin
    said = f"{decodes}; it ends at {max(end, 0.0):.3f} s of show time"
    if origin >= end - 1e-9:
        return Finding(PROBLEM, "music", f"{said}: the run starts at {origin:.3f} s, past its end",
                       "an earlier --from or --loop, or --no-music")
    if last is not None and last[1] > end:
        fix = ("the whole file again (a copy that decodes to its end)" if cut
               else f"a longer music file, or move the cues before {end:.3f} s")
        return Finding(PROBLEM, "music", f"{said}, before {last[0]} at {last[1]:.3f} s: that cue and the ones "
                       "after it would play in silence", fix)
    cue = f", after the last cue ({last[0]} at {last[1]:.3f} s)" if last is not None else ""
    if show_end > end:
        return Finding(NOTE, "music", f"{said}{cue}; the show's last motions run on to {show_end:.3f} s, in silence")
    return Finding(OK, "music", f"{said}{cue}; the show ends at {show_end:.3f} s")


def last_cue(plans: Mapping[str, Plan]) -> tuple[str, float] | None:
    """The cue planned latest (its name, its show time): what the music must outlast."""
    cued = [(step.planned_s, step) for plan in plans.values() for step in plan.steps
            if step.at is not None or step.go]
    if not cued:
        return None
    planned, step = max(cued, key=lambda pair: pair[0])
    name = f"cue {step.cue}" if step.cue else f"step {step.name}"
    return name + (f" {step.label!r}" if step.label and step.cue else ""), planned


# --------------------------------------------------------------------------- OSC


def _osc(osc: OscAsk, settings: RunSettings | None) -> list[Finding]:
    """The OSC port binds (UDP and TCP, as the run binds it; closed at once) and the options
    parse; without --osc, a show with GO cues needs the console to give them."""
    if osc.port is None:
        given = [name for name, value in (("--osc-allow", osc.allow), ("--osc-notify", osc.notify),
                                          ("--osc-host", osc.host != "127.0.0.1")) if value]
        if given:
            return [Finding(PROBLEM, "osc", f"{given[0]} is for OSC, and no --osc PORT is given", "give --osc PORT")]
        if settings is not None and has_go_cues(settings.plans):
            return [Finding(NOTE, "osc", "no --osc: the show's GO cues come from the console only",
                            "run on a terminal (the console), or give --osc PORT")]
        return []
    try:
        server = _bound(osc)
    except UsageError as exc:
        return [_osc_problem(exc.lines()[0])]
    allowed = f"; allows {', '.join(osc.allow)}" if osc.allow else "; this machine only"
    said = f"udp and tcp port {server} on {osc.host} are free{allowed}"
    if osc.port.strip() == "0":
        return [Finding(NOTE, "osc", f"--osc 0: the run listens on a port the system picks as it starts ({server} "
                        "now): QLab cannot be told it beforehand", "a fixed port, e.g. --osc 53200")]
    if osc.allow and _loopback(osc.host):
        return [Finding(NOTE, "osc", f"{said}, but {osc.host} is reachable from this machine only",
                        "--osc-host 0.0.0.0 (or this machine's address on the stage network)")]
    return [Finding(OK, "osc", said)]


def _osc_problem(said: str) -> Finding:
    """What the run would refuse, with the fix for its cause: the allow-list, a target, the port
    number, a port in use, or an address this machine cannot listen on."""
    if said.startswith("--osc-allow"):
        return Finding(PROBLEM, "osc-allow", said, "an IP address or network, as 192.168.1.20 or 192.168.1.0/24")
    if said.startswith("--osc-notify"):
        return Finding(PROBLEM, "osc-notify", said, "HOST:PORT where a program listens for choreo's progress, "
                       "e.g. 127.0.0.1:53001")
    if "give a port number" in said:
        return Finding(PROBLEM, "osc", said, "--osc with a number, e.g. 53200 (QLab itself listens on 53000)")
    if "another program listens there" in said:
        return Finding(PROBLEM, "osc", said, "another --osc port (QLab itself listens on 53000; e.g. 53200), "
                       "or stop what holds it")
    return Finding(PROBLEM, "osc", said, "--osc-host with an address of this machine (127.0.0.1; 0.0.0.0: every "
                   "network) and a port from 1024 up")


def _loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return host.strip().lower() == "localhost"


def has_go_cues(plans: Mapping[str, Plan]) -> bool:
    return any(step.go for plan in plans.values() for step in plan.steps)


def _bound(osc: OscAsk) -> int | None:
    """Bind as the run does, then close: the port the run would get (UsageError if none)."""
    from choreo.events import StopRequest
    from choreo.live.controls import Live
    from choreo.live.osc import OscServer, parse_allow
    from choreo.live.oscnotify import parse_targets, port_number

    port = None if osc.port is None else port_number(osc.port, lowest=0)
    if port is None:
        raise UsageError(f"--osc {osc.port}: give a port number, 1..65535 (0: any free port)")
    if not osc.host.strip():
        raise UsageError("--osc-host '': give the address to listen on (127.0.0.1, 0.0.0.0, ::)")
    parse_allow(osc.allow)
    live = Live(StopRequest())
    server = OscServer(live, port, host=osc.host, allow=osc.allow, notify=parse_targets(osc.notify))
    try:
        server.bind()
        return server.port
    finally:
        server.close()
        live.close()


# --------------------------------------------------------------------------- the log


def run_log_estimate(settings: RunSettings) -> LogEstimate:
    """The log of the run `settings` describe (its plans, its show file, its robots' topics)."""
    robots = tuple(settings.links) if settings.show.ensemble else ()
    return log_estimate(settings.plans, len(settings.show.source), robots)


def log_estimate(plans: Mapping[str, Plan], source_bytes: int = 0, robots: tuple[str, ...] = ()) -> LogEstimate:
    """What a run of `plans` will log: each frame with its reply (a `wait: done` polls every
    POLL_S for the motion's expected rest, and once more), each step's start and end, a clock
    sample every CLOCK_EVERY_S of the show and one at each GO, each GO's command. `robots`: a
    show for several names them (each has topics, so schemas, of its own)."""
    frames = events = gos = labels = 0
    longest = 0.0
    for plan in plans.values():
        longest = max(longest, plan.estimated_s)
        for step in plan.steps:
            if not step.is_for(plan.robot):
                continue
            events += 2
            labels += 2 * len(step.label or "")
            gos += 1 if step.go else 0
            polls = math.ceil(step.expected_s / POLL_S) + 1 if step.kind is StepKind.WAIT_DONE else 1
            frames += len(step.frames) * polls if step.kind is not StepKind.WAIT else 0
        frames += 4  # opening the port (an ACK check, a config read) and its close
    samples = math.ceil(longest / CLOCK_EVERY_S) + 2 + gos
    topics = channels_for(robots)
    schemas = sum(len(schema_text(filename)) for _, filename in topics.values())
    records = (frames * FRAME_AND_REPLY_BYTES + events * STEP_EVENT_BYTES + labels + samples * CLOCK_SAMPLE_BYTES
               + gos * COMMAND_BYTES)
    chunks = math.ceil(longest / (FLUSH_EVERY_S / 2)) + records // CHUNK_SIZE + 2
    indexes = chunks * (CHUNK_BYTES + CHUNK_CHANNEL_BYTES * len(topics))
    total = START_BYTES + 2 * schemas + source_bytes + records + indexes
    return LogEstimate(frames, events, samples, total, total + _reserve_tail(schemas, chunks, total))


def _reserve_tail(schemas: int, chunks: int, written: int) -> int:
    """What the recorder keeps reserved past the log's end at most (its `_tail_bytes`, a batch of
    messages not yet written, the least it grows by) and a file system block to round up to."""
    tail = (CHUNK_BOUND + IN_FLIGHT * MESSAGE_BUDGET + schemas + SUMMARY_SLACK
            + CHUNK_BUDGET * (chunks + written // CHUNK_SIZE + 2))
    return tail + BATCH * MESSAGE_BUDGET + RESERVE_AHEAD // 16 + 4096


def _log(request: RunRequest, estimate: LogEstimate | None, machine: Machine) -> list[Finding]:
    """The log's folder takes a file, and has room for the log."""
    if request.no_log:
        return [Finding(NOTE, "log", "off (--no-log): nothing of the show is recorded")]
    named = bool(request.log_path)  # as the run takes it: `--log ''` is the default name
    folder = Path(request.log_path).parent if request.log_path else Path(request.log_dir)
    writable = _writable(folder, named)
    taken = _taken(str(request.log_path)) if named and writable.level != PROBLEM else None
    if writable.level == PROBLEM or taken is not None:
        return [taken or writable]
    room = _room(folder, estimate, machine)
    if request.loop is not None and estimate is not None:  # a rehearsal loops until stopped
        room = replace(room, text=f"{room.text}; --loop logs until stopped: each pass adds at most as much")
    return [writable, room]


def _taken(path: str) -> Finding | None:
    """Why the run could not create the log `path`: a file there already (a dangling link too:
    the run creates it exclusively), or a name the system refuses (too long)."""
    fix = "give another --log path, or leave --log out"
    try:
        os.lstat(path)
    except FileNotFoundError:
        return None
    except OSError as exc:
        return Finding(PROBLEM, "log", f"--log {path}: {exc.strerror or exc}", fix)
    return Finding(PROBLEM, "log", f"{path} exists already: choreo never overwrites a log", fix)


def _writable(folder: Path, named: bool) -> Finding:
    """A file can be made in `folder` (made and removed at once); the default folder, which
    the run creates, need not exist: its nearest existing parent must take it."""
    fix = "give --log PATH in a folder you can write, or free the folder"
    try:
        if folder.is_dir():
            handle, name = tempfile.mkstemp(prefix=".choreo-doctor-", dir=folder)
            os.close(handle)
            os.unlink(name)
            return Finding(OK, "log", f"folder {folder} takes a new file")
        why = folder_problem(folder)
        if why is not None and (named or os.path.lexists(folder)):
            return Finding(PROBLEM, "log", f"folder {folder} {why}", fix)
        parent = _existing_parent(folder)
        if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
            return Finding(PROBLEM, "log", f"folder {folder} cannot be made: {parent} is "
                           f"{'not a folder' if not parent.is_dir() else 'not writable'}", fix)
        return Finding(OK, "log", f"folder {folder} will be made in {parent}")
    except OSError as exc:
        return Finding(PROBLEM, "log", f"folder {folder}: {exc.strerror or exc}", fix)


def _existing_parent(folder: Path) -> Path:
    parent = folder.absolute()
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    return parent


def _room(folder: Path, estimate: LogEstimate | None, machine: Machine) -> Finding:
    where = _existing_parent(folder) if not folder.exists() else folder
    try:
        free = machine.free_bytes(where)
    except OSError as exc:
        return Finding(NOTE, "log space", f"free space on {where} not read: {exc.strerror or exc}")
    if estimate is None:
        return Finding(NOTE, "log space", f"{size(free)} free on {where}; the log's size is not "
                       "estimated (the show did not load)")
    said = f"the log will take {estimate.text()}; {size(free)} free on {where}"
    if free < estimate.room:
        return Finding(PROBLEM, "log space", f"{said}: the run would stop when the disk fills",
                       f"free {size(estimate.room - free)} or more there, or --log PATH on another disk")
    if free < ROOM_MARGIN * estimate.room:
        return Finding(NOTE, "log space", f"{said}: little to spare (another program writing there, each "
                       "pass of a --loop)", "free some space there")
    return Finding(OK, "log space", said)


def size(count: int) -> str:
    """Bytes as a user reads a disk's figures: 512 B, 130 kB, 4.2 MB, 12.0 GB."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if count >= scale:
            return f"{count / scale:.1f} {unit}" if count < 100 * scale else f"{count / scale:.0f} {unit}"
    return f"{count} B"

