"""Several robots on one show clock: one runner thread per robot, gates for shared steps, faults.

Each robot's `Runner` plays its own plan over its own link in a thread of its own, so a slow
reply on one line never holds up another robot's frames; all read one show clock (the same
monotonic zero). A unison play is due at the same instant in every thread, and each thread
spins the last 2 ms to it on its own, so the robots' first bytes leave together, not one after
the other.

Shared `steps:` stay in step through `Gates`: a step starts when every robot it is for is
through the one before, and a unison play's start frames (the frame that starts the motion,
after each robot's own exchanges before it) wait for each other and leave at one instant. When
the gate opens late (the last robot's `wait: done` saw its motion end just now), the next step
is released a little ahead (`SYNC_S`), so that every thread, woken at slightly different
moments, still sends at one due time.

Faults: a robot whose link fails either stops the show (`on_fault: stop`, the default: the
others play their abort motions, the run fails naming the robot) or drops out
(`on_fault: continue`: the gates stop waiting for it and the others finish; the run still fails
at the end, saying who dropped out and when).

Hosts: in a show played by several hosts (`hosts:`, `choreo run --host NAME`), a run's parts
are its host's robots only, and its gates know no others (`Gates.live`: this run's robots). A
robot on another host is absent, which is not a dropout: no gate ever waits for it, none says
it dropped out, and a shared step that is its alone ends where the plan says (`through`'s
`idle`). The hosts line up on the show's cues (on the Link clock, the session's beat), not on
each other's robots.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from choreo.clock import MachineShowClock, RunClock, ShowClock, quick_thread_switches
from choreo.errors import LinkError
from choreo.events import STOPPED, RunResult, StopRequest, never
from choreo.log.format import ERROR, WARNING
from choreo.run.runner import Runner
from choreo.show.model import PlannedStep

SYNC_S = 0.002  # how far ahead a gate opened late releases the next step (see the docstring)
ARMED = "armed"  # gates keyed (ARMED, step index): a unison play's start frames
START_S = 0.02  # how far ahead of the threads' start show time 0 is


@dataclass
class _Gate:
    """One shared step: who has come through it, and where the show clock stood."""

    arrived: set[str] = field(default_factory=set)
    end: float | None = None  # latest end of the step among the robots it was for
    idle: float | None = None  # where the plan ends the step, for the robots it was not for
    release: float | None = None  # when the next step may start, once everyone is through
    expected: frozenset[str] | None = None  # who must arrive (None: every robot still in the show)
    writes: dict[str, Callable[[], None]] = field(default_factory=dict)  # a unison play's start frames
    written: dict[str, int] | None = None  # when each was written (monotonic ns)
    taking: bool = False  # the writer has the writes: no robot may take its own back
    opened: float = 0.0  # monotonic time the gate opened


class Gates:
    """Shared steps: step i + 1 starts when every robot still in the show is through step i
    (`robots`: this run's; another host's robots are never awaited)."""

    def __init__(self, robots: list[str], clock: RunClock, show: ShowClock, stop: StopRequest) -> None:
        self.live = set(robots)
        self.clock = clock
        self.show = show
        self.stop = stop
        self._gates: dict[int | tuple[str, int], _Gate] = {}  # by step index, and (ARMED, index)
        self._lock = threading.Lock()

    def through(self, index: int, robot: str, end: float | None, idle: float | None = None) -> float | None:
        """A step nobody left could do (its robots dropped out) ends when the plan says
        (`idle`): the robots still on stage keep the show's timing, not run ahead of it."""
        with self._lock:
            gate = self._gates.setdefault(index, _Gate())
            gate.arrived.add(robot)
            if end is not None:
                gate.end = end if gate.end is None else max(gate.end, end)
            if idle is not None:
                gate.idle = idle if gate.idle is None else max(gate.idle, idle)
            self._open(index, gate)
        self.clock.source.notify()
        if not self.clock.source.wait_for(lambda: gate.release is not None, self.stop):
            return None
        return gate.release

    def armed(self, step: PlannedStep, robot: str, write: Callable[[], None]) -> int | None:
        """Every robot the unison play is for is ready to send its start frame: the last one to
        get ready writes them all, back to back, `SYNC_S` later (one thread: no wake-ups to wait
        for between them). The others get the moment theirs was written."""
        key = (ARMED, step.index)
        with self._lock:
            gate = self._gates.setdefault(key, _Gate(expected=frozenset(step.robots) if step.robots else None))
            if gate.release is not None:
                return None  # a retry after the others went: on its own
            gate.writes[robot] = write
            gate.arrived.add(robot)
            self._open(key, gate)
            writer = gate.release is not None
        if writer:
            self._write_all(gate)
        elif not self.clock.source.wait_for(lambda: gate.written is not None, self.stop):
            with self._lock:
                if not gate.taking:  # stopping before the writes began: this robot writes its own
                    gate.writes.pop(robot, None)
                    return None
            self.clock.source.wait_for(lambda: gate.written is not None, never)
        return gate.written.get(robot) if gate.written is not None else None

    def _write_all(self, gate: _Gate) -> None:
        """The start frames, `SYNC_S` after the gate opened on the machine's clock, not the show's:
        a play under way finishes while the show clock stands (a pause, another track's GO
        cue held), its motion never left waiting halfway for the clock to go on."""
        assert gate.release is not None, "written only once the gate is open"
        self.clock.sleep_until(gate.opened + SYNC_S)
        written = {}
        with self._lock:
            gate.taking = True
            writes = dict(gate.writes)
        for name, write in writes.items():
            written[name] = self.clock.mono_ns()
            write()
        gate.written = written
        self.clock.source.notify()

    def drop(self, robot: str) -> None:
        """`robot` is out of the show: no gate waits for it any more."""
        with self._lock:
            self.live.discard(robot)
            opened = []
            for key, gate in list(self._gates.items()):
                waiting = gate.release is None
                self._open(key, gate)
                if waiting and gate.release is not None and gate.writes:
                    opened.append(gate)  # a unison play the others were ready for: write it here
        for gate in opened:
            self._write_all(gate)
        self.clock.source.notify()

    def _open(self, key: int | tuple[str, int], gate: _Gate) -> None:
        """The last robot through opens the gate; the lock is held."""
        awaited = self.live if gate.expected is None else gate.expected & self.live
        if gate.release is not None or not awaited <= gate.arrived:
            return
        gate.opened = self.clock.mono()
        now = self.show.show_at(gate.opened)
        end = gate.end if gate.end is not None else gate.idle if gate.idle is not None else now
        gate.release = max(end, now + SYNC_S)
        if isinstance(key, int):  # everyone is past the step before and its play: forget them
            self._gates.pop(key - 1, None)
            self._gates.pop((ARMED, key), None)


@dataclass
class Dropout:
    """A robot whose link failed while the others went on (`on_fault: continue`)."""

    robot: str
    show_s: float
    error: LinkError

    def __str__(self) -> str:
        return f"robot {self.robot} dropped out at {self.show_s:.3f} s: {self.error}"


class RobotFault(LinkError):
    """A robot's link failed: the message names the robot (exit 3)."""


@dataclass(frozen=True)
class Part:
    """One robot's part in the show: its runner and what a fault on its link does."""

    robot: str
    runner: Runner
    on_fault: str = "stop"


@dataclass
class EnsembleResult:
    """The show's outcome for all robots: each runner's result, and who dropped out."""

    results: dict[str, RunResult]
    dropouts: list[Dropout]
    show_s: float

    @property
    def outcome(self) -> str:
        return "aborted" if any(r.outcome == "aborted" for r in self.results.values()) else "done"

    @property
    def late_steps(self) -> int:
        return sum(r.late_steps for r in self.results.values())

    @property
    def steps_run(self) -> int:
        return sum(r.steps_run for r in self.results.values())

    def combined(self) -> RunResult:
        return RunResult(self.outcome, self.steps_run, self.late_steps, self.show_s)


class Ensemble:
    """Runs every robot's part at once on one show clock; see the module's docstring."""

    def __init__(self, parts: list[Part], clock: RunClock, stop: StopRequest, unison: bool,
                 log: Callable[[int, str], None] = lambda level, message: None, origin: float = 0.0) -> None:
        self.parts = parts
        self.origin = origin  # show time of the first step played (0, or --from's step)
        self.clock = clock
        self.stop = stop
        self.unison = unison
        self.log = log
        self._errors: dict[str, BaseException] = {}
        self._results: dict[str, RunResult] = {}
        self._dropouts: list[Dropout] = []
        self.show: ShowClock = MachineShowClock(0.0)
        self._gates: Gates | None = None

    def preroll_s(self) -> float:
        """How long before the show's start the threads must be running: long enough for every
        thread to be up and spinning, and for a first play cued at the start to go out early."""
        return max(START_S, *(part.runner.preroll_s() for part in self.parts))

    def run(self, show: ShowClock | None = None, on_idle: Callable[[], None] | None = None) -> EnsembleResult:
        """Every part in its thread; LinkError (naming the robot) when a fault stopped the show
        or a robot dropped out, else the combined result. `show`: the music's clock, else the
        machine's, with show time 0 (or --from's step) `preroll_s` from now. `on_idle`: each
        runner's background work while it waits. Shared steps meet at this run's gates, handed
        to each runner's run (nothing of a runner is set from here)."""
        self.show = show if show is not None else MachineShowClock(self.clock.mono() - self.origin + self.preroll_s())
        if self.unison:
            self._gates = Gates([p.robot for p in self.parts], self.clock, self.show, self.stop)
        threads = [threading.Thread(target=self._play, args=(part, on_idle), name=f"choreo-{part.robot}", daemon=True)
                   for part in self.parts]
        self.clock.source.admit(len(threads))
        with quick_thread_switches():
            for thread in threads:
                thread.start()
            self._join(threads)
        return self._finish()

    @property
    def dropouts(self) -> list[Dropout]:
        return list(self._dropouts)

    def _join(self, threads: list[threading.Thread]) -> None:
        """Wait for every thread, in slices so that the main thread takes its signals (a first
        Ctrl-C sets the stop request every runner reads; a second leaves at once)."""
        for thread in threads:
            while thread.is_alive():
                thread.join(0.05)

    def _play(self, part: Part, on_idle: Callable[[], None] | None = None) -> None:
        try:
            self._results[part.robot] = part.runner.run(self.show, cues=self._gates, on_idle=on_idle)
        except LinkError as exc:
            self._fault(part, exc)
        except BaseException as exc:  # noqa: BLE001 - carried to the main thread, raised there
            self._errors[part.robot] = exc
            self.stop.request(STOPPED)
        finally:
            if self._gates is not None:
                self._gates.drop(part.robot)
            self.clock.source.leave()

    def _fault(self, part: Part, exc: LinkError) -> None:
        show_s = self.show.show_at(self.clock.mono())
        if part.on_fault == "continue":
            dropout = Dropout(part.robot, show_s, exc)
            self._dropouts.append(dropout)
            self.log(WARNING, f"{dropout}; the others go on (on_fault: continue)")
            return
        self._errors[part.robot] = RobotFault(f"robot {part.robot}: {exc}")
        self.log(ERROR, f"robot {part.robot}'s link failed at {show_s:.3f} s: the show stops")
        self.stop.request(f"stopped: robot {part.robot}'s link failed")

    def _finish(self) -> EnsembleResult:
        if self._errors:
            first = next(iter(self._errors.values()))
            raise first
        show_s = self.show.show_at(self.clock.mono())
        result = EnsembleResult(dict(self._results), list(self._dropouts), show_s)
        if self._dropouts and result.outcome == "done":
            named = "; ".join(str(d) for d in self._dropouts)
            everyone = len(self._dropouts) == len(self.parts)
            raise RobotFault(f"{named} ({'every robot dropped out' if everyone else 'the others finished the show'})")
        return result
