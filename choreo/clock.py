"""One monotonic clock for a run, anchored once to the wall clock, and the time it reads.

Log times must be wall-clock nanoseconds (Foxglove shows them as dates) but must never jump
when NTP adjusts the system time mid-show, so every timestamp is the monotonic clock plus one
offset taken at the start. Cue timing uses the same monotonic clock.

Everything that waits or measures on a run's behalf (the runner, the link, the in-process
simulator) reads its time from one `TimeSource`: the machine's (`SystemTime`) on stage, or
`VirtualTime`, where a sleep takes no real time. With the in-process simulator on virtual time
a 22-second show runs in a fraction of a second and every figure in its log comes out the same
on a loaded machine as on an idle one: timing logic is tested exactly, not by luck.
"""

from __future__ import annotations

import contextlib
import math
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

# The last stretch before a cue is spun, not slept: sleep() on a loaded machine overshoots by
# up to a millisecond or more, and a cue's first byte must leave within 1 ms of its time.
SPIN_S = 0.002
# Background work (writing the log) runs only before a sleep with at least this much to spare.
IDLE_S = 0.01
# Python's thread switch interval while other threads share a show (several robots' runners,
# the music's audio callback): a thread due to send must not wait 5 ms (the default) for the lock.
SWITCH_S = 0.0001


class _SwitchInterval:
    """The interpreter's switch interval is the whole process's: one object stands for it, so
    that blocks entered and left on several threads (two runs in one program) keep it quick
    until the last one ends, then put back what was there before the first. Saving and
    restoring per block would let the first run to end slow the other's threads down, and the
    last to end leave the process switching every SWITCH_S for good."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._users = 0
        self._before = 0.0

    def enter(self) -> None:
        with self._lock:
            if self._users == 0:
                self._before = sys.getswitchinterval()
                sys.setswitchinterval(SWITCH_S)
            self._users += 1

    def leave(self) -> None:
        with self._lock:
            self._users -= 1
            if self._users == 0:
                sys.setswitchinterval(self._before)


_SWITCHES = _SwitchInterval()  # the process's one switch interval (see _SwitchInterval)


@contextlib.contextmanager
def quick_thread_switches() -> Iterator[None]:
    """Python hands its lock between threads every 5 ms by default: while other threads share
    a show, a thread due to send could wait that long behind another's work. Every SWITCH_S
    inside the block (and any other such block, on any thread), as it was after the last."""
    _SWITCHES.enter()
    try:
        yield
    finally:
        _SWITCHES.leave()


class TimeSource(Protocol):
    """Monotonic time and sleeping, as a run sees them."""

    virtual: bool

    def now(self) -> float:
        """Monotonic seconds."""

    def now_ns(self) -> int:
        """Monotonic nanoseconds."""

    def sleep(self, seconds: float) -> None:
        """Let `seconds` pass."""

    def doze(self, seconds: float, seen: int | None = None) -> None:
        """Let up to `seconds` pass: `notify` ends it early (a deadline that moved), and so
        does one that came after `notified()` read `seen` (before the doze began: the deadline
        the sleeper read may already have moved)."""

    def notified(self) -> int:
        """How many times `notify` was called: read before a deadline, given to `doze`."""

    def spin(self) -> None:
        """One turn of a busy wait (the last SPIN_S before a cue)."""

    def wall_ns(self) -> int:
        """Wall-clock nanoseconds, read once to anchor a run's log times."""

    def admit(self, threads: int) -> None:
        """Several threads (one a robot) are about to share this time."""

    def leave(self) -> None:
        """One of them is done."""

    def notify(self) -> None:
        """Something a `wait_for` predicate reads has changed."""

    def wait_for(self, ready: Callable[[], bool], should_stop: Callable[[], bool]) -> bool:
        """Block until `ready()` (True) or `should_stop()` (False)."""


class SystemTime:
    """The machine's clocks: what a show on stage runs on."""

    virtual = False

    def now(self) -> float:
        return time.monotonic()

    def now_ns(self) -> int:
        return time.monotonic_ns()

    def sleep(self, seconds: float) -> None:
        time.sleep(max(seconds, 0.0))

    def doze(self, seconds: float, seen: int | None = None) -> None:
        with self._changed:
            if seen is None or seen == self._notified:
                self._changed.wait(max(seconds, 0.0))

    def notified(self) -> int:
        return self._notified

    def __init__(self) -> None:
        self._changed = threading.Condition()
        self._threads = 0  # threads of one run sharing this time (several robots)
        self._notified = 0  # notify calls so far: a doze that missed one does not begin

    def spin(self) -> None:
        """A busy-wait turn; with several robots' threads, one that lets the others run: one
        robot spinning towards a cue must not hold Python's lock while another's falls due."""
        if self._threads:
            time.sleep(0)

    def wall_ns(self) -> int:
        return time.time_ns()

    # -- threads of one run (several robots) ------------------------------------------------

    def admit(self, threads: int) -> None:
        """`threads` threads are about to share this time (spinning then yields to them)."""
        with self._changed:
            self._threads += threads

    def leave(self) -> None:
        """A thread admitted with `admit` is done."""
        with self._changed:
            self._threads = max(0, self._threads - 1)

    def notify(self) -> None:
        """Something a `wait_for` predicate reads has changed."""
        with self._changed:
            self._notified += 1
            self._changed.notify_all()

    def wait_for(self, ready: Callable[[], bool], should_stop: Callable[[], bool]) -> bool:
        """Block until `ready()` (True) or `should_stop()` (False); woken by `notify`."""
        with self._changed:
            while not ready():
                if should_stop():
                    return False
                self._changed.wait(0.05)
        return True


class VirtualTime:
    """Time that passes only when something sleeps or spins: no real waiting, same result on
    any machine. Its wall clock starts at the real one, so logs look like any other run's.

    Only the in-process simulator (`sim://`) can keep up with it: a real port answers in real
    time, so a session refuses the pair (see `choreo.run.session`).
    """

    virtual = True
    SPIN_NS = 1_000  # a busy-wait turn costs a microsecond

    def __init__(self, start_s: float = 1000.0) -> None:
        self._ns = round(start_s * 1e9)
        self._wall_ns = time.time_ns()
        self._lock = threading.Condition()
        # With several threads (one a robot), time is a scheduler's: it moves only when every
        # admitted thread sleeps or waits, to the earliest wake-up, so each thread sees the
        # others' frames at the instants they were sent. None: one thread, sleeps advance at once.
        self._running: int | None = None
        self._sleepers: dict[object, int] = {}  # token -> wake-up time (ns)
        self._waiting: dict[object, Callable[[], bool]] = {}  # token -> what it waits for
        self._dozing: set[object] = set()  # sleepers `notify` wakes early
        self._notified = 0  # notify calls so far: a doze that missed one does not begin

    def now(self) -> float:
        return self._ns / 1e9

    def now_ns(self) -> int:
        return self._ns

    def sleep(self, seconds: float) -> None:
        self._nap(seconds, dozing=False)

    def doze(self, seconds: float, seen: int | None = None) -> None:
        """A sleep that `notify` ends early; alone (no other thread to notify), a sleep."""
        self._nap(seconds, dozing=True, seen=seen)

    def _nap(self, seconds: float, dozing: bool, seen: int | None = None) -> None:
        """`seconds` of virtual time; a dozing nap is one `notify` may end early."""
        if self._running is None:
            self.advance(seconds)
            return
        with self._lock:
            if seen is not None and seen != self._notified:
                return  # notified since the sleeper read its deadline: no time passes
            token = object()
            self._sleepers[token] = self._ns + max(1, math.ceil(seconds * 1e9))
            if dozing:
                self._dozing.add(token)
            try:
                self._block(token, self._sleepers)
            finally:
                self._dozing.discard(token)

    def spin(self) -> None:
        if self._running is None:
            with self._lock:
                self._ns += self.SPIN_NS
            return
        self.sleep(self.SPIN_NS / 1e9)

    def advance(self, seconds: float) -> None:
        """Whole nanoseconds, rounded up: a sleep of any length lets some time pass, so a
        loop waiting for a deadline always gets there."""
        if seconds > 0:
            with self._lock:
                self._ns += math.ceil(seconds * 1e9)

    def notified(self) -> int:
        return self._notified

    def wall_ns(self) -> int:
        return self._wall_ns + self._ns

    # -- threads of one run (several robots) ------------------------------------------------

    def admit(self, threads: int) -> None:
        """`threads` threads are about to share this time (call before starting them)."""
        with self._lock:
            self._running = (self._running or 0) + threads

    def leave(self) -> None:
        """An admitted thread is done: the others' time may move on without it."""
        with self._lock:
            assert self._running is not None, "leave() without admit()"
            self._running -= 1
            if self._running == 0 and not self._sleepers and not self._waiting:
                self._running = None  # back to one thread
            else:
                self._schedule()

    def notify(self) -> None:
        """Dozers wake now, at this instant (their deadline moved); `wait_for` predicates
        are read when time would move: nothing to wake for them."""
        with self._lock:
            self._notified += 1
            woken = [token for token in self._dozing if token in self._sleepers]
            if not woken:
                return
            for token in woken:
                del self._sleepers[token]
            self._running = (self._running or 0) + len(woken)
            self._lock.notify_all()

    def wait_for(self, ready: Callable[[], bool], should_stop: Callable[[], bool]) -> bool:
        """Block until `ready()`; no time passes for it unless every other thread waits too."""
        if ready():
            return True
        if self._running is None:
            return False  # one thread: nobody else can make it ready
        with self._lock:
            token = object()
            self._waiting[token] = lambda: ready() or should_stop()
            self._block(token, self._waiting)
        return ready()

    def _block(self, token: object, where: dict) -> None:
        """This thread stops running until the scheduler takes `token` out of `where`."""
        assert self._running is not None
        self._running -= 1
        self._schedule()
        while token in where:
            self._lock.wait()

    def _schedule(self) -> None:
        """Every admitted thread is blocked: wake the waiters whose condition holds, else move
        time to the earliest wake-up and wake the sleepers due then. The lock is held."""
        if self._running != 0:
            return
        ready = [token for token, check in self._waiting.items() if check()]
        if ready:
            for token in ready:
                del self._waiting[token]
        elif self._sleepers:
            self._ns = max(self._ns, min(self._sleepers.values()))
            ready = [token for token, due in self._sleepers.items() if due <= self._ns]
            for token in ready:
                del self._sleepers[token]
        self._running += len(ready)
        self._lock.notify_all()


@dataclass
class RunClock:
    """Monotonic seconds for scheduling, anchored wall-clock nanoseconds for the log."""

    source: TimeSource = field(default_factory=SystemTime)
    mono_anchor_ns: int = -1
    wall_anchor_ns: int = -1

    def __post_init__(self) -> None:
        if self.mono_anchor_ns < 0:
            self.mono_anchor_ns = self.source.now_ns()
        if self.wall_anchor_ns < 0:
            self.wall_anchor_ns = self.source.wall_ns()

    @property
    def virtual(self) -> bool:
        return self.source.virtual

    def mono(self) -> float:
        return self.source.now()

    def mono_ns(self) -> int:
        return self.source.now_ns()

    def sleep(self, seconds: float) -> None:
        self.source.sleep(seconds)

    def wall_ns(self, mono_ns: int | None = None) -> int:
        """Wall-clock nanoseconds of a monotonic instant (now if not given)."""
        if mono_ns is None:
            mono_ns = self.source.now_ns()
        return self.wall_anchor_ns + mono_ns - self.mono_anchor_ns

    def sleep_until(self, deadline: float | Callable[[], float], should_stop: Callable[[], bool] = lambda: False,
                    slice_s: float = 0.05, on_idle: Callable[[], None] | None = None) -> bool:
        """Sleep until a monotonic deadline, spinning the last SPIN_S; False if told to stop.

        Sleeps in slices so that a stop request (Ctrl-C) is seen within `slice_s`. Before each
        slice with more than IDLE_S to spare, `on_idle` runs: the time to write the log. A
        deadline given as a function is read again each slice: a show time on the music's
        clock falls at a monotonic time that moves as the sound card's clock drifts, and on a
        clock held for a GO it moves when the GO comes, so such a sleep is a `doze`, which the
        clock's `notify` ends at once (a cue due just after the GO is not a slice late).
        """
        source = self.source
        due = deadline if callable(deadline) else lambda: deadline
        moves = callable(deadline)
        while True:
            if should_stop():
                return False
            seen = source.notified() if moves else None  # before reading where the deadline is
            left = due() - source.now()
            if left <= 0:
                return True
            if left > SPIN_S:
                if on_idle is not None and left > IDLE_S:
                    on_idle()
                    left = due() - source.now()
                    if left <= SPIN_S:
                        continue
                nap = min(left - SPIN_S, slice_s)
                if moves:
                    source.doze(nap, seen)
                else:
                    source.sleep(nap)
            elif source.virtual:
                source.sleep(left)  # nothing to gain by spinning on time that only sleeping moves
            else:
                source.spin()


class ShowClock(Protocol):
    """Show time against the monotonic clock: the machine's (a fixed zero) or the music's
    (the playing song's position, which drifts against the machine's).

    Everything that schedules on show time (runners, gates) goes through one, so a show runs
    the same code on either clock."""

    def mono_at(self, show_s: float) -> float:
        """The monotonic time at which show time `show_s` falls (on the latest estimate)."""

    def show_at(self, mono: float) -> float:
        """The show time at monotonic time `mono`."""


RUNNING, HELD, PAUSED = "running", "held", "paused"  # a show clock's states (the log's /choreo/clock `state`)


@runtime_checkable
class PausableShowClock(ShowClock, Protocol):
    """A show clock the operator can pause (`p`, `/choreo/pause`): the machine's, which also
    holds at a GO cue, and the music's, whose song pauses with it. While paused, show time
    stands still; on resume it goes on from where it stood, the pause taken out of the show."""

    @property
    def state(self) -> str:
        """RUNNING, HELD (at a GO cue: the machine's clock only) or PAUSED."""

    def pause(self) -> float:
        """Stand still now; the show time it stands at. Twice is harmless."""

    def resume(self) -> None:
        """Go on from where it stood (a GO cue still waiting keeps the machine's clock held)."""


@runtime_checkable
class BeatGrid(Protocol):
    """A show clock whose bars and beats are not fixed show times: an Ableton Link session's,
    whose tempo any peer may change mid-show. A cue written in bars and beats is placed on it
    as it stands when the runner looks (and looks again as it sleeps towards it); a cue in
    seconds stays on seconds."""

    def at_beat(self, bar: int, beat: float) -> float:
        """Show time at which bar `bar`, beat `beat` (counted from 1) falls now."""


@dataclass(frozen=True)
class MachineShowClock:
    """The machine's clock: show time 0 is one fixed monotonic instant."""

    zero: float  # monotonic time of show time 0

    def mono_at(self, show_s: float) -> float:
        return self.zero + show_s

    def show_at(self, mono: float) -> float:
        return mono - self.zero


def sleep_until_show(clock: RunClock, show: ShowClock, show_s: float | Callable[[], float],
                     should_stop: Callable[[], bool] = lambda: False,
                     on_idle: Callable[[], None] | None = None) -> bool:
    """Sleep until show time `show_s` on `show`; False if told to stop. A show time given as a
    function (a cue in bars on a `BeatGrid`) is read again as the sleep goes on."""
    if callable(show_s):
        due = show_s
        return clock.sleep_until(lambda: show.mono_at(due()), should_stop, on_idle=on_idle)
    if isinstance(show, MachineShowClock):
        return clock.sleep_until(show.zero + show_s, should_stop, on_idle=on_idle)
    fixed = show_s
    return clock.sleep_until(lambda: show.mono_at(fixed), should_stop, on_idle=on_idle)
