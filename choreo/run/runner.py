"""The show clock: walks a compiled plan and has the link send each step on time.

Every due time is absolute from the show's start (a step is due at max(its cue, the end of the
step before it)), so the time frames take on the wire never accumulates as drift. The runner
sleeps until just before a due time and spins the rest, so a cue's first byte leaves within a
millisecond of it. It reports each step's start and end, late steps and retried frames to its
listeners (the recorder, the progress display) and sends nothing the show did not ask for.

Under the live controls (`choreo.live.controls`) it waits, before a step starts, while the show
is paused (a step under way finishes: a play sequence is never cut), and it passes a cue the
operator skipped where the robot is, with one `skip` event and no frame.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Protocol

from choreo.board.link import Link, Played
from choreo.clock import BeatGrid, MachineShowClock, RunClock, ShowClock, sleep_until_show
from choreo.errors import ChoreoError, Interrupted, LinkError
from choreo.events import RunListener, RunResult, RxEvent, StepEvent, StopRequest, Tag, TxEvent, never
from choreo.log.format import ABORT_LABEL, ERROR, INFO, LATE_MS, WARNING
from choreo.show.model import SOLO, Plan, PlannedStep, StepKind

if TYPE_CHECKING:
    from choreo.live.controls import Live

POLL_S = 0.05  # the board refreshes its status every 50 ms: never poll faster


def step_ref(step: PlannedStep) -> str:
    """How messages name a step: `step 4 'spin'` (the index `choreo plan` and `--from` use)."""
    return f"step {step.index}" + (f" '{step.label}'" if step.label else "")


class WaitTimeout(LinkError):
    """`wait: done` gave up: the board kept saying the motion is executing."""


class Cues(Protocol):
    """Where a robot's runner meets the others on shared steps (`choreo.run.ensemble.Gates`)."""

    def through(self, index: int, robot: str, end: float | None, idle: float | None = None) -> float | None:
        """`robot` is through step `index` (ended at `end` on the show clock, None: not its
        step, which would end at `idle` as planned); blocks until every robot the step was for
        is, and returns when the next step may start (None: the show is stopping)."""

    def armed(self, step: PlannedStep, robot: str, write: Callable[[], None]) -> int | None:
        """`robot` has sent all of a unison play but the frame that starts the motion, whose
        `write` it hands over; blocks until every robot the play is for has, and returns when
        its frame was written (monotonic ns), or None: write it yourself (stopping, a retry)."""


class Runner:
    """Plays one robot's plan over its link on the show clock (one of several, with `robot`;
    `choreo.run.ensemble` hands each run its show clock and its `cues`)."""

    def __init__(self, plan: Plan, link: Link, *, clock: RunClock | None = None,
                 listeners: Iterable[RunListener] = (), start: int = 0, on_abort: int | None = None,
                 stop: StopRequest | None = None, poll_s: float = POLL_S, robot: str | None = None,
                 live: Live | None = None, end: int | None = None) -> None:
        self.robot = robot
        self.cues: Cues | None = None  # given by each run (see `run`)
        self.live = live  # where GO cues wait for the operator (None: a show without them)
        self.plan = plan
        self.link = link
        self.clock = clock or link.clock
        self.listeners = list(listeners)
        self.start = start
        self.end = end  # where the plan stops (--loop's last step + 1), None: at its end
        self.on_abort = on_abort
        self.stop = stop or StopRequest()
        self.poll_s = poll_s
        self.on_idle: Callable[[], None] | None = None  # given by each run (see `run`)
        self.show: ShowClock = MachineShowClock(0.0)
        self._grid: BeatGrid | None = None  # the show clock, if its bars move (a Link session's tempo)
        self._last_play_done: float | None = None  # monotonic time the last restore was answered
        self._last_motion: int | None = None
        self._played = Played(1, 0.0)  # how the last play sequence went
        self._ready_s = float("-inf")  # show time the step before was done with (its frames answered)
        self._late = 0
        self._run = 0

    # -- the show ----------------------------------------------------------------------------

    def run(self, show: ShowClock | None = None, *, cues: Cues | None = None,
            on_idle: Callable[[], None] | None = None) -> RunResult:
        """Play the plan from `start`; LinkError on a fault, RunResult otherwise (done or aborted).

        `show`: the show clock, when several robots share it or the music keeps it (by default
        the machine's, with the show starting now). `cues`: where shared steps meet the other
        robots' runners (the ensemble's gates). `on_idle`: background work done while waiting
        (the log's writes, the clock samples). The run owns its wiring of the link: its retry
        reporter and its stop request are attached for the run and detached when it ends,
        however it ends, so a link run again (`--loop`) reports each failed try once."""
        steps = self.plan.steps[self.start:self.end]
        preroll = self.preroll_s()
        cursor = self._origin() - preroll  # a first play cued at the start may go out before it
        self.show = show if show is not None else MachineShowClock(self.clock.mono() - cursor)
        self._grid = self.show if isinstance(self.show, BeatGrid) else None  # asked once: isinstance is slow
        self.cues, self.on_idle = cues, on_idle
        with self.link.subscribe(_RetryReporter(self)), self.link.stopping_on(self.stop):
            try:
                for i, step in enumerate(steps):
                    cursor = self._next(step, cursor, steps[i + 1] if i + 1 < len(steps) else None)
            except Interrupted:
                return self._abort()
        return RunResult("done", self._run, self._late, self.show_time())

    def _next(self, step: PlannedStep, cursor: float, following: PlannedStep | None) -> float:
        """Run `step` if it is this robot's, meet the others after it (a shared step); the show
        time the next step may start at."""
        mine = step.is_for(self.robot) if self.robot is not None else True
        end = self._run_step(step, cursor, following) if mine else None
        # a step skipped passes where the robot is when it reaches it (now, or the step
        # before's end if that is later): the next step is timed from there, never from a cue
        # the robot was on its way to or waited at
        passed = max(cursor, self.show_time()) if mine and end is None else None
        if self.cues is not None and self.robot is not None:
            # a step for others takes, if none of them is left to do it, its planned time
            idle = passed if mine else cursor + step.expected_s
            through = self.cues.through(step.index, self.robot, end, idle)
            if through is None:
                raise Interrupted(self.stop.reason)
            return through
        return end if end is not None else passed if passed is not None else cursor

    def _origin(self) -> float:
        """Where the show clock starts: 0 for a whole show, so that a cue on the first step
        waits for its time like any other; with --from, the planned time of that step, so a
        rehearsal starts at once and its later cues keep their places."""
        if self.start and self.start < len(self.plan.steps):
            return self.plan.steps[self.start].planned_s
        return 0.0

    def preroll_s(self) -> float:
        """How long before show time 0 (or --from's step) the run must begin for its first play
        to go out early by its lead: a cue at the very start still lands on its time."""
        steps = self.plan.steps[self.start:]
        first = next((s for s in steps if self.robot is None or s.is_for(self.robot)), None)
        if first is None or first.kind is not StepKind.PLAY or first.at is None or first.motion is None:
            return 0.0
        return max(0.0, self.link.start_lead_s(first.motion) - (first.at - self._origin()))

    def _at(self, step: PlannedStep) -> float | None:
        """A step's cue in show time: as planned, or for a cue in bars on a clock whose tempo
        moves, where that bar falls now."""
        if step.at_beat is not None and self._grid is not None:
            return self._grid.at_beat(*step.at_beat)
        return step.at

    def _sleep_until(self, show_s: float) -> bool:
        return sleep_until_show(self.clock, self.show, show_s, self.stop, on_idle=self.on_idle)

    def show_time(self) -> float:
        return self.show.show_at(self.clock.mono())

    def _lead(self, step: PlannedStep | None) -> float:
        """How early a step's first frame goes out: a cued play's lead, so that the frame that
        starts its motion is written on the cue; 0 for anything else."""
        if step is None or step.kind is not StepKind.PLAY or step.at is None or step.motion is None:
            return 0.0
        if self.robot is not None and not step.is_for(self.robot):
            return 0.0
        return self.link.start_lead_s(step.motion)

    def _run_step(self, step: PlannedStep, cursor: float, following: PlannedStep | None = None) -> float | None:
        """Carry out `step` when it is due; the show time the next step may start at (None:
        the operator skipped it, and the robot passes it where it is)."""
        due = self._due(step, cursor)
        if due is None:
            self._pass(step, cursor)
            return None
        lead = self._lead(step)
        started = self.show_time()
        # A cue is measured against its own time: one the show has already overrun (a motion
        # ran long before it) starts at once and counts as late by the overrun.
        at = self._at(step)
        planned = at - lead if at is not None else due
        # An uncued step waits for the step before to be answered (a play's frames take the
        # wire's time after its start): it is late only by what came after that.
        late_ms = (started - (planned if at is not None else max(planned, self._ready_s))) * 1e3
        self._emit(StepEvent(step, "start", planned, started, self._now_ns(), late_ms, robot=self.robot))
        self._run += 1
        if late_ms > LATE_MS and step.kind is StepKind.PLAY:
            # Only a play's lateness shows on stage; a wait after a play always starts once the
            # play's frames are answered, and its end stays on the absolute schedule anyway.
            self._late += 1
            cue = f" (cue at {at:g} s)" if at is not None else ""
            self._log(WARNING, f"{step_ref(step)}{cue} started {late_ms:.1f} ms late")
        outcome = "failed"
        slip_ms = 0.0
        self._played = Played(1, 0.0)
        try:
            end = self._do(step, due + lead, self._lead(following))
            outcome = "ok"
            if step.kind is StepKind.PLAY:
                slip_ms = self._slip(step, planned, already_late=late_ms > LATE_MS)
            return end
        except WaitTimeout:
            outcome = "timeout"
            raise
        except (Interrupted, KeyboardInterrupt):
            outcome = "aborted"
            raise
        except LinkError as exc:
            self._log(ERROR, str(exc))
            raise
        finally:
            self._ready_s = self.show_time()
            start_s = self.show.show_at(self._played.started) if self._played.started is not None else None
            self._emit(StepEvent(step, "end", planned, self.show_time(), self._now_ns(), slip_ms, outcome,
                                 self.robot, start_s, lead * 1e3))

    def _due(self, step: PlannedStep, cursor: float) -> float | None:
        """Wait until `step` may start (a GO cue: its GO first; paused: the resume); when it was
        due (None: skipped, before or while it waited).

        A cued play goes out early by its lead, so that its start frame is written on the cue,
        or (a cue the show has overrun) when the step before ends: a `wait:` before a cued play
        ends its sleep that much early for it (`_run_step`'s `following`), so a cue on the very
        end of a wait is still met."""
        if self._skipping(step):
            return None
        if step.go:
            cursor = self._await_go(step, cursor)
        lead = self._lead(step)
        if step.at_beat is not None and self._grid is not None:
            # a cue in bars on a clock whose tempo moves: where it falls is read again as the sleep goes on
            grid, (bar, beat) = self._grid, step.at_beat

            def moving() -> float:
                return max(grid.at_beat(bar, beat), cursor) - lead
            if not self._sleep_to_cue(step, moving):
                return None
            due = moving()
        else:
            due = max(step.at, cursor) - lead if step.at is not None else cursor
            if not self._sleep_to_cue(step, due):
                return None
        if self.live is not None:  # not paused: one attribute read, and one set look-up for a cue
            if not self.live.await_running(self.stop, self.robot or SOLO):
                raise Interrupted(self.stop.reason)
            if self._skipping(step):
                return None
        return due

    def _sleep_to_cue(self, step: PlannedStep, due: float | Callable[[], float]) -> bool:
        """Sleep until `due`; False: `step` was skipped on the way. A skip given while the robot
        sleeps towards the cue ends the sleep (the Live wakes the dozers): the robot passes the
        cue then, not at its time. Only a stop interrupts: a skip undone between the sleep's
        look and the look after (the sleep ended for a skip no longer there) sleeps on, as the
        undo's answer promised the cue would run, where it played the abort motion."""
        while not sleep_until_show(self.clock, self.show, due, lambda: self.stop() or self._skipping(step),
                                   on_idle=self.on_idle):
            if self.stop():  # a stop stands once requested: the sleep ended for it, or it came since
                raise Interrupted(self.stop.reason)
            if self._skipping(step):
                return False
            # else the sleep ended for a skip undone since: sleep on
        return True

    def _skipping(self, step: PlannedStep) -> bool:
        """Is `step` a cue the operator skipped?"""
        return self.live is not None and step.cue is not None and self.live.skipped(self.robot or SOLO, step.index)

    def _pass(self, step: PlannedStep, cursor: float) -> None:
        """A skipped cue's step: one `skip` event (no start, no end), nothing sent."""
        self._log(INFO, f"{step_ref(step)} skipped (cue {step.cue}): not run")
        at = self._at(step)
        planned = at if at is not None else cursor
        self._emit(StepEvent(step, "skip", planned, self.show_time(), self._now_ns(), outcome="skipped",
                             robot=self.robot))

    def _await_go(self, step: PlannedStep, cursor: float) -> float:
        """A GO cue: reached when the step before ends, then held until the operator's GO; the
        show time the show goes on from (on the machine's clock, held: where it stopped)."""
        if not self._sleep_until(cursor):
            raise Interrupted(self.stop.reason)
        if self.live is None:
            raise ChoreoError(f"{step_ref(step)} waits for GO, but nothing can give it: run on a terminal "
                              "(the console) or with --osc PORT")
        self._log(INFO, f"{step_ref(step)} waits for GO")
        went = self.live.await_go(step, self.robot or SOLO, cursor, self.stop,
                                  shared=self.cues is not None or self.robot is None)
        if went is None:
            raise Interrupted(self.stop.reason)
        return max(cursor, went)

    def _slip(self, step: PlannedStep, planned: float, already_late: bool) -> float:
        """How late the motion really started: retries delay the sequence that worked.

        Reported (and counted late, once) when the delay comes from retries; the end event
        carries it so the log says when the motion began, not only when the step did.
        """
        played = self._played
        slip_ms = (self.show.show_at(played.began) - planned) * 1e3
        if played.tries > 1 and slip_ms > LATE_MS and not already_late:
            self._late += 1
            self._log(WARNING, f"{step_ref(step)}: motion {step.motion} started {slip_ms:.1f} ms "
                               f"late ({played.tries} tries)")
        return slip_ms

    def _do(self, step: PlannedStep, due: float, lead_after: float = 0.0) -> float:
        """Carry out a step; returns when the next step is due on the show clock (a wait wakes
        `lead_after` before it: the next step's frames go out that early)."""
        tag = Tag(step.index, step.label)
        if step.kind is StepKind.PLAY:
            assert step.motion is not None
            self._played = self._play(step.motion, tag, step_ref(step), self._together(step))
            self._last_play_done = self.clock.mono()
            self._last_motion = step.motion
            return due
        if step.kind is StepKind.WAIT:
            end = due + (step.seconds or 0.0)
            if not self._sleep_until(end - lead_after):
                raise Interrupted(self.stop.reason)
            return end
        return self.show.show_at(self._wait_done(step, tag))

    def _together(self, step: PlannedStep) -> Callable[[Callable[[], None]], int | None] | None:
        """With other robots on a unison play: hand the frame that starts the motion to the
        gate, which writes every robot's back to back once all are ready, so that their motions
        start at one instant (the frames before it take each robot's own reply times)."""
        if self.cues is None or self.robot is None:
            return None
        cues, robot = self.cues, self.robot
        return lambda write: cues.armed(step, robot, write)

    def _play(self, motion: int, tag: Tag, where: str,
              before_start: Callable[[Callable[[], None]], int | None] | None = None) -> Played:
        """One play sequence; a start whose reply was lost but which the board shows started
        (running or over) is a play done (never sent twice), said in a warning."""
        played = self.link.play(motion, tag, before_start)
        if played.recovered:
            self._log(WARNING, f"{where}: {played.recovered}")
        return played

    def _wait_done(self, step: PlannedStep, tag: Tag) -> float:
        """Poll the status every `poll_s` until the motion is over; the monotonic time it was seen."""
        started = self.clock.mono()
        timeout = step.seconds if step.seconds is not None else 60.0
        first = self._last_play_done + self.poll_s if self._last_play_done is not None else started
        due = max(first, started)
        while True:
            if not self.clock.sleep_until(due, self.stop, on_idle=self.on_idle):
                raise Interrupted(self.stop.reason)
            reply = self.link.query_status(tag)
            if not reply.executing:
                return self.clock.mono()
            # The next poll is 50 ms after this one really went out, never sooner.
            due = self.link.last_tx_mono + self.poll_s
            if due - started > timeout:
                motion = step.motion if step.motion is not None else self._last_motion
                raise WaitTimeout(
                    f"port {self.link.name}: {step_ref(step)}: motion {motion} still "
                    f"executing after {timeout:g} s (wait: done timeout): give the step a longer "
                    f"`timeout:`, or check that the motion ends")

    # -- stopping ----------------------------------------------------------------------------

    def _abort(self) -> RunResult:
        """No more show frames; play the show's abort motion if it has one."""
        self._log(WARNING, f"show {self.stop.reason} at {self.show_time():.3f} s")
        if self.stop.panicked and self.on_abort is None and self.link.moved:
            self._halt()
        if self.on_abort is not None and self.link.moved:  # a robot the show never moved stays as it is
            self._log(INFO, f"playing abort motion {self.on_abort}")
            try:
                with self.link.stopping_on(never):  # the abort motion runs to its end
                    self._play(self.on_abort, Tag(None, ABORT_LABEL), ABORT_LABEL)
            except LinkError as exc:
                self._log(ERROR, f"abort motion {self.on_abort} failed: {exc}")
                raise
        return RunResult("aborted", self._run, self._late, self.show_time())

    def _halt(self) -> None:
        """Panic on a robot without an abort motion: the stop frame halts the motion it plays."""
        self._log(INFO, "panic: stop frame")
        try:
            with self.link.stopping_on(never):  # the stop frame goes out whatever was asked
                self.link.halt(Tag(None, ABORT_LABEL))
        except LinkError as exc:
            self._log(ERROR, f"panic stop frame failed: {exc}")
            raise

    # -- reporting ---------------------------------------------------------------------------

    def _now_ns(self) -> int:
        return self.clock.wall_ns()

    def _emit(self, event: StepEvent) -> None:
        for listener in self.listeners:
            listener.on_step(event)

    def _log(self, level: int, message: str) -> None:
        if self.robot is not None:
            message = f"robot {self.robot}: {message}"
        for listener in self.listeners:
            listener.on_log(level, message, self._now_ns())


class _RetryReporter:
    """Turns each failed try the link reports into a warning line in the log."""

    def __init__(self, runner: Runner) -> None:
        self.runner = runner

    def on_tx(self, event: TxEvent) -> None:
        pass

    def on_rx(self, event: RxEvent) -> None:
        if not event.reply.ok:
            where = f"{event.tag}: " if event.tag and event.tag.step is not None else ""
            self.runner._log(WARNING, f"{where}{event.reply.describe()} to '{event.frame}' "
                                      f"({event.frame.kind.value} frame, seq {event.seq})")
