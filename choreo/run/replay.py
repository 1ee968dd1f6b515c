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
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from choreo.clock import TimeSource
from choreo.numtext import whole_number
from choreo.errors import UsageError
from choreo.wire.protocol import Frame, FrameKind
from choreo.review.attached import AttachedShow, attached_show
from choreo.review.showtime import ShowTimes
from choreo.log.format import (LATE_MS, RX_TOPIC, STEP_TOPIC, TX_TOPIC, WARNING, LogLayouts, RxRecord, StepRecord,
                              TxRecord, parse, reply_meaning)
from choreo.log.reader import Cut, LogReader
from choreo.sim.options import is_simulator

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
        return (f"{self.show_s:9.3f} s  #{self.seq} {where}{self.frame}: recorded "
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


def default_port(show: AttachedShow, baud: int | None = None, layout: str = "seed") -> str:
    """`sim://` with the attached show's motion durations (and the run's baud and layout), or
    plain `sim://`."""
    return _with_durations("sim://", show, baud, layout)


def _with_durations(url: str, show: AttachedShow, baud: int | None = None, layout: str = "seed") -> str:
    """`--port sim://?drop=5`: still the show's durations and the replay's baud and layout (as
    `choreo run` does: one rule, `session.with_show_durations`)."""
    from choreo.wire.layouts import layout_named
    from choreo.board.link import DEFAULT_BAUD
    from choreo.run.session import with_show_durations

    return with_show_durations(url, show.show, show.plan, baud or DEFAULT_BAUD, layout_named(layout))



def at_speed(url: str, speed: float) -> str:
    """A `sim://` URL whose board runs `speed` times faster: every slot's duration (`durations`),
    the default for the others (`motion_s`), the board's reply delay (`reply_ms`) and its status
    refresh (`refresh_ms`, where the simulator has one) divided by the speed, and, faster than 1,
    bytes that take no wire time (`wire=0`).

    Without it a replay at speed 10 polls a motion ten times sooner after its start than the run
    did, finds it still executing where the run found it over, and `--strict` fails a clean log.
    The wire cannot run 10 times faster (the board has three bauds), and a 19-byte frame's
    1.7 ms at 115200 baud would be 17 ms of the run's time at speed 10: off is far closer to the
    run's timing than on. A URL that sets `wire` itself keeps it; one the simulator would refuse
    is left as it is, for the link to say what is wrong with it.
    """
    if speed == 1 or not is_simulator(url):
        return url
    from choreo.sim.options import SimUrl, durations_text, ms_text

    try:
        given = SimUrl.parse(url)
    except ValueError:
        return url
    options = given.options
    scaled = {"motion_s": f"{options.motion_s / speed:.9g}", "reply_ms": ms_text(options.reply_s / speed),
              "refresh_ms": ms_text(options.refresh_s / speed)}
    if options.durations:
        scaled["durations"] = durations_text({slot: seconds / speed for slot, seconds in options.durations.items()})
    faster = given.unless_given(wire="0") if speed > 1 else given
    return str(faster.with_text(**scaled))


MAX_SPEED = 1000.0
MIN_SPEED = 0.01  # a 10-minute show replays in at most 1000 minutes: slower is never meant


def check_options(speed: float, baud: int | None, timeout: float | None, layout: str | None = None) -> None:
    """Refuse what would make a meaningless replay, before anything is opened (UsageError, exit 2)."""
    from choreo.wire.layouts import layout_named
    from choreo.board.link import BAUD_RATES
    from choreo.run.session import check_timeout

    if not (math.isfinite(speed) and MIN_SPEED <= speed <= MAX_SPEED):
        raise UsageError(f"--speed {speed:g}: give a speed from {MIN_SPEED:g} to {MAX_SPEED:g} "
                         "(1 is the recorded timing, 2 twice as fast, 0.5 half as fast)")
    if layout is not None:
        try:
            layout_named(layout)
        except ValueError as exc:
            raise UsageError(f"--layout: {exc}") from None
    if baud is not None and baud not in BAUD_RATES:
        raise UsageError(f"--baud {baud}: the RCB-4 runs at {', '.join(map(str, BAUD_RATES))} baud")
    if timeout is not None:
        check_timeout(timeout)


@dataclass
class _ReplayedStep:
    """A recorded step event, re-timed for the new log (what Recorder.on_step needs of it)."""

    time_ns: int
    step: StepRecord

    @property
    def robot(self) -> str | None:
        return self.step.robot

    def record(self) -> StepRecord:
        return self.step


def replay(source: str | Path, *, port: str | None = None, speed: float = 1.0, baud: int | None = None,
           timeout: float | None = None, log_path: str | Path | None = None, log_dir: str | Path = "runs",
           layout: str | None = None, time_source: TimeSource | None = None,
           on_difference: Callable[[Difference], None] | None = None,
           on_start: Callable[[ReplayReport], None] | None = None) -> ReplayReport:
    """Replay the run recorded in `source`; the report says where the replies differ.

    LinkError (exit 3) if the port fails; a LogError if `source` is not a log or the new log
    cannot be written. A cut log replays as far as it goes.
    """
    check_options(speed, baud, timeout, layout)
    if log_path is not None:
        from choreo.run.session import check_output_folder

        check_output_folder(Path(log_path), "--log")
    from choreo.clock import RunClock, SystemTime
    from choreo.board.link import BAUD_RATES, DEFAULT_BAUD, DEFAULT_TIMEOUT_S
    from choreo.log.recorder import RobotInfo, RunInfo, default_log_path
    from choreo.run.session import RobotLink, Stage
    from choreo.show.model import SOLO

    with LogReader(source) as reader:
        show = attached_show(reader)
        recorded_baud = reader.run_info.get("baud", "")
        if baud is None:
            recorded = whole_number(recorded_baud)
            baud = recorded if port and recorded in BAUD_RATES else DEFAULT_BAUD
        given_layout = layout
        layout = layout or _recorded_layout(reader, None)  # logs before layouts: seed
        check_options(speed, baud, timeout, layout)
        url = at_speed(_with_durations(port or "sim://", show, baud, layout), speed)
        name = reader.run_info.get("show") or reader.path.stem
        clock = RunClock(time_source or SystemTime())
        new_log = Path(log_path) if log_path else default_log_path(f"{name}-replay", log_dir)
        attachment = reader.show_attachment()
        show_source = reader.attachment_data(attachment) if attachment else b""
        show_path = reader.run_info.get("show_path") or (attachment.name if attachment else "show.yaml")
        report = ReplayReport(reader.path, url, speed, new_log,
                              show_note=None if show.show is not None or port else show.problem)
        robots = reader.robots
        if robots and port:
            raise UsageError(f"--port {port}: a replay of several robots ({', '.join(robots)}) runs each on "
                             "its own simulator; leave out --port")
        # Each robot's simulator models its recorded layout, or --layout's for every robot. The
        # links send the recorded bytes only: no layout of their own (an HTH4 link would read the
        # config word at open, a frame the recording does not have).
        boards = {name: given_layout or _recorded_layout(reader, name) for name in robots}
        links = ([_robot_link(reader, show, name, boards[name], speed, timeout) for name in robots] if robots else
                 [RobotLink(SOLO, url, "command line", baud, timeout or DEFAULT_TIMEOUT_S, tries=1)])
        robot_info = tuple(RobotInfo(link.robot, link.port, link.baud, boards[link.robot])
                           for link in links) if robots else ()
        info = RunInfo(show_path, name, show_source, url, baud, clock.wall_anchor_ns, layout, robot_info,
                       reader.run_info.get("unison") == "yes")
        stage = Stage(info, new_log, clock, links, unique_log=log_path is None, named=bool(robots),
                      opening_note=f"replay of {reader.path} at speed {speed:g} on {url if not robots else 'simulators'}")
        report.boards = tuple(link.port for link in links)
        if robots:
            each = ", ".join(f"{name}: {boards[name]}" for name in robots)
            report.port = f"{len(robots)} simulators, one per robot and its layout ({each})"
        with stage:
            report.log_path = stage.log_path
            if speed > 1:
                for link in stage.links.values():
                    if is_simulator(link.name):  # its motions and status refresh run `speed` times faster: so may the polls
                        link.status_spacing_s /= speed
            if on_start is not None:
                on_start(report)
            if robots:
                _replay_robots(source, stage, clock, speed, report, on_difference, _first_frame_s(reader))
            else:
                _replay_frames(reader, stage.link, stage.recorder, clock, speed, report, on_difference)
            report.cut = reader.cut if not robots else report.cut
            stage.outcome = {"outcome": "done", "replay_of": str(reader.path), "speed": f"{speed:g}",
                             "frames": str(report.frames), "differences": str(report.different),
                             "show_s": f"{_elapsed(clock):.6f}", "exit_code": "0"}
    return report


def _robot_link(reader: LogReader, show: AttachedShow, robot: str, layout_name: str, speed: float,  # type: ignore[no-untyped-def]
                timeout: float | None):
    """A recorded robot's replay link: its own simulator of `layout_name`, set up from its plan,
    at its baud."""
    from choreo.wire.layouts import layout_named
    from choreo.board.link import BAUD_RATES, DEFAULT_BAUD, DEFAULT_TIMEOUT_S
    from choreo.run.session import RobotLink, with_show_durations

    baud_text = reader.run_info.get(f"robot.{robot}.baud", "")
    recorded = whole_number(baud_text)
    baud = recorded if recorded in BAUD_RATES else DEFAULT_BAUD
    layout = layout_named(layout_name)
    plan = show.plan_of(robot)
    abort = show.show.abort_motion(robot) if show.show is not None and plan is not None else None
    url = with_show_durations("sim://", show.show if plan is not None else None, plan, baud, layout, abort)
    return RobotLink(robot, at_speed(url, speed), "simulator", baud, timeout or DEFAULT_TIMEOUT_S, tries=1)


def _replay_robots(source: str | Path, stage, clock, speed: float, report: ReplayReport,  # type: ignore[no-untyped-def]
                   on_difference: Callable[[Difference], None] | None, first_s: float = 0.0) -> None:
    """Each robot's frames on its own thread and link, all on one start: a robot waiting for its
    reply never holds up another's frames. Each thread reads the log on its own (a reader is
    not shared between threads); the reports are added up at the end."""
    import threading

    start = clock.mono() - min(first_s, 0.0) / speed  # recorded show time 0; frames sent at open come before it
    parts = {name: ReplayReport(report.source, link.name, speed, report.log_path) for name, link in stage.links.items()}
    errors: list[BaseException] = []

    def play(name: str) -> None:
        try:
            with LogReader(source) as reader:
                _replay_frames(reader, stage.links[name], stage.recorder, clock, speed, parts[name], on_difference,
                               robot=name, start=start)
                parts[name].cut = reader.cut
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
    from choreo.wire.layouts import LAYOUT_NAMES

    layouts = LogLayouts.of(reader.run_info)
    if layouts.layout(robot) is None:
        whose = f"robot {robot}'s" if robot is not None else "its"
        raise UsageError(f"log {reader.path}: {whose} board layout {layouts.name(robot)!r} is unknown to "
                         f"this choreo: replay it with --layout {' or '.join(LAYOUT_NAMES)}")
    return layouts.name(robot)


def _first_frame_s(reader: LogReader) -> float:
    """The recorded show time of the log's first frame (negative: sent when the ports opened)."""
    times = ShowTimes.of(reader)
    for _, log_time, _ in reader.messages((TX_TOPIC,)):
        return times.seconds(log_time) or 0.0
    return 0.0


def _add_up(report: ReplayReport, part: ReplayReport) -> None:
    for name in ("frames", "same", "different", "timing", "replay_late", "excused", "unmatched"):
        setattr(report, name, getattr(report, name) + getattr(part, name))
    report.differences.extend(part.differences[:LISTED_DIFFERENCES - len(report.differences)])
    report.max_lag_ms = max(report.max_lag_ms, part.max_lag_ms)
    report.cut = report.cut or part.cut


def _elapsed(clock) -> float:
    return (clock.mono_ns() - clock.mono_anchor_ns) / 1e9


def _replay_frames(reader: LogReader, link, recorder, clock, speed: float, report: ReplayReport,
                   on_difference: Callable[[Difference], None] | None, robot: str | None = None,
                   start: float | None = None) -> None:
    """The recorded frames, each at its show time / speed; replies compared as they come.

    `robot`: only that robot's frames and steps; `start`: the monotonic time of recorded show
    time 0, shared by every robot's thread (else the replay starts at its first event)."""
    from choreo.board.link import Tag

    at_end = _polls_at_motion_ends(reader, robot)
    recorded_clock = ShowTimes.of(reader)
    layouts = LogLayouts.of(reader.run_info)
    zero_mono: float | None = start  # replay's monotonic time of recorded show time 0
    first_s = 0.0
    last: tuple[float, float] | None = None  # the last event: (recorded show s, replay monotonic)
    restored: tuple[float, float] | None = None  # the last restore: (recorded show s, replay write)
    # recorded seq -> (tx, replayed reply, show s, how late it left on the run's clock in ms)
    pending: dict[int, tuple[TxRecord, RxRecord, float, float]] = {}

    def due(show_s: float) -> float:
        """Wait for an event's time: its recorded show time, and never closer to the event before
        it than it was recorded. The replay's own exchanges can put it a few ms behind (a play
        sequence is three frames, each waiting for its reply); keeping the recorded gaps then keeps
        a status poll as far from the restore that started the motion as it was, so the board
        answers it the same way."""
        nonlocal zero_mono, first_s, last
        if zero_mono is None:
            first_s = show_s  # start at once, whatever show time the recording starts at
            zero_mono = clock.mono()
        target = zero_mono + (show_s - first_s) / speed
        if last is not None:
            target = max(target, last[1] + (show_s - last[0]) / speed)
        clock.sleep_until(target)
        now = clock.mono()
        last = (show_s, now)
        lag_ms = (now - (zero_mono + (show_s - first_s) / speed)) * 1e3
        if lag_ms > report.max_lag_ms:
            report.max_lag_ms = lag_ms
        return target

    topic, number = None, 0
    try:
        for topic, log_time, data in reader.messages((TX_TOPIC, RX_TOPIC, STEP_TOPIC)):
            number += 1
            record = parse(topic, data)
            if isinstance(record, StepRecord):
                recorded_clock.see_step(log_time, record)
            if robot is not None and record.robot != robot:
                continue
            if isinstance(record, StepRecord):
                due(recorded_clock.seconds(log_time) or 0.0)
                # the replay's show clock is the run's, from its first event if the run's started
                # later than zero: frames the run sent before zero (at open) stay before it
                origin = max(first_s, 0.0)
                retimed = _retimed(record, origin, speed, clock.mono() - zero_mono + (first_s - origin) / speed)
                recorder.on_step(_ReplayedStep(clock.wall_ns(), retimed))
            elif isinstance(record, TxRecord):
                show_s = recorded_clock.seconds(log_time) or 0.0
                frame = _frame(reader, record)
                if record.seq in pending:  # its recorded reply never came: nothing to compare
                    pending.pop(record.seq)
                    report.unmatched += 1
                target = due(show_s)
                reply = link.send(frame, record.attempt, Tag(record.step, record.label))
                report.frames += 1
                replayed = RxRecord(record.seq, reply.kind.value, reply.hex, executing=reply.executing,
                                    error=reply.error, robot=record.robot)
                written = getattr(link, "last_tx_mono", target)  # after any wait in the link
                if frame.kind is FrameKind.RESTORE:
                    restored = (show_s, written)
                late_ms = _late_ms(show_s, written, target, restored, speed)
                pending[record.seq] = (record, replayed, show_s, late_ms)
                if len(pending) > 64:  # replies missing from the recording: do not hold them forever
                    pending.pop(next(iter(pending)))
                    report.unmatched += 1
            else:
                held = pending.pop(record.seq, None)
                if held is None:
                    continue
                tx, replayed, show_s, late_ms = held
                if _same(record, replayed):
                    report.same += 1
                    continue
                difference = Difference(record.seq, tx.step, tx.kind, show_s, record, replayed,
                                        round(late_ms, 3), record.seq in at_end, tx, layouts)
                report.different += 1
                report.timing += difference.timing
                report.replay_late += difference.replay_late
                report.excused += difference.excused
                if len(report.differences) < LISTED_DIFFERENCES:
                    report.differences.append(difference)
                recorder.on_log(WARNING, f"replay differs: {difference}", clock.wall_ns())
                if on_difference is not None:
                    on_difference(difference)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise reader.not_choreo(topic, number, exc) from None
    report.unmatched += len(pending)


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
        if record.robot != robot:
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
    if restored is not None:
        behind = (written - restored[1]) - (show_s - restored[0]) / speed
    else:
        behind = written - target
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
