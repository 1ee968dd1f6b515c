"""Running a show live: the operator's commands (GO, a cue's GO, skip, the playhead, pause and
resume, panic, start, stop), from whichever source gives them (the console's keys, OSC), and the
GO cues that wait for them.

One `Live` a run, shared by every robot's runner and every source: a command is answered the
same way from the keyboard as from QLab, and every command, accepted or refused, is reported to
the listeners (the log records who pressed what and when). Sources never touch the runners:
they call `command`, which sets state the runners read (a GO cue released, a cue skipped, the
pause, the stop request).

The cue list (`choreo.show.cues`) has a playhead, as QLab's has: the cue a GO fires. By default
it is "auto", the earliest GO cue waiting, else the next GO cue ahead; once the operator moves
it, it stays on that cue until the cue runs or is skipped, then it is auto again. Live hears the
run's steps (`on_step`), so it knows which cues are ahead, waiting, running, done or skipped.

The show clock holds while a GO cue waits (on the machine's clock: the steps after it are timed
from the GO, as if it came at once); on the music's clock it cannot hold, so the music plays on
and the step is reported against it. A pause stands either clock still (the music pauses with
it); no step starts while paused, a step under way finishes, and the steps after the resume are
timed from it.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, NamedTuple

from choreo.clock import HELD, PAUSED, RUNNING, PausableShowClock, ShowClock
from choreo.sync.clock import LinkShowClock
from choreo.events import (PANIC, STOPPED, Answer, Command, CommandEvent, CommandListener, GoCue, Listeners,
                           StepEvent, StopRequest, Subscription, WaitingListener)
from choreo.live.limits import LIMITS, Held, Limits, ReportGate
from choreo.log.format import UNLOGGED
from choreo.show.cues import Cue, CueList, CueNotFound, quoted
from choreo.show.model import LINK, SOLO, PlannedStep
from choreo.textfit import fit

if TYPE_CHECKING:
    from choreo.live.status import ShowStatus

LOCKOUT_S = 0.5  # a second GO this soon after one is taken for a double press, and refused
NO_CUES = CueList()  # a show run without its cue list (GO still fires the earliest GO cue waiting)
RESUME_FIRST = "paused: resume first (p or /choreo/resume)"

# a cue's state (`Live.cue_state`)
AHEAD, WAITING, ACTIVE, DONE, SKIPPED = "ahead", "waiting", "running", "done", "skipped"
TOLD_WITHIN_S = 2.0  # the run's end waits this long at most for the commands under way to be told
NOT_STARTED = "nothing waits for GO now (the show waits for its start: /choreo/start)"
OPENING = "refused: the show is still opening (its log is not recording yet): send it again in a moment"


class _Stand(NamedTuple):
    """Where the machine's show clock is: its zero, and the show times it stands at (a GO cue's
    hold, the operator's pause; None: not standing for it). One tuple, swapped whole, so a
    runner reading it never sees half a change."""

    zero: float
    hold: float | None
    pause: float | None

    @property
    def at(self) -> float | None:
        """The show time the clock stands at: the earlier of the two."""
        if self.hold is None:
            return self.pause
        return self.hold if self.pause is None else min(self.hold, self.pause)


class HoldingShowClock:
    """The machine's show clock, which stops at a GO cue's time while the cue waits, and where
    the operator pauses it: show time stands still there, and every runner's later due times
    move on with it. Times up to that point keep their places (another robot still on its way to
    the same cue gets there). A hold and a pause may overlap: the clock stands at the earlier,
    and releasing one takes out of the show only the time it really stood. A runner asleep
    towards a later due time (another track's cue) dozes: `wake` (its time source's `notify`)
    ends the doze when the clock goes on, so it sleeps again towards the due time as moved, not
    to the end of a sleep slice. A `PausableShowClock`."""

    def __init__(self, zero: float, mono: Callable[[], float], wake: Callable[[], None] = lambda: None) -> None:
        self._stand = _Stand(zero, None, None)
        self._mono = mono
        self._wake = wake
        self._lock = threading.Lock()  # changes only; readers take `_stand` whole

    @property
    def held(self) -> bool:
        """A GO cue holds it (paused or not)."""
        return self._stand.hold is not None

    @property
    def state(self) -> str:
        stand = self._stand
        return PAUSED if stand.pause is not None else HELD if stand.hold is not None else RUNNING

    def hold_at(self, show_s: float) -> None:
        """Stop the clock when it reaches `show_s` (at once if it has: where it is now, never
        back to a time it has shown already)."""
        with self._lock:
            stand = self._stand
            at = max(show_s, self._show(stand, self._mono()))
            self._stand = stand._replace(hold=at if stand.hold is None else min(stand.hold, at))

    def release(self) -> None:
        """A GO: go on from the held time (still standing if paused); the time spent holding is
        taken out of the show."""
        self._go_on(hold=True)

    def pause(self) -> float:
        with self._lock:
            stand = self._stand
            if stand.pause is None:
                stand = self._stand = stand._replace(pause=self._show(stand, self._mono()))
            assert stand.pause is not None
            return stand.pause

    def resume(self) -> None:
        """Go on from the pause (still held while a GO cue waits)."""
        self._go_on(hold=False)

    def _go_on(self, hold: bool) -> None:
        with self._lock:
            stand = self._stand
            if (stand.hold if hold else stand.pause) is None:
                return
            now = self._mono()
            stood = self._show(stand, now)
            zero = now - stood if now - stand.zero > stood else stand.zero
            self._stand = _Stand(zero, None if hold else stand.hold, stand.pause if hold else None)
        self._wake()

    def wake(self) -> None:
        """Every runner dozing towards a due time looks again now: a stop or a panic given
        while the clock stands ends the others' dozes at once, not a sleep slice later."""
        self._wake()

    def mono_at(self, show_s: float) -> float:
        stand = self._stand
        at = stand.at
        if at is not None and show_s > at + 1e-9:
            return float("inf")
        return stand.zero + show_s

    def show_at(self, mono: float) -> float:
        return self._show(self._stand, mono)

    @staticmethod
    def _show(stand: _Stand, mono: float) -> float:
        at = stand.at
        show_s = mono - stand.zero
        return show_s if at is None else min(show_s, at)


def _order(cue: GoCue) -> tuple[float, float, int]:
    """GO cues waiting, the earliest first: by when they were reached, then as planned."""
    return cue.reached_s, cue.step.planned_s, cue.step.index


class Live:
    """A running show's controls; see the module's docstring."""

    def __init__(self, stop: StopRequest, *, cues: CueList = NO_CUES, status: ShowStatus | None = None,
                 clock: str = "machine", wait_start: bool = False, lockout_s: float = LOCKOUT_S,
                 now: Callable[[], float] = time.monotonic, wall_ns: Callable[[], int] = time.time_ns,
                 limits: Limits = LIMITS, opening: bool = False) -> None:
        self.stop = stop
        self.cues = cues
        self.status_of_robots = status  # each robot's row for `status()` (None: none given)
        self.clock = clock  # what keeps the show clock: machine | music (`status()`, before it starts too)
        self.lockout_s = lockout_s
        self.listeners: Listeners[CommandListener] = Listeners()  # attached through `subscribe`
        self.show: ShowClock | None = None  # the pass's show clock (`use_clock`), once the show starts
        self._pausable: PausableShowClock | None = None  # the same, if it can pause
        self._wake_runners: Callable[[], None] | None = None  # ends the runners' dozes (`use_clock`)
        self._now = now
        self._wall_ns = wall_ns
        self._changed = threading.Condition()
        self._pausing = threading.Lock()  # one pause or resume at a time, flag and clock together
        self._clock_changes: Listeners[Callable[[], None]] = Listeners()
        self._started = not wait_start
        self._paused = False
        self._waiting: dict[object, GoCue] = {}  # the GO cues robots wait at, by `_key`
        self._released: set[object] = set()  # GO cues already given their GO
        self._last_go: float | None = None
        self._cue_at: dict[tuple[str, int], Cue] = {key: cue for cue in cues for key in cue.steps}
        self._marks: dict[tuple[str, int], str] = {}  # a cue's step: its last event (start, end, skip)
        self._gone: set[object] = set()  # GO cues given their GO this pass, by key (running until their steps say)
        self._made: dict[object, Cue] = {}  # cues made up for GO cues a show without its cue list waits at
        self._skips: dict[str, Cue] = {}  # cues to skip, by number
        self._skip_steps: frozenset[tuple[str, int]] = frozenset()  # their steps; swapped whole, read without the lock
        self._moved: Cue | None = None  # the playhead where the operator put it (None: auto)
        self._ahead_from = 0  # no GO cue before this position of the list is ahead (`_next_ahead`)
        self._timed_from = 0  # no timed cue before this position is open (`_timed_open`): reset with it
        self._out: frozenset[str] = frozenset()  # cues outside the run's section (--from, --loop)
        self._paused_robots: set[str] = set()  # runners the pause keeps from their next step
        self._reports = ReportGate(limits, now)  # what of the commands the listeners hear
        self._summing = threading.RLock()  # a summary is told whole before `close` returns
        self._over = False  # the run is over (`close`): no command is taken any more
        # `opening`: until the log hears the commands (`recording`), only a panic or a stop is
        # carried out, and told to the log once it does: every command carried out is logged
        self._opening = opening
        self._opened = threading.Lock()
        self._unheard: list[tuple[Command, Answer, int]] = []  # each with when it was carried out
        self._handlers = self._handlers_by_name()
        # commands carried out but maybe not yet told: the log's subscription ends after them
        self._under_way = 0
        self._told = threading.Condition()

    def subscribe(self, listener: CommandListener) -> Subscription:
        """Tell `listener` every command and its answer (and, if it is a `WaitingListener`,
        every GO cue reached) until the subscription closes; whoever subscribes closes it."""
        return self.listeners.subscribe(listener)

    def on_clock_change(self, listener: Callable[[], None]) -> Subscription:
        """Call `listener` after each change of the show clock's state that goes through here (a
        GO cue holds it, a GO releases it, a pause, a resume): the log samples the clock then."""
        return self._clock_changes.subscribe(listener)

    def use_clock(self, show: ShowClock, wake: Callable[[], None] | None = None) -> None:
        """The show clock of the pass now starting: GO cues hold it, a pause stands it still
        (one given before it started too), commands are timed on it. `wake` (the run's time
        source's `notify`) ends the runners' dozes towards a cue when a stop or panic comes,
        on any clock (the music's too), not a sleep slice later."""
        with self._pausing:
            self.show = show
            self._wake_runners = wake
            self._pausable = show if isinstance(show, PausableShowClock) else None  # asked once: it is slow
            if self._paused and self._pausable is not None:
                self._pausable.pause()

    def use_section(self, starts: Mapping[str, int], ends: Mapping[str, int]) -> None:
        """The steps this run plays, robot by robot (--from, --loop): a cue outside them will
        not run, and the playhead never stands on it."""
        def outside(robot: str, index: int) -> bool:
            return index < starts.get(robot, 0) or (robot in ends and index >= ends[robot])

        with self._changed:
            self._out = frozenset(cue.number for cue in self.cues if all(outside(*key) for key in cue.steps))
            self._ahead_from = self._timed_from = 0

    @property
    def panicked(self) -> bool:
        """The show was stopped by a panic (not by stop, Ctrl-C or a fault)."""
        return self.stop.panicked

    @property
    def started(self) -> bool:
        """False until the show may start (with --wait-start, until /choreo/start or the
        console's Space or Enter; /choreo/go does not start it)."""
        return self._started

    @property
    def paused(self) -> bool:
        return self._paused

    @property
    def state(self) -> str:
        """opening (the log not recording yet) | waiting_start | running | held (a GO cue
        waits) | paused | stopping | over."""
        if self._over:
            return "over"
        if self.stop():
            return "stopping"
        if self._opening:
            return "opening"
        if not self._started:
            return "waiting_start"
        if self._paused:
            return "paused"
        return "held" if self._waiting else "running"

    @property
    def paused_robots(self) -> tuple[str, ...]:
        """The robots whose next step is due and waits for the resume (a robot asleep towards a
        later due time is not among them: the clock it sleeps on stands still)."""
        with self._changed:
            return tuple(sorted(self._paused_robots))

    # -- what the show asks ------------------------------------------------------------------

    def await_start(self) -> bool:
        """Block until `/choreo/start` (with --wait-start); False if stopped first."""
        with self._changed:
            while not self._started:
                if self.stop():
                    return False
                self._changed.wait(0.05)
        return True

    def await_running(self, should_stop: Callable[[], bool], robot: str = SOLO) -> bool:
        """Before a step starts: block while the show is paused; False if stopped meanwhile.
        Not paused, it returns at once without a lock (the runner's path to a cue's frame)."""
        if not self._paused:
            return True
        with self._changed:
            self._paused_robots.add(robot)
            try:
                while self._paused:
                    if should_stop():
                        return False
                    self._changed.wait(0.05)
            finally:
                self._paused_robots.discard(robot)
        return not should_stop()

    def skipped(self, robot: str, index: int) -> bool:
        """Is `robot`'s step `index` a cue's the operator skipped (it must not run)? Lock-free."""
        return (robot, index) in self._skip_steps

    def await_go(self, step: PlannedStep, robot: str, reached_s: float, should_stop: Callable[[], bool],
                 shared: bool = True) -> float | None:
        """`robot` has reached GO cue `step` (`shared`: a step of shared `steps:`, which every
        robot it is for waits at, released by one GO; else its own track's): hold the machine's
        show clock and block until a GO releases it (or a skip: `skipped` says which). Returns
        the show time it goes on from (None: stopped while waiting). `reached_s`: the show time
        the robot reached it at."""
        show = self.show
        key = step.index if shared else (robot, step.index)
        with self._changed:
            # the others were given their GO as this robot arrived; or the cue was skipped since
            # the runner looked (it passes it, as it would have): neither waits nor holds the clock
            if key in self._released or self.skipped(robot, step.index):
                return show.show_at(self._now()) if show is not None else step.planned_s
            cue = self._waiting.get(key)
            new = cue is None
            if cue is None:
                cue = self._waiting[key] = GoCue(step, set(), reached_s, key=key)
            cue.reached_by(robot)
            if isinstance(show, HoldingShowClock):
                show.hold_at(reached_s)
            self._changed.notify_all()
        if new:
            self._announce(cue, show)
        with self._changed:
            while not cue.released:
                if should_stop():
                    return None
                self._changed.wait(0.05)
        return show.show_at(self._now()) if show is not None else cue.reached_s

    def _announce(self, cue: GoCue, show: ShowClock | None) -> None:
        """A GO cue newly waiting: the log marks where the clock began to hold, its listeners
        hear it, and only then does `waiting` show it (outside the lock, then under it)."""
        if isinstance(show, HoldingShowClock):
            self._clock_changed()
        for listener in self.listeners:
            if isinstance(listener, WaitingListener):  # optional: the console, OSC notify, progress lines
                listener.on_waiting(cue)
        with self._changed:
            cue.tell()

    def new_pass(self) -> None:
        """A --loop pass begins: its GO cues wait for a GO of their own again, its cues are
        ahead again (a skip not yet reached still stands)."""
        with self._changed:
            self._released.clear()
            self._gone.clear()
            passed = {number for number, cue in self._skips.items() if self._passed(cue)}
            self._marks.clear()
            self._moved = None
            self._ahead_from = self._timed_from = 0
            for number in passed:
                del self._skips[number]
            self._skips_changed()

    # -- what the run tells (a RunListener) --------------------------------------------------

    def on_step(self, event: StepEvent) -> None:
        """A cue's step started, ended or was skipped: the cue's state follows. Other steps
        cost one attribute read on the runner's path; a cue's, one dictionary store without the
        lock (atomic, and read under it): a cue's start comes just before its first frame, which
        must not wait behind a command's answer."""
        if event.step.cue is not None:
            self._marks[(event.robot or SOLO, event.step.index)] = event.event

    def on_log(self, level: int, message: str, time_ns: int) -> None:
        """Log lines say nothing the controls act on."""

    # -- the cue list ------------------------------------------------------------------------

    @property
    def waiting(self) -> list[GoCue]:
        """The GO cues waiting now whose hold the log has (a GO does not wait for that: it
        releases any cue waiting), the earliest first. Whoever watches the show sees a cue wait
        once the log says so: an operator (or a test on virtual time) acting on it acts after."""
        with self._changed:
            return [cue for cue in self._in_order() if cue.told]

    def _in_order(self) -> list[GoCue]:
        """The lock is held. A cue given its GO leaves `_waiting` at once (`_release`)."""
        return sorted(self._waiting.values(), key=_order)

    def cue_state(self, cue: Cue) -> str:
        """ahead | waiting | running | done | skipped (a cue outside the run's section: done)."""
        with self._changed:
            return self._state_of(cue)

    def cue_states(self) -> dict[Cue, str]:
        """Every cue's state, under the lock once (the console's whole list at each redraw)."""
        with self._changed:
            return {cue: self._state_of(cue) for cue in self.cues}

    @property
    def playhead(self) -> Cue | None:
        """The cue a GO fires: where the operator put it, else the earliest GO cue waiting, else
        the next GO cue ahead (None: no GO cue ahead)."""
        with self._changed:
            return self._playhead()

    def _state_of(self, cue: Cue) -> str:
        """The lock is held."""
        if cue.number in self._out:
            return DONE
        if self._waiting_for(cue) is not None:
            return WAITING
        marks = [self._marks.get(key) for key in cue.steps]
        if cue.number in self._skips or "skip" in marks:
            return SKIPPED
        if marks and all(mark == "end" for mark in marks):
            return DONE
        return ACTIVE if any(marks) or self._gone_on(cue) else AHEAD

    def _gone_on(self, cue: Cue) -> bool:
        """Was `cue` given its GO this pass (its steps may not have started yet)? The lock is held."""
        gone = self._gone
        return bool(gone) and any(key in gone or key[1] in gone for key in cue.steps)

    def _open(self, cue: Cue) -> bool:
        """Not run yet: the playhead may stand on it (a skipped cue no robot has passed too:
        skipping it again undoes the skip). The lock is held."""
        state = self._state_of(cue)
        return state in (AHEAD, WAITING) or (state == SKIPPED and not self._passed(cue))

    def _passed(self, cue: Cue) -> bool:
        return any(self._marks.get(key) for key in cue.steps)

    def _waiting_for(self, cue: Cue) -> GoCue | None:
        """The GO cue waiting that is `cue` (the lock is held)."""
        for waiting in self._waiting.values():
            if any(cue.starts(robot, waiting.step.index) for robot in waiting.robots):
                return waiting
        return None

    def _cue_of(self, waiting: GoCue) -> Cue:
        """The cue of the list a waiting GO cue is (a show run without its list: one made up)."""
        for robot in waiting.robots:
            cue = self._cue_at.get((robot, waiting.step.index))
            if cue is not None:
                return cue
        made = self._made.get(waiting.key)
        if made is None or len(made.robots) != len(waiting.robots):
            step, robots = waiting.step, tuple(sorted(waiting.robots))
            made = self._made[waiting.key] = Cue(step.cue or f"step {step.index}", step.label, robots,
                                                 step.planned_s, True, steps=tuple((r, step.index) for r in robots))
        return made

    def _playhead(self) -> Cue | None:
        """The lock is held."""
        if self._moved is not None:
            if self._open(self._moved):
                return self._moved
            self._moved = None  # its cue ran or was skipped: auto again
        waiting = self._in_order()
        if waiting:
            return self._cue_of(waiting[0])
        return self._next_ahead()

    def _next_ahead(self) -> Cue | None:
        """The first GO cue ahead, looked for from where the last look found one: a cue once
        past that (waiting, running, done, skipped) is ahead again only with a new pass, a new
        section or a skip undone, which look from the start again. So the console's redraw,
        `/choreo/status` and a GO's answer cost a few cues, not a 10,000-cue walk under the lock
        a released runner needs. The lock is held."""
        cues = self.cues.cues
        for at in range(self._ahead_from, len(cues)):
            cue = cues[at]
            if cue.go and self._state_of(cue) == AHEAD:
                self._ahead_from = at
                return cue
        self._ahead_from = len(cues)
        return None

    def _skips_changed(self) -> None:
        """The lock is held."""
        self._skip_steps = frozenset(key for cue in self._skips.values() for key in cue.steps)

    def _data(self, cue: Cue) -> dict[str, Any]:
        """A cue command's answer data (the lock is held)."""
        playhead = self._playhead()
        return {"cue": cue.number, "label": cue.label, "playhead": playhead.number if playhead else None}

    def status(self) -> dict[str, Any]:
        """The show now, JSON-ready (the `/choreo/status` reply's data)."""
        show = self.show
        with self._changed:
            playhead = self._playhead()
            waiting = [{**self._cue_of(w).to_json(), "robots": sorted(w.robots), "reached_s": round(w.reached_s, 3)}
                       for w in self._in_order()]
        rows = self.status_of_robots.robots(self.skipped) if self.status_of_robots is not None else ()
        return {"state": self.state,
                "show_s": round(show.show_at(self._now()), 3) if show is not None else None,
                "clock": self.clock,
                "playhead": playhead.to_json() if playhead is not None else None,
                "waiting": waiting, "paused": self._paused,
                "robots": {row.robot: row.to_json() for row in rows},
                **({"link": link_status(show, self._now())} if isinstance(show, LinkShowClock) else {})}

    # -- what the operator says --------------------------------------------------------------

    def command(self, command: Command) -> Answer:
        """Carry out one command from any source, and tell the listeners. Once the show is
        stopping (or over) every command is refused: a GO then releases nothing, whatever still
        waits, and a stop or panic cannot change the stop under way."""
        with self._told:
            self._under_way += 1
        try:
            return self._carry_out(command)
        finally:
            with self._told:
                self._under_way -= 1
                self._told.notify_all()

    def _carry_out(self, command: Command) -> Answer:
        handler = self._handlers.get(command.name)
        if self._opening:
            with self._opened:
                if self._opening:
                    return self._while_opening(command, handler)
        refusal = self._refusal()
        if refusal is not None:
            answer = refusal
        else:
            answer = handler(command) if handler else Answer("error", f"unknown command {command.name!r}")
        self.report(command, answer)
        return answer

    def _while_opening(self, command: Command, handler: Callable[[Command], Answer] | None) -> Answer:
        """Before the log hears the commands: a panic or a stop is carried out (and kept for
        the log), anything else refused (`_opened` is held)."""
        if handler is not None and command.name in ("panic", "stop") and self._refusal() is None:
            answer = handler(command)
            self._unheard.append((command, answer, self._wall_ns()))
        else:
            answer = self._refusal() or Answer("error", OPENING)
        self.report(command, answer)
        return answer

    def recording(self, log: CommandListener | None) -> Subscription:
        """The log hears the commands from now (None: the run keeps none) until the subscription
        closes: commands are taken from here on, and `log` is told first the panic or stop
        carried out before, at the time each was. Subscribed here, under the lock a command
        given while opening takes: subscribed apart, a panic between the two was told it twice
        (as it happened, then as one held). Closed (the run's end), it first waits for the
        commands under way to be told: a GO lets the runners go on the moment it is carried out,
        and a show that ends a few milliseconds after its last GO cue closed its log before a
        GO's thread (put off by a loaded machine, or a slow listener told before the log) told
        it: the log lost the GO."""
        with self._opened:
            heard = self.subscribe(log) if log is not None else Subscription(lambda: None)
            subscription = Subscription(lambda: self._after_commands_told(heard.close))
            unheard, self._unheard = self._unheard, []
            for command, answer, wall_ns in unheard:
                if log is not None:
                    log.on_command(CommandEvent(command, answer, wall_ns, None))
            self._opening = False
        return subscription

    def _after_commands_told(self, then: Callable[[], None]) -> None:
        """`then`, once no command is under way (or after `TOLD_WITHIN_S`: a listener stuck)."""
        with self._told:
            self._told.wait_for(lambda: self._under_way == 0, TOLD_WITHIN_S)
        then()

    def _handlers_by_name(self) -> dict[str, Callable[[Command], Answer]]:
        return {"go": self._go, "cue_go": self._cue_go, "skip": self._skip, "playhead": self._put_playhead,
                "playhead_next": self._playhead_next, "playhead_previous": self._playhead_previous,
                "pause": self._pause, "resume": self._resume,
                "panic": self._panic, "start": self._start, "stop": self._stop}

    def _refusal(self) -> Answer | None:
        if self._over:
            return Answer("error", "refused: the show is over")
        if self.stop():
            return Answer("error", f"refused: the show is stopping ({self.stop.reason})")
        return None

    def report(self, command: Command, answer: Answer) -> None:
        """Tell the listeners of a command and its answer: one carried out here, or one a
        source refused itself (a sender not allowed, an address it does not know). Refused
        ones only within the limits (`choreo.live.limits.ReportGate`): the rest are counted and told
        later as one `unlogged` summary."""
        passes = self._reports.passes(command.name, command.source, answer.ok)
        self.flush_reports()  # the summary of what came before, first
        if passes:
            self._tell(command, answer)

    def count(self, name: str, source: str, n: int = 1) -> None:
        """`n` more `name` from `source` refused without a word (packets or a bundle's messages
        over their sender's rate, not read): only counted, for the next summary (the ticker's)."""
        self._reports.hold(name, source, n)

    def flush_reports(self, force: bool = False) -> None:
        """Tell the listeners the commands held back since the last summary, if it is time
        (called on every command, and by a ticker while the show runs; `force`: at the end)."""
        with self._summing:
            held = self._reports.due(force)
            if held is not None:
                self._tell(*summary_of(held))

    def _tell(self, command: Command, answer: Answer) -> None:
        show = self.show
        event = CommandEvent(command, answer, self._wall_ns(), show.show_at(self._now()) if show is not None else None)
        for listener in self.listeners:
            listener.on_command(event)

    def close(self) -> None:
        """The run is over: later commands are refused, and what was held back is told."""
        self._over = True
        self._wake()
        self.flush_reports(force=True)

    # -- GO ----------------------------------------------------------------------------------

    def _go(self, command: Command) -> Answer:
        with self._changed:
            now = self._now()
            if self._last_go is not None and now - self._last_go < self.lockout_s:
                return Answer("error", f"GO ignored: {now - self._last_go:.2f} s after the last one "
                              f"(a double press? GOs {self.lockout_s:g} s apart at least)")
            if self._paused:
                return Answer("error", RESUME_FIRST)
            waiting, aside = self._under_playhead()
            if waiting is None:
                return Answer("error", self._why_not(self._playhead()))
            self._last_go = now
            self._release(waiting)
        # the answer, and the sample of the clock going on, once the runners are free to go
        self._clock_changed()
        kind = "a timed" if aside is not None and not aside.go else "a skipped"
        return self._answer("GO", waiting, f" (the playhead is on {aside.name}, {kind} cue: GO fired the earliest "
                                           "cue waiting)" if aside is not None else "")

    def _under_playhead(self) -> tuple[GoCue | None, Cue | None]:
        """The GO cue waiting under the playhead, if one is: the runner's path to a GO's first
        frame, so the auto playhead's (the earliest waiting) is found without the cue list. A
        playhead moved onto a cue that takes no GO (timed, or skipped) never leaves GO dead
        while a cue waits: GO fires the earliest waiting, and that cue is returned to say so."""
        moved = self._moved
        if moved is not None and self._open(moved):
            if moved.go and moved.number not in self._skips:
                return self._waiting_for(moved), None
            waiting = min(self._waiting.values(), key=_order, default=None)
            return waiting, moved if waiting is not None else None
        self._moved = None
        return min(self._waiting.values(), key=_order, default=None), None

    def _why_not(self, cue: Cue | None) -> str:
        """Why a GO fires nothing: the playhead's cue is not reached yet, or timed (the lock is held)."""
        if not self._started:
            return NOT_STARTED
        if cue is None:
            return "nothing waits for GO now"
        return self._not_waiting(cue)

    def _not_waiting(self, cue: Cue, named: bool = False) -> str:
        """Why `cue` takes no GO now, in the operator's words (the lock is held); `named`: the
        cue's own GO (by number or label), where the playhead has no part."""
        state = self._state_of(cue)
        if not cue.go:
            return f"{cue.name} is a timed cue (at {cue.planned_s:.3f} s): nothing to GO" + \
                ("" if named else "; move the playhead")
        if state == SKIPPED:
            return f"{cue.name} is skipped (skip it again to undo)"
        if state in (ACTIVE, DONE):
            return f"{cue.name} has had its GO already"
        others = ", ".join(self._cue_of(w).name for w in self._in_order())
        waits = f"; waiting: {others}" + ("" if named else " (move the playhead to it)") if others else ""
        return f"nothing waits for GO now: {cue.name} is not reached yet (planned at {cue.planned_s:.3f} s){waits}"

    def _cue_go(self, command: Command) -> Answer:
        with self._changed:
            if self._paused:
                return Answer("error", RESUME_FIRST)
            found = self._find(command.label)
            if isinstance(found, Answer):
                return found
            waiting = self._waiting_for(found)
            if waiting is None:
                why = self._not_waiting(found, named=True) if self._started else NOT_STARTED
                return Answer("error", why, self._data(found))
            self._last_go = self._now()
            self._release(waiting)
        self._clock_changed()
        return self._answer("GO", waiting)

    def _find(self, ref: str | None) -> Cue | Answer:
        """The cue `ref` names, or the answer refusing it (the lock is held). A show run without
        its cue list finds the GO cues waiting by label or number."""
        if not ref:
            return Answer("error", "name a cue: its number or label")
        try:
            return self.cues.find(ref)
        except CueNotFound as exc:
            for waiting in self._waiting.values():
                if ref in (waiting.step.label, waiting.step.cue):
                    return self._cue_of(waiting)
            if not self.cues:
                at = ", ".join(repr(w.name) for w in self._in_order()) or "no cue"
                return Answer("error", f"cue {quoted(ref)} is not waiting for GO (waiting: {at})")
            return Answer("error", fit(str(exc), 200))

    def _answer(self, verb: str, waiting: GoCue, note: str = "") -> Answer:
        with self._changed:
            cue = self._cue_of(waiting)
            return Answer("ok", f"{verb}: {cue.name}{note}", self._data(cue))

    def _release(self, waiting: GoCue, go: bool = True) -> None:
        """Let the robots waiting at `waiting` go on (`go`: given its GO, else skipped); the
        machine's clock goes on from where it held (the lock is held). A GO is the operator's
        choice to go on: another cue still waiting keeps its robots waiting but no longer holds
        the clock."""
        waiting.release()
        del self._waiting[waiting.key]
        self._released.add(waiting.key)
        if isinstance(self.show, HoldingShowClock):
            self.show.release()
        self._changed.notify_all()
        if go:
            self._gone.add(waiting.key)

    # -- skip and the playhead ---------------------------------------------------------------

    def _skip(self, command: Command) -> Answer:
        """The playhead's cue (or the one named) will not run; again on a cue no robot has
        passed yet, the skip is undone."""
        with self._changed:
            found = self._find(command.label) if command.label is not None else self._playhead()
            if found is None:
                return Answer("error", self._nothing_to_skip())
            if isinstance(found, Answer):
                return found
            state = self._state_of(found)
            if state in (ACTIVE, DONE) or (state == SKIPPED and self._passed(found)):
                return Answer("error", f"{self._gone_by(found, state)}: nothing to skip", self._data(found))
            if state == SKIPPED:
                del self._skips[found.number]
                self._skips_changed()
                self._ahead_from = self._timed_from = 0  # the cue is ahead again
                return Answer("ok", f"skip undone: {found.name} will run", self._data(found))
            was_playhead = self._playhead() == found
            self._skips[found.number] = found
            self._skips_changed()
            waiting = self._waiting_for(found)
            if waiting is not None:
                self._release(waiting, go=False)
            if was_playhead:
                self._moved = None  # the playhead follows the show again: a cue waiting, else the next GO cue
            answer = Answer("ok", f"skipped: {found.name}" + ("" if waiting is not None else " will not run"),
                            self._data(found))
        if waiting is not None:
            self._clock_changed()
        else:
            self._wake()  # a robot asleep towards the cue passes it now, not at its time
        return answer

    def _nothing_to_skip(self) -> str:
        """A skip with the auto playhead on no cue: no GO cue is ahead, but a timed cue may be,
        and the operator skips one by standing the playhead on it (the lock is held)."""
        if self._timed_open():
            return "nothing to skip under the playhead (no GO cue ahead): to skip a timed cue, move the playhead " \
                   "onto it (Up/Down, j, /choreo/playhead/CUE), then skip"
        return "nothing to skip: no cue ahead"

    def _timed_open(self) -> bool:
        """Is a timed cue not yet run? Looked for from where the last look found one, as
        `_next_ahead` does (a timed cue once run is open again only when it resets too): a skip
        refused at the end of a 10,000-cue show walked every cue under the lock the runners
        need. The lock is held."""
        cues = self.cues.cues
        for at in range(self._timed_from, len(cues)):
            cue = cues[at]
            if not cue.go and self._open(cue):
                self._timed_from = at
                return True
        self._timed_from = len(cues)
        return False

    def _gone_by(self, cue: Cue, state: str) -> str:
        """Why a cue can no longer be skipped or stood on (the lock is held)."""
        if cue.number in self._out:
            return f"{cue.name} is not in this run (--from, --loop)"
        if state == ACTIVE:
            return f"{cue.name} is running"
        return f"{cue.name} has {'been passed' if state == SKIPPED else 'run'} already"

    def _after(self, cue: Cue) -> Cue | None:
        """The next GO cue not yet run after `cue`, not skipped (None: auto). The lock is held."""
        later = self.cues.cues[self.cues.position(cue) + 1:] if cue in self.cues.cues else ()
        return next((c for c in later if c.go and self._state_of(c) in (AHEAD, WAITING)), None)

    def _put_playhead(self, command: Command) -> Answer:
        with self._changed:
            found = self._find(command.label)
            if isinstance(found, Answer):
                return found
            if not self._open(found):
                return Answer("error", f"{self._gone_by(found, self._state_of(found))}: the playhead goes on "
                              "cues not yet run", self._data(found))
            self._moved = found
            return Answer("ok", f"playhead: {found.name}", self._data(found))

    def _playhead_next(self, command: Command) -> Answer:
        return self._step_playhead(+1)

    def _playhead_previous(self, command: Command) -> Answer:
        return self._step_playhead(-1)

    def _step_playhead(self, by: int) -> Answer:
        """Move the playhead to the next (+1) or previous (-1) cue not yet run."""
        with self._changed:
            open_cues = [cue for cue in self.cues if self._open(cue)]
            here = self._playhead()
            if not open_cues:
                return Answer("error", "no cue ahead: the playhead has nowhere to go")
            if here is None or here not in open_cues:  # only timed cues ahead: onto the first
                self._moved = open_cues[0]
                return Answer("ok", f"playhead: {self._moved.name}", self._data(self._moved))
            at = open_cues.index(here)
            if not 0 <= at + by < len(open_cues):
                return Answer("error", f"the playhead is on the {'last' if by > 0 else 'first'} cue not yet run "
                              f"({here.name})", self._data(here))
            self._moved = open_cues[at + by]
            return Answer("ok", f"playhead: {self._moved.name}", self._data(self._moved))

    # -- pause and resume --------------------------------------------------------------------

    def _pause(self, command: Command) -> Answer:
        if self.clock == LINK:
            return Answer("error", "the Link session's beat never stops: no pause on the Link clock "
                                   "(skip, stop and panic work)")
        if not self._started:
            return Answer("error", "the show has not started: nothing to pause")
        with self._pausing:
            with self._changed:
                if self._paused:
                    return Answer("ok", "paused already", {"show_s": self._show_s()})
                self._paused = True
            if self._pausable is not None:
                self._pausable.pause()
        self._clock_changed()
        stood = self._show_s()
        at = f" at {stood:.3f} s" if stood is not None else ""
        return Answer("ok", f"paused{at}: no new step starts (one under way finishes); resume: p or /choreo/resume",
                      {"show_s": stood})

    def _resume(self, command: Command) -> Answer:
        with self._pausing:
            if not self._paused:
                return Answer("error", "not paused: nothing to resume")
            if self._pausable is not None:
                self._pausable.resume()
            with self._changed:
                self._paused = False
                self._changed.notify_all()
        self._clock_changed()
        stood = self._show_s()
        at = f" from {stood:.3f} s" if stood is not None else ""
        return Answer("ok", f"resumed{at}", {"show_s": stood})

    def _show_s(self) -> float | None:
        show = self.show
        return round(show.show_at(self._now()), 3) if show is not None else None

    def _clock_changed(self) -> None:
        """Tell who samples the clock that its state changed (outside the lock)."""
        for listener in self._clock_changes:
            listener()

    # -- start and stop ----------------------------------------------------------------------

    def _panic(self, command: Command) -> Answer:
        self.stop.request(PANIC)
        self._wake()
        return Answer("ok", "panic: no more show frames; stop frames and every robot's abort motion")

    def _stop(self, command: Command) -> Answer:
        self.stop.request(STOPPED)
        self._wake()
        return Answer("ok", "stopping: the exchange in flight, then the abort motion")

    def _start(self, command: Command) -> Answer:
        with self._changed:
            if self._started:
                return Answer("error", "the show has started already")
            self._started = True
            self._last_go = self._now()  # a second press of the start's GO key is a double press, not a GO
            self._changed.notify_all()
        return Answer("ok", "starting")

    def _wake(self) -> None:
        with self._changed:
            self._changed.notify_all()
        wake = self._wake_runners
        if wake is not None:
            wake()  # runners dozing towards a cue see the stop now
        elif isinstance(self.show, HoldingShowClock):
            self.show.wake()


def summary_of(held: Held) -> tuple[Command, Answer]:
    """The `unlogged` event summing up commands held back: `data` carries the counts (the log
    records them as the record's `count` and `counts`)."""
    return (Command(UNLOGGED, held.source),
            Answer("error", held.message(), {"count": held.count, "counts": held.counts}))


def link_status(show: LinkShowClock, mono: float) -> dict[str, Any]:
    """The Link session in a status reply: what an operator checks when a peer changed something."""
    snapshot = show.session.snapshot()
    return {"tempo": round(snapshot.tempo, 3), "peers": snapshot.peers, "playing": snapshot.playing,
            "beat": round(show.show_beat(mono), 3), "meter": show.meter}
