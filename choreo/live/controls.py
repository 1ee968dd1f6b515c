"""Running a show live: the operator's commands (GO, panic, start, stop, a cue's GO), from
whichever source gives them (the console's keys, OSC), and the GO cues that wait for them.

One `Live` a run, shared by every robot's runner and every source: a command is answered the
same way from the keyboard as from QLab, and every command, accepted or refused, is reported to
the listeners (the log records who pressed what and when). Sources never touch the runners:
they call `command`, which sets state the runners read (a GO cue released, the stop request).

The show clock holds while a GO cue waits (on the machine's clock: the steps after it are timed
from the GO, as if it came at once); on the music's clock it cannot hold, so the music plays on
and the step is reported against it.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from choreo.clock import ShowClock
from choreo.events import (PANIC, STOPPED, Answer, Command, CommandEvent, CommandListener, GoCue, Listeners,
                           StopRequest, Subscription, WaitingListener)
from choreo.live.limits import LIMITS, Held, Limits, ReportGate
from choreo.log.format import UNLOGGED
from choreo.show.model import PlannedStep

LOCKOUT_S = 0.5  # a second GO this soon after one is taken for a double press, and refused


class HoldingShowClock:
    """The machine's show clock, which stops at a GO cue's time while the cue waits: show time
    stands still there, and every runner's later due times move on with the hold. Times up to
    the cue keep their places (another robot still on its way to the same cue gets there).
    A runner asleep towards a later due time (another track's cue) dozes: `wake` (its time
    source's `notify`) ends the doze when the clock goes on, so it sleeps again towards the due
    time as moved by the GO, not to the end of a sleep slice."""

    def __init__(self, zero: float, mono: Callable[[], float], wake: Callable[[], None] = lambda: None) -> None:
        self._zero = zero
        self._mono = mono
        self._wake = wake
        self._hold_s: float | None = None  # the show time the clock stops at
        self._on_resume: Listeners[Callable[[], None]] = Listeners()  # told when it goes on

    @property
    def held(self) -> bool:
        return self._hold_s is not None

    def hold_at(self, show_s: float) -> None:
        """Stop the clock when it reaches `show_s` (at once if it has)."""
        self._hold_s = show_s if self._hold_s is None else min(self._hold_s, show_s)

    def resume(self) -> None:
        """Go on from the held time: the time spent holding is taken out of the show."""
        if self._hold_s is not None:
            reached = self._zero + self._hold_s
            now = self._mono()
            if now > reached:
                self._zero += now - reached
            self._hold_s = None
            self._wake()
            for listener in self._on_resume:
                listener()

    def on_resume(self, listener: Callable[[], None]) -> Subscription:
        """Call `listener` each time the clock goes on after a hold (the log's clock sample
        marks where show time goes on), until the subscription closes."""
        return self._on_resume.subscribe(listener)

    def wake(self) -> None:
        """Every runner dozing towards a due time looks again now: a stop or a panic given
        while a GO cue holds ends the others' dozes at once, not a sleep slice later."""
        self._wake()

    def mono_at(self, show_s: float) -> float:
        if self._hold_s is not None and show_s > self._hold_s + 1e-9:
            return float("inf")
        return self._zero + show_s

    def show_at(self, mono: float) -> float:
        show_s = mono - self._zero
        return show_s if self._hold_s is None else min(show_s, self._hold_s)


class Live:
    """A running show's controls; see the module's docstring."""

    def __init__(self, stop: StopRequest, *, wait_start: bool = False, lockout_s: float = LOCKOUT_S,
                 now: Callable[[], float] = time.monotonic, wall_ns: Callable[[], int] = time.time_ns,
                 limits: Limits = LIMITS) -> None:
        self.stop = stop
        self.lockout_s = lockout_s
        self.listeners: Listeners[CommandListener] = Listeners()  # attached through `subscribe`
        self.show: ShowClock | None = None  # the pass's show clock (`use_clock`), once the show starts
        self._now = now
        self._wall_ns = wall_ns
        self._changed = threading.Condition()
        self._started = not wait_start
        self._waiting: dict[object, GoCue] = {}  # the GO cues robots wait at, by `_key`
        self._released: set[object] = set()  # GO cues already given their GO
        self._last_go: float | None = None
        self._reports = ReportGate(limits, now)  # what of the commands the listeners hear
        self._summing = threading.RLock()  # a summary is told whole before `close` returns
        self._over = False  # the run is over (`close`): no command is taken any more

    def subscribe(self, listener: CommandListener) -> Subscription:
        """Tell `listener` every command and its answer (and, if it is a `WaitingListener`,
        every GO cue reached) until the subscription closes; whoever subscribes closes it."""
        return self.listeners.subscribe(listener)

    def use_clock(self, show: ShowClock) -> None:
        """The show clock of the pass now starting: GO cues hold it, commands are timed on it."""
        self.show = show

    @property
    def panicked(self) -> bool:
        """The show was stopped by a panic (not by stop, Ctrl-C or a fault)."""
        return self.stop.panicked

    @property
    def started(self) -> bool:
        """False until the show may start (with --wait-start, until start or GO)."""
        return self._started

    # -- what the show asks ------------------------------------------------------------------

    def await_start(self) -> bool:
        """Block until `/choreo/start` (with --wait-start); False if stopped first."""
        with self._changed:
            while not self._started:
                if self.stop():
                    return False
                self._changed.wait(0.05)
        return True

    def await_go(self, step: PlannedStep, robot: str, reached_s: float, should_stop: Callable[[], bool],
                 shared: bool = True) -> float | None:
        """`robot` has reached GO cue `step` (`shared`: a step of shared `steps:`, which every
        robot it is for waits at, released by one GO; else its own track's): hold the machine's
        show clock and block until a GO releases it. Returns the show time it goes on from
        (None: stopped while waiting). `reached_s`: the show time the robot reached it at."""
        show = self.show
        key = step.index if shared else (robot, step.index)
        with self._changed:
            if key in self._released:  # the others were given their GO as this robot arrived
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
            for listener in self.listeners:
                if isinstance(listener, WaitingListener):  # optional: the console, OSC notify, progress lines
                    listener.on_waiting(cue)
        with self._changed:
            while not cue.released:
                if should_stop():
                    return None
                self._changed.wait(0.05)
        return show.show_at(self._now()) if show is not None else cue.reached_s

    def new_pass(self) -> None:
        """A --loop pass begins: its GO cues wait for a GO of their own again."""
        with self._changed:
            self._released.clear()

    @property
    def waiting(self) -> list[GoCue]:
        """The GO cues waiting now, the earliest first."""
        with self._changed:
            return self._in_order()

    def _in_order(self) -> list[GoCue]:
        """The lock is held. A cue given its GO leaves `_waiting` at once (`_release`)."""
        return sorted(self._waiting.values(), key=lambda c: (c.reached_s, c.step.planned_s, c.step.index))

    # -- what the operator says --------------------------------------------------------------

    def command(self, command: Command) -> Answer:
        """Carry out one command from any source, and tell the listeners. Once the show is
        stopping (or over) every command is refused: a GO then releases nothing, whatever still
        waits, and a stop or panic cannot change the stop under way."""
        handler = {"go": self._go, "panic": self._panic, "start": self._start, "stop": self._stop,
                   "cue_go": self._cue_go}.get(command.name)
        refusal = self._refusal()
        if refusal is not None:
            answer = refusal
        else:
            answer = handler(command) if handler else Answer("error", f"unknown command {command.name!r}")
        self.report(command, answer)
        return answer

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

    def _go(self, command: Command) -> Answer:
        with self._changed:
            now = self._now()
            if self._last_go is not None and now - self._last_go < self.lockout_s:
                return Answer("error", f"GO ignored: {now - self._last_go:.2f} s after the last one "
                              f"(a double press? GOs {self.lockout_s:g} s apart at least)")
            waiting = self._in_order()
            if not waiting:
                return Answer("error", "nothing waits for GO now" + ("" if self._started else
                              " (the show waits for its start: /choreo/start)"))
            self._last_go = now
            return self._release(waiting[0])

    def _cue_go(self, command: Command) -> Answer:
        with self._changed:
            waiting = list(self._waiting.values())
            match = [c for c in waiting if c.step.label == command.label]
            if not match:
                at = ", ".join(repr(c.name) for c in waiting) or "no cue"
                return Answer("error", f"cue {command.label!r} is not waiting for GO (waiting: {at})")
            self._last_go = self._now()
            return self._release(match[0])

    def _release(self, cue: GoCue) -> Answer:
        """The lock is held."""
        cue.release()
        del self._waiting[cue.key]
        self._released.add(cue.key)
        if isinstance(self.show, HoldingShowClock) and not self._waiting:
            self.show.resume()
        self._changed.notify_all()
        return Answer("ok", f"GO: {cue.name}", {"cue": cue.name, "step": cue.step.index})

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
            self._changed.notify_all()
        return Answer("ok", "starting")

    def _wake(self) -> None:
        with self._changed:
            self._changed.notify_all()
        if isinstance(self.show, HoldingShowClock):
            self.show.wake()  # runners dozing towards a cue see the stop now


def summary_of(held: Held) -> tuple[Command, Answer]:
    """The `unlogged` event summing up commands held back: `data` carries the counts (the log
    records them as the record's `count` and `counts`)."""
    return (Command(UNLOGGED, held.source),
            Answer("error", held.message(), {"count": held.count, "counts": held.counts}))
