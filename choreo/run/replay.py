"""`choreo replay LOG`: send a recorded run's frames again, on their recorded timing, and compare.

Every frame of the log goes out again, byte for byte (retries included: they were on the wire
too), at its recorded time on the show clock divided by `--speed`, and each reply is compared
with the one recorded. The replay is a run of its own: it is recorded to a new log (same topics,
steps re-timed to the replay's clock), so it can be reviewed with the same commands.

The default port is the built-in simulator, set up from the show attached to the log (its
motions run as long as the show says) - never the robot the show names: a replay moves a real
robot only when `--port` says so. At `--speed X` a `sim://` board runs its motions X times
faster too, so a status poll falls on the same side of a motion's end as it did in the run and a
clean log replays clean at any speed. Only the motions' lengths are scaled: a frame's wire time,
the board's reply delay and the link's reply timeout are the line's, and a replay cannot make a
frame shorter. A robot (or `choreo sim` on a pty) runs its motions at its own speed.

Each board modelled gets the layout the log records for its robot; `--layout` gives every one
that layout (the recorded bytes are sent as they are: a board of another layout answers them as
it would, and the differences show it).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from choreo.board.link import DEFAULT_TIMEOUT_S, Link
from choreo.clock import RunClock, SystemTime, TimeSource
from choreo.errors import UsageError
from choreo.events import Tag
from choreo.log.format import (LATE_MS, RX_TOPIC, SHOW_FALLBACK_NAME, STEP_TOPIC, TX_TOPIC, WARNING, LogLayouts,
                               Record, Result, RxRecord, StepRecord, TxRecord, parse, reply_meaning)
from choreo.log import LOG_DIR
from choreo.log.reader import Cut, LogReader
from choreo.log.recorder import Recorder, RobotInfo, RunInfo, default_log_path
from choreo.review.attached import AttachedShow, attached_show
from choreo.review.showtime import Durations, ShowTimes, durations, fixed
from choreo.run.settings import LinkSettings, check_output_folder, check_timeout, given_layout, show_durations
from choreo.run.stage import Stage
from choreo.show.model import SIM_URL, SOLO, is_simulator
from choreo.wire.layouts import LAYOUT_NAMES, layout_named
from choreo.wire.protocol import BAUDS, DEFAULT_BAUD, Frame, FrameKind, baud_refusal

LISTED_DIFFERENCES = 200  # kept in the report; all are counted (and written to the new log)


@dataclass(frozen=True)
class Difference:
    """A frame whose reply in the replay is not the one recorded."""

    seq: int  # the recorded frame's seq
    step: int | None
    frame: str  # frame kind
    show_s: float  # recorded show time of the frame
    recorded: RxRecord
    replayed: RxRecord
    late_ms: float = 0.0  # how late the replay sent the frame, on the run's clock (ms)
    at_end: bool = False  # in the recording, the motion's end showed at this poll or the next
    sent: TxRecord | None = None  # the recorded frame: what the replies answer
    layouts: LogLayouts = LogLayouts({})  # the recorded run's layouts: the replies are read with them

    @property
    def timing(self) -> bool:
        """Both are good status replies that disagree only on whether the motion is still
        executing: a poll that fell on the motion's end, not a fault on the line."""
        return self.recorded.kind == self.replayed.kind == "status"

    @property
    def replay_late(self) -> bool:
        """The replay itself sent this poll late (a busy machine: at speed 10, 0.3 ms is 3 ms of
        the run), and it found over a motion the run found still executing: the replay's timing,
        not the board's answer. A poll sent on time that differs is never excused."""
        return (self.timing and self.recorded.executing is True
                and self.replayed.executing is False and self.late_ms > LATE_MS)

    @property
    def excused(self) -> bool:
        """A status poll that fell on the motion's end, where the board's 50 ms status refresh
        decides the answer: the refresh ticks run from the board's power-on, which no log
        records, so a replay's ticks fall elsewhere and the poll next to the end may go either
        way. A poll away from the end that differs is never excused."""
        return self.timing and (self.at_end or self.replay_late)

    def __str__(self) -> str:
        where = f"step {self.step} " if self.step is not None else ""
        if self.replay_late:
            note = (f" (timing: the replay sent this poll {self.late_ms:.1f} ms late on the run's clock, "
                    "after the motion's end: not the board's doing)")
        elif self.at_end and self.timing:
            note = " (timing: a poll at the motion's end, where the board's 50 ms status refresh decides)"
        else:
            note = " (a poll away from the motion's end: the board answered differently)" if self.timing else ""
        return (f"{fixed(self.show_s, 3, 9)} s  #{self.seq} {where}{self.frame}: recorded "
                f"{self._said(self.recorded)}, replay {self._said(self.replayed)}{note}")

    def _said(self, reply: RxRecord) -> str:
        shown = reply.hex and reply.kind not in ("timeout", "invalid")
        return reply_meaning(reply, self.sent, self.layouts) + (f" ({reply.hex})" if shown else "")


@dataclass
class ReplayReport:
    source: Path
    port: str
    speed: float
    log_path: Path | None
    frames: int = 0
    same: int = 0
    different: int = 0
    timing: int = 0  # of the differences, status polls that disagree only on "executing"
    replay_late: int = 0  # of those, polls the replay sent late (`Difference.replay_late`)
    excused: int = 0  # of those, polls at a motion's end or sent late (`Difference.excused`)
    unmatched: int = 0  # frames whose recorded reply is missing (a cut log)
    differences: list[Difference] = field(default_factory=list)
    max_lag_ms: float = 0.0  # how far behind its recorded show time (scaled) a frame left at worst
    cut: Cut | None = None
    show_note: str | None = None  # why the simulator runs without the show's durations
    boards: tuple[str, ...] = ()  # where the frames went: one URL a robot (empty: `port`)
    recorded: Durations | None = None  # the recorded show's lengths, as every review gives them

    @property
    def board_differences(self) -> int:
        """Differences the board is answerable for: what `--strict` fails on."""
        return self.different - self.excused

    @property
    def speed_note(self) -> str | None:
        """Why replies may differ at a motion's end: only a `sim://` board runs faster, so the
        note names the boards that are not one (none: no note)."""
        others = [board for board in self.boards or (self.port,) if not is_simulator(board)]
        if self.speed == 1 or not others:
            return None
        return (f"{', '.join(others)} {'runs' if len(others) == 1 else 'run'} motions at the robot's own "
                f"speed, not {self.speed:g}x: status polls near a motion's end may differ")


MAX_SPEED = 1000.0
MIN_SPEED = 0.01  # a 10-minute show replays in at most 1000 minutes: slower is never meant


def check_options(speed: float, baud: int | None, timeout: float | None, layout: str | None = None) -> None:
    """Refuse what would make a meaningless replay, before anything is opened (UsageError, exit 2)."""
    if not (math.isfinite(speed) and MIN_SPEED <= speed <= MAX_SPEED):
        raise UsageError(f"--speed {speed:g}: give a speed from {MIN_SPEED:g} to {MAX_SPEED:g} "
                         "(1 is the recorded timing, 2 twice as fast, 0.5 half as fast)")
    if layout is not None:
        given_layout(layout)
    if baud is not None and baud not in BAUDS:
        raise UsageError(baud_refusal(baud, "--baud"))
    if timeout is not None:
        check_timeout(timeout)


@dataclass(frozen=True)
class ReplayRequest:
    """What the user asked of a replay (None: not given): the replay's `RunRequest`."""

    port: str | None = None
    speed: float = 1.0
    baud: int | None = None
    timeout: float | None = None
    log_path: str | Path | None = None
    log_dir: str | Path = LOG_DIR
    layout: str | None = None


@dataclass(frozen=True)
class ReplaySettings:
    """A replay's settings, read off the log and the request before anything opens: a link's
    settings a robot (the port each opens is built from them, as a run's is), the board layout
    each simulator models, and what the new log records of the run."""

    links: tuple[LinkSettings, ...]
    boards: dict[str, str]  # robot -> the layout its simulator models (several robots only)
    info: RunInfo
    log_path: Path
    unique_log: bool

    @property
    def several(self) -> bool:
        return bool(self.boards)


def replay(source: str | Path, *, port: str | None = None, speed: float = 1.0, baud: int | None = None,
           timeout: float | None = None, log_path: str | Path | None = None, log_dir: str | Path = LOG_DIR,
           layout: str | None = None, time_source: TimeSource | None = None,
           on_difference: Callable[[Difference], None] | None = None,
           on_start: Callable[[ReplayReport], None] | None = None) -> ReplayReport:
    """Replay the run recorded in `source`; the report says where the replies differ.

    LinkError (exit 3) if the port fails; a LogError if `source` is not a log or the new log
    cannot be written. A cut log replays as far as it goes.
    """
    request = ReplayRequest(port, speed, baud, timeout, log_path, log_dir, layout)
    check_options(speed, baud, timeout, layout)
    if log_path is not None:
        check_output_folder(Path(log_path), "--log")
    clock = RunClock(time_source or SystemTime())
    with LogReader(source) as reader:
        show = attached_show(reader)
        settings = _settle(reader, show, request, clock)
        report: ReplayReport = _report(reader, show, request, settings)
        report.recorded = _recorded(reader)
        with _stage(reader, settings, request, clock) as stage:
            report.log_path = stage.log_path
            if on_start is not None:
                on_start(report)
            _replay_stage(source, reader, stage, clock, report, on_difference)
            stage.finished({Result.OUTCOME: "done", Result.REPLAY_OF: str(reader.path), Result.SPEED: f"{speed:g}",
                            Result.FRAMES: str(report.frames), Result.DIFFERENCES: str(report.different),
                            Result.SHOW_S: f"{_elapsed(clock):.6f}", Result.EXIT_CODE: "0"})
    return report


def _settle(reader: LogReader, show: AttachedShow, request: ReplayRequest, clock: RunClock) -> ReplaySettings:
    """The replay's settings. Each robot's simulator models its recorded layout, or --layout's
    for every robot. The links send the recorded bytes only: no layout of their own (an HTH4
    link would read the config word at open, a frame the recording does not have)."""
    robots = reader.robots
    if robots and request.port:
        raise UsageError(f"--port {request.port}: a replay of several robots ({', '.join(robots)}) runs each on "
                         "its own simulator; leave out --port")
    layout = request.layout or _recorded_layout(reader, None)  # logs before layouts: seed
    solo = _solo_link(reader, show, request, layout)  # with several robots, what the log's head names
    boards = {name: request.layout or _recorded_layout(reader, name) for name in robots}
    links = tuple(_robot_link(reader, show, name, boards[name], request) for name in robots) if robots else (solo,)
    robot_info = tuple(RobotInfo(link.robot, link.port, link.baud, boards[link.robot]) for link in links) \
        if robots else ()
    name = reader.info.show or reader.path.stem
    # the show as the review read it (a hostile log's attachment past a show file's size is not
    # read again here, whole, into the new log)
    show_path = reader.info.show_path or show.file_name or SHOW_FALLBACK_NAME
    info = RunInfo(show_path, name, show.source, solo.port, solo.baud, clock.wall_anchor_ns, layout, robot_info,
                   reader.info.unison)
    new_log = Path(request.log_path) if request.log_path else default_log_path(f"{name}-replay", request.log_dir)
    return ReplaySettings(links, boards, info, new_log, unique_log=request.log_path is None)


def _solo_link(reader: LogReader, show: AttachedShow, request: ReplayRequest, layout: str) -> LinkSettings:
    """A one-robot log's link: --port (default: the simulator, set up from the attached show),
    at --baud, else the recorded baud on a port that was given, else the default."""
    baud = request.baud
    if baud is None:
        recorded = reader.info.baud()
        baud = recorded if request.port and recorded is not None and recorded in BAUDS else DEFAULT_BAUD
    return LinkSettings(SOLO, request.port or SIM_URL, "command line", baud, request.timeout or DEFAULT_TIMEOUT_S,
                        tries=1, durations=show_durations(show.show, show.plan), board_layout=layout_named(layout),
                        speed=request.speed)


def _robot_link(reader: LogReader, show: AttachedShow, robot: str, layout_name: str,
                request: ReplayRequest) -> LinkSettings:
    """A recorded robot's replay link: its own simulator of `layout_name`, set up from its plan,
    at its baud."""
    recorded = reader.info.baud(robot)
    baud = recorded if recorded is not None and recorded in BAUDS else DEFAULT_BAUD
    plan = show.plan_of(robot)
    abort = show.show.abort_motion(robot) if show.show is not None and plan is not None else None
    return LinkSettings(robot, SIM_URL, "simulator", baud, request.timeout or DEFAULT_TIMEOUT_S, tries=1,
                        durations=show_durations(show.show, plan, abort), board_layout=layout_named(layout_name),
                        speed=request.speed)


def _report(reader: LogReader, show: AttachedShow, request: ReplayRequest, settings: ReplaySettings) -> ReplayReport:
    """The report, before any frame: where the frames go, and why a simulator runs without the
    show's durations."""
    report = ReplayReport(reader.path, settings.info.port, request.speed, settings.log_path,
                          show_note=None if show.show is not None or request.port else show.problem,
                          boards=tuple(link.port for link in settings.links))
    if settings.several:
        each = ", ".join(f"{name}: {layout}" for name, layout in settings.boards.items())
        report.port = f"{len(settings.boards)} simulators, one per robot and its layout ({each})"
    return report


def _stage(reader: LogReader, settings: ReplaySettings, request: ReplayRequest, clock: RunClock) -> Stage:
    where = "simulators" if settings.several else settings.info.port
    return Stage(settings.info, settings.log_path, clock, settings.links, unique_log=settings.unique_log,
                 named=settings.several,
                 opening_note=f"replay of {reader.path} at speed {request.speed:g} on {where}")


def _replay_stage(source: str | Path, reader: LogReader, stage: Stage, clock: RunClock, report: ReplayReport,
                  on_difference: Callable[[Difference], None] | None) -> None:
    """The recorded frames through the open stage: each robot on its own thread, or the one."""
    assert stage.recorder is not None, "a replay always writes its log"
    if report.speed > 1:
        for link in stage.links.values():
            if is_simulator(link.name):  # its motions and status refresh run `speed` times faster: so may polls
                link.refresh_faster(report.speed)
    if stage.named:
        _replay_robots(source, stage, clock, report, on_difference, _first_frame_s(reader))
        return
    link = next(iter(stage.links.values()))
    _FrameReplay(reader, link, stage.recorder, clock, report, on_difference).run()
    report.cut = reader.cut


def _replay_robots(source: str | Path, stage: Stage, clock: RunClock, report: ReplayReport,
                   on_difference: Callable[[Difference], None] | None, first_s: float = 0.0) -> None:
    """Each robot's frames on its own thread and link, all on one start: a robot waiting for its
    reply never holds up another's frames. Each thread reads the log on its own (a reader is
    not shared between threads); the reports are added up at the end."""
    recorder = stage.recorder
    assert recorder is not None
    speed = report.speed
    start = clock.mono() - min(first_s, 0.0) / speed  # recorded show time 0; frames sent at open come before it
    parts = {name: ReplayReport(report.source, link.name, speed, report.log_path) for name, link in stage.links.items()}
    errors: list[BaseException] = []

    def play(name: str) -> None:
        try:
            with LogReader(source) as reader:
                part: ReplayReport = parts[name]
                _FrameReplay(reader, stage.links[name], recorder, clock, part, on_difference, robot=name,
                             start=start).run()
                part.cut = reader.cut
        except BaseException as exc:  # noqa: BLE001 - raised in the main thread
            errors.append(exc)
        finally:
            clock.source.leave()

    threads = [threading.Thread(target=play, args=(name,), name=f"choreo-replay-{name}", daemon=True)
               for name in stage.links]
    clock.source.admit(len(threads))
    for thread in threads:
        thread.start()
    for thread in threads:
        while thread.is_alive():
            thread.join(0.05)
    if errors:
        raise errors[0]
    for part in parts.values():
        _add_up(report, part)


def _recorded_layout(reader: LogReader, robot: str | None) -> str:
    """The layout the log records for the robot's frames (seed for a log from before layouts
    were recorded); UsageError for one this choreo does not know."""
    layouts = LogLayouts.of(reader.run_info)
    if layouts.layout(robot) is None:
        whose = f"robot {robot}'s" if robot is not None else "its"
        raise UsageError(f"log {reader.path}: {whose} board layout {layouts.name(robot)!r} is unknown to "
                         f"this choreo: replay it with --layout {' or '.join(LAYOUT_NAMES)}")
    return layouts.name(robot)


def _recorded(reader: LogReader) -> Durations:
    """The recorded show's duration, holds and pauses (`showtime.durations`, as the reviews)."""
    times = ShowTimes.of(reader)
    last = None
    for _, log_time, _ in reader.messages():
        last = log_time
    return durations(times, reader.result, last)


def _first_frame_s(reader: LogReader) -> float:
    """The recorded show time of the log's first frame (negative: sent when the ports opened)."""
    times = ShowTimes.of(reader)
    for _, log_time, _ in reader.messages((TX_TOPIC,)):
        return times.elapsed(log_time) or 0.0
    return 0.0


def _add_up(report: ReplayReport, part: ReplayReport) -> None:
    for name in ("frames", "same", "different", "timing", "replay_late", "excused", "unmatched"):
        setattr(report, name, getattr(report, name) + getattr(part, name))
    report.differences.extend(part.differences[:LISTED_DIFFERENCES - len(report.differences)])
    report.max_lag_ms = max(report.max_lag_ms, part.max_lag_ms)
    report.cut = report.cut or part.cut


def _elapsed(clock: RunClock) -> float:
    return (clock.mono_ns() - clock.mono_anchor_ns) / 1e9


@dataclass
class _Sent:
    """A frame sent again, waiting for its recorded reply to compare with the replay's."""

    tx: TxRecord
    replayed: RxRecord
    show_s: float  # the frame's recorded show time
    late_ms: float  # how late it left, on the run's clock


class _FrameReplay:
    """The recorded frames, each at its show time / speed; replies compared as they come.

    `robot`: only that robot's frames and steps; `start`: the monotonic time of recorded show
    time 0, shared by every robot's thread (else the replay starts at its first event)."""

    def __init__(self, reader: LogReader, link: Link, recorder: Recorder, clock: RunClock, report: ReplayReport,
                 on_difference: Callable[[Difference], None] | None, robot: str | None = None,
                 start: float | None = None) -> None:
        self.reader, self.link, self.recorder, self.clock = reader, link, recorder, clock
        self.report, self.speed, self.on_difference, self.robot = report, report.speed, on_difference, robot
        self.at_end = _polls_at_motion_ends(reader, robot)
        self.recorded_clock = ShowTimes.of(reader)
        self.layouts = LogLayouts.of(reader.run_info)
        self.zero_mono: float | None = start  # replay's monotonic time of recorded show time 0
        self.first_s = 0.0
        self.last: tuple[float, float] | None = None  # the last event: (recorded show s, replay monotonic)
        self.restored: tuple[float, float] | None = None  # the last restore: (recorded show s, replay write)
        self.pending: dict[int, _Sent] = {}  # by recorded seq

    def run(self) -> None:
        topic, number = None, 0
        try:
            for topic, log_time, data in self.reader.messages((TX_TOPIC, RX_TOPIC, STEP_TOPIC)):
                number += 1
                self._event(parse(topic, data), log_time)
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise self.reader.not_choreo(topic, number, exc) from None
        report: ReplayReport = self.report
        report.unmatched += len(self.pending)

    def _event(self, record: Record, log_time: int) -> None:
        if not isinstance(record, (TxRecord, RxRecord, StepRecord)):
            return  # only frames, replies and steps are read
        if isinstance(record, StepRecord):
            self.recorded_clock.see_step(log_time, record)
        if self.robot is not None and record.robot != self.robot:
            return
        if isinstance(record, StepRecord):
            self._step(record, log_time)
        elif isinstance(record, TxRecord):
            self._send(record, log_time)
        else:
            self._compare(record)

    def _due(self, show_s: float) -> float:
        """Wait for an event's time: its recorded show time, and never closer to the event before
        it than it was recorded. The replay's own exchanges can put it a few ms behind (a play
        sequence is three frames, each waiting for its reply); keeping the recorded gaps then keeps
        a status poll as far from the restore that started the motion as it was, so the board
        answers it the same way."""
        if self.zero_mono is None:
            self.first_s = show_s  # start at once, whatever show time the recording starts at
            self.zero_mono = self.clock.mono()
        on_time = self.zero_mono + (show_s - self.first_s) / self.speed
        target = on_time if self.last is None else max(on_time, self.last[1] + (show_s - self.last[0]) / self.speed)
        self.clock.sleep_until(target)
        now = self.clock.mono()
        self.last = (show_s, now)
        report: ReplayReport = self.report
        report.max_lag_ms = max(report.max_lag_ms, (now - on_time) * 1e3)
        return target

    def _step(self, record: StepRecord, log_time: int) -> None:
        """A recorded step event, re-timed into the new log: the replay's show clock is the
        run's, from its first event if the run's started later than zero (frames the run sent
        before zero, at open, stay before it)."""
        self._due(self.recorded_clock.elapsed(log_time) or 0.0)
        assert self.zero_mono is not None  # set by the first _due
        origin = max(self.first_s, 0.0)
        elapsed = self.clock.mono() - self.zero_mono + (self.first_s - origin) / self.speed
        self.recorder.on_step_record(_retimed(record, origin, self.speed, elapsed), self.clock.wall_ns())

    def _send(self, record: TxRecord, log_time: int) -> None:
        """The recorded frame sent again on time; its reply held until the recorded one comes."""
        report: ReplayReport = self.report
        show_s = self.recorded_clock.seconds(log_time) or 0.0
        at = self.recorded_clock.elapsed(log_time) or 0.0  # paced with the holds in: the board sees the same gaps
        frame = _frame(self.reader, record)
        if self.pending.pop(record.seq, None) is not None:  # its recorded reply never came: nothing to compare
            report.unmatched += 1
        target = self._due(at)
        reply = self.link.send(frame, record.attempt, Tag(record.step, record.label))
        report.frames += 1
        replayed = RxRecord(record.seq, reply.kind.value, reply.hex, executing=reply.executing,
                            error=reply.error, robot=record.robot)
        written = self.link.last_tx_mono  # after any wait in the link
        if frame.kind is FrameKind.RESTORE:
            self.restored = (at, written)
        late_ms = _late_ms(at, written, target, self.restored, self.speed)
        self.pending[record.seq] = _Sent(record, replayed, show_s, late_ms)
        if len(self.pending) > 64:  # replies missing from the recording: do not hold them forever
            self.pending.pop(next(iter(self.pending)))
            report.unmatched += 1

    def _compare(self, record: RxRecord) -> None:
        """A recorded reply against the replay's to the same frame; a difference is counted,
        listed (up to LISTED_DIFFERENCES), logged and told."""
        sent = self.pending.pop(record.seq, None)
        if sent is None:
            return
        report: ReplayReport = self.report
        if _same(record, sent.replayed):
            report.same += 1
            return
        difference = Difference(record.seq, sent.tx.step, sent.tx.kind, sent.show_s, record, sent.replayed,
                                round(sent.late_ms, 3), record.seq in self.at_end, sent.tx, self.layouts)
        report.different += 1
        report.timing += difference.timing
        report.replay_late += difference.replay_late
        report.excused += difference.excused
        if len(report.differences) < LISTED_DIFFERENCES:
            report.differences.append(difference)
        self.recorder.on_log(WARNING, f"replay differs: {difference}", self.clock.wall_ns())
        if self.on_difference is not None:
            self.on_difference(difference)


def _frame(reader: LogReader, tx: TxRecord) -> Frame:
    """The recorded frame, to send again byte for byte."""
    try:
        return Frame(FrameKind(tx.kind), bytes.fromhex(tx.hex), tx.motion)
    except (TypeError, ValueError):
        raise UsageError(f"log {reader.path}: frame #{tx.seq} cannot be sent again: "
                         f"kind {tx.kind!r}, bytes {tx.hex!r}") from None


def _polls_at_motion_ends(reader: LogReader, robot: str | None = None) -> set[int]:
    """The recorded status polls next to a motion's end: the last that saw it executing and the
    first that saw it over (by the seq of the frame they answer)."""
    statuses: set[int] = set()
    edges: set[int] = set()
    previous: tuple[int, bool] | None = None
    for topic, _, data in reader.messages((TX_TOPIC, RX_TOPIC)):
        record = parse(topic, data)
        if not isinstance(record, (TxRecord, RxRecord)) or record.robot != robot:
            continue
        if isinstance(record, TxRecord):
            if record.kind == "status":
                statuses.add(record.seq)
            continue
        executing = record.executing
        if record.seq not in statuses or not isinstance(executing, bool):
            continue
        if previous is not None and previous[1] != executing:
            edges.update((previous[0], record.seq))
        previous = (record.seq, executing)
    return edges


def _late_ms(show_s: float, written: float, target: float, restored: tuple[float, float] | None,
             speed: float) -> float:
    """How late a frame went out, in ms of the run's clock: against the restore that started
    the running motion (what decides a status poll's answer), else against its own due time.

    Measured from the restore, not from the poll's due time: a step event between them that ran
    late moves the poll's due time with it, and the poll then looks on time while it fell later
    in the motion than the run's did.
    """
    behind = (written - restored[1]) - (show_s - restored[0]) / speed if restored is not None else written - target
    return max(0.0, behind * 1e3 * speed)


def _same(recorded: RxRecord, replayed: RxRecord) -> bool:
    """Same verdict and, where the board answered, the same bytes (a status byte included)."""
    if recorded.kind != replayed.kind:
        return False
    return replayed.kind == "timeout" or recorded.hex == replayed.hex


def _retimed(step: StepRecord, first_s: float, speed: float, elapsed_s: float) -> StepRecord:
    """A recorded step event on the replay's clock (seconds since recorded show time `first_s`,
    at `speed`; `elapsed_s`: the replay's show time now)."""

    def moved(seconds: float) -> float:
        return round(max(0.0, (seconds - first_s) / speed), 6)

    planned_s = moved(step.planned_s)
    late_ms = round(max(0.0, (elapsed_s - planned_s) * 1e3), 3) if step.event == "start" else step.late_ms
    return replace(step, planned_s=planned_s, estimated_s=moved(step.estimated_s), actual_s=round(elapsed_s, 6),
                   late_ms=late_ms, cue=None if step.cue is None else moved(step.cue))
