"""Everything a run tells and who listens: the event types, the listener protocols, the stop
request, and the subscriptions that attach a listener for a run and detach it after.

One module, below the board, the music, the log, the live controls and the run, so that each of
them names the events it emits or hears without importing the module that emits them: the
recorder hears the runner, the link and the live controls, the OSC server hears the runner and
the controls, and none of them imports another. It imports only the base modules, the wire's
frames and the show's model (a step event carries its step).

Optional hooks (a GO cue reached, the music playing out, the run's result) are declared here as
runtime-checkable protocols: a listener has the hook or not, and the caller asks `isinstance`,
never looks for a method by its name.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Generic, Protocol, TypeVar, runtime_checkable

from choreo.show.model import PlannedStep
from choreo.wire.protocol import Frame, Reply

PANIC = "panic"  # a stop request's reason for the operator's panic: stop frames, then every abort
STOPPED = "stopped"  # the reason of a stop nobody gave one for


# -- stopping ----------------------------------------------------------------------------------


class StopRequest:
    """No more show frames after the one in flight: one object the signal handler, the live
    controls (console, OSC), the runner threads and the log ask through, from any thread.

    The first reason given is the run's, except that a panic always wins: the operator's panic
    replaces any reason before it (stop frames, then every abort motion), and nothing replaces
    a panic (a link fault it causes, a Ctrl-C after it). The rule lives here, under a lock, so
    that no interleaving of threads can lose a panic.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._event = threading.Event()
        self._reason: str | None = None

    def request(self, reason: str = STOPPED) -> bool:
        """Ask the run to stop; True if `reason` is now the run's (the first, or a panic)."""
        with self._lock:
            if self._reason is not None and (self._reason == PANIC or reason != PANIC):
                return False
            self._reason = reason
            self._event.set()
            return True

    @property
    def reason(self) -> str:
        """Why the run stops (`stopped` if nobody has asked yet)."""
        return self._reason if self._reason is not None else STOPPED

    @property
    def panicked(self) -> bool:
        return self._reason == PANIC

    def __call__(self) -> bool:
        return self._event.is_set()


def never() -> bool:
    """The stop check of what must run to its end whatever was asked (the abort motion)."""
    return False


# -- subscriptions -------------------------------------------------------------------------------

L = TypeVar("L")


class Subscription:
    """One listener attached until `close` (or the end of a `with` block): whoever attached it
    detaches it, so nothing outlives the run it was attached for."""

    def __init__(self, detach: Callable[[], None]) -> None:
        self._detach: Callable[[], None] | None = detach

    def close(self) -> None:
        detach, self._detach = self._detach, None
        if detach is not None:
            detach()

    def __enter__(self) -> Subscription:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class Listeners(Generic[L]):
    """Who hears an emitter now. Attaching and detaching swap the whole tuple under a lock, so
    an emitting thread reads a consistent snapshot without taking the lock on its fast path."""

    def __init__(self, initial: tuple[L, ...] = ()) -> None:
        self._lock = threading.Lock()
        self._now: tuple[L, ...] = tuple(initial)

    def subscribe(self, listener: L) -> Subscription:
        """Attach `listener` now; the subscription detaches it (once) when closed."""
        with self._lock:
            self._now = (*self._now, listener)
        return Subscription(lambda: self._remove(listener))

    def _remove(self, listener: L) -> None:
        with self._lock:
            at = next((i for i, known in enumerate(self._now) if known is listener), None)
            if at is not None:
                self._now = self._now[:at] + self._now[at + 1:]

    def __iter__(self) -> Iterator[L]:
        return iter(self._now)

    def __len__(self) -> int:
        return len(self._now)


# -- the link: frames and replies --------------------------------------------------------------


@dataclass(frozen=True)
class Tag:
    """Which show step a frame belongs to, carried into the log and into error messages."""

    step: int | None = None
    label: str | None = None

    def __str__(self) -> str:
        if self.step is None:
            return ""
        return f"step {self.step}" + (f" '{self.label}'" if self.label else "")


@dataclass(frozen=True, slots=True)
class TxEvent:
    """A frame about to be written (timestamped just before the write)."""

    seq: int
    frame: Frame
    attempt: int
    time_ns: int
    tag: Tag | None


@dataclass(frozen=True, slots=True)
class RxEvent:
    """The verdict on what came back for frame `seq` (timestamped when the reply completed)."""

    seq: int
    frame: Frame
    reply: Reply
    time_ns: int
    latency_s: float
    tag: Tag | None


class LinkListener(Protocol):
    def on_tx(self, event: TxEvent) -> None: ...

    def on_rx(self, event: RxEvent) -> None: ...


# -- the runner: steps, log lines, the result ----------------------------------------------------


@dataclass(frozen=True)
class StepEvent:
    """A step starting or ending (or passed, skipped), on the show clock (seconds since the
    show started)."""

    step: PlannedStep
    event: str  # start | end | skip (a cue the operator skipped: its step not run, no start nor end)
    planned_s: float  # when it was due at run time
    actual_s: float
    time_ns: int
    late_ms: float = 0.0
    outcome: str | None = None  # end: ok | failed | aborted | timeout; skip: skipped
    robot: str | None = None  # whose step, in a show for several robots
    start_s: float | None = None  # end of a play: when the frame that started the motion was written
    lead_ms: float = 0.0  # end of a cued play: how far ahead of the cue its first frame was due


class RunListener(Protocol):
    """Hears a run's steps and its log lines (`time_ns`: the run clock's wall time, always
    given: on virtual time or the music's clock the machine's would place a line elsewhere)."""

    def on_step(self, event: StepEvent) -> None: ...

    def on_log(self, level: int, message: str, time_ns: int) -> None: ...


@dataclass(frozen=True)
class RunResult:
    outcome: str  # done | aborted
    steps_run: int
    late_steps: int
    show_s: float  # show clock at the end (the log's `choreo.result` text: log/format.result_metadata)


@runtime_checkable
class PlayOutListener(Protocol):
    """Hears that the steps are done and the music plays on to its end (at show time `end_s`)."""

    def on_play_out(self, end_s: float) -> None: ...


@runtime_checkable
class ResultListener(Protocol):
    """Hears the run's result once it is over (OSC notify tells its targets)."""

    def on_result(self, result: RunResult) -> None: ...


# -- the live controls: commands, answers, GO cues -----------------------------------------------


@dataclass(frozen=True)
class Command:
    """An operator's command: what, from where (`key`, `osc udp 127.0.0.1:53001`), and for
    `cue_go`, `playhead` and `skip` which cue (its number or label, as typed or sent; a `skip`
    without one skips the playhead's cue)."""

    name: str
    source: str
    label: str | None = None


@dataclass(frozen=True)
class Answer:
    """What a command did: `ok`, or `error` with why; `data` says more (the cue released)."""

    status: str  # ok | error
    message: str = ""
    data: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "ok"


@dataclass(frozen=True)
class CommandEvent:
    """A command and its answer, when it came (wall-clock ns and show time)."""

    command: Command
    answer: Answer
    time_ns: int
    show_s: float | None


class CommandListener(Protocol):
    """Hears every command and its answer (it may hear GO cues too: `WaitingListener`)."""

    def on_command(self, event: CommandEvent) -> None: ...


@dataclass
class GoCue:
    """A GO cue some robot is waiting at: its step (same index for every robot of a shared
    step), who waits, and when the show reached it. The live controls own it: they release it."""

    step: PlannedStep
    robots: set[str]
    reached_s: float
    released: bool = False
    key: object = None
    told: bool = False  # its hold is in the log and its listeners have heard it

    def reached_by(self, robot: str) -> None:
        """`robot` waits at it too (the live controls call it, under their lock)."""
        self.robots.add(robot)

    def release(self) -> None:
        """Its GO was given (the live controls call it, under their lock)."""
        self.released = True

    def tell(self) -> None:
        """Its hold is logged and its listeners told (the live controls call it, under their lock)."""
        self.told = True

    @property
    def name(self) -> str:
        return self.step.label or f"step {self.step.index}"


@runtime_checkable
class WaitingListener(Protocol):
    """Hears, once, that the show reached a GO cue (from the runner's thread: be quick)."""

    def on_waiting(self, cue: GoCue) -> None: ...
