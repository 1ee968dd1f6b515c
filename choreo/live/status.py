"""Where each robot of a running show is, and how its link is doing: one record every part that
tells the operator reads (the console's robot rows, the `/choreo/status` reply), so they agree.

It is a listener (the run's steps, each robot's link frames and replies) that the runners and
the links call on their own path: each call only notes what happened under a short lock, and
`robots` hands out frozen snapshots (`RobotRow`) to be read outside it.
"""

from __future__ import annotations

import statistics
import threading
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from choreo.events import LinkListener, RxEvent, StepEvent, TxEvent
from choreo.show.model import SOLO, Plan, PlannedStep, StepKind

LATENCIES = 20  # the replies a link's health is the median of
Skipped = Callable[[str, int], bool]  # is this robot's step a cue the operator skipped? (`Live.skipped`)


def _none_skipped(robot: str, index: int) -> bool:
    return False


@dataclass(frozen=True)
class RobotRow:
    """One robot now (a snapshot)."""

    robot: str
    step: PlannedStep | None  # its current step (None: not started)
    ended: bool  # that step has ended (between steps)
    done: bool  # its last step ended
    next_step: PlannedStep | None
    started_s: float  # show time the current step started
    latency_ms: float | None  # median of the last LATENCIES replies (None: no reply yet)
    retries: int
    failed: int  # tries without a good reply
    due_s: tuple[float, ...] = ()  # show times its runner next wakes to send (`_Robot.dues_s`)
    cue_step: PlannedStep | None = None  # the cue's step it is on, or comes to next: where it is in the cue list
    aborted: bool = False  # a step of it was cut off (stop, panic): its steps did not all end

    @property
    def state(self) -> str:
        if self.step is None:
            return "not_started"
        if self.aborted:
            return "aborted"
        if self.done:
            return "done"
        return "between" if self.ended else "running"

    def to_json(self) -> dict[str, Any]:
        """The `/choreo/status` reply's entry for this robot (labels as the show gives them:
        JSON escapes what a terminal would obey)."""
        step, following = self.step, self.next_step
        return {"robot": self.robot, "state": self.state,
                "step": step.index if step is not None else None,
                "label": step.label if step is not None else None,
                "cue": step.cue if step is not None else None,
                "doing": step.describe() if step is not None else None,
                "next": _step_json(following) if following is not None else None,
                "latency_ms": round(self.latency_ms, 3) if self.latency_ms is not None else None,
                "retries": self.retries, "failed": self.failed}


def _step_json(step: PlannedStep) -> dict[str, Any]:
    return {"step": step.index, "label": step.label, "cue": step.cue, "doing": step.describe()}


@dataclass
class _Robot:
    """One robot as the status keeps it: its steps, where it is in them, its link's replies."""

    name: str
    steps: tuple[PlannedStep, ...]  # its own steps, from where it starts
    at: int = -1  # position in `steps` of its current step (-1: none started)
    ended: bool = False
    aborted: bool = False  # a step ended `aborted`: the robot was stopped mid-show
    started_s: float = 0.0
    latencies_ms: deque[float] = field(default_factory=lambda: deque(maxlen=LATENCIES))
    retries: int = 0
    failed: int = 0
    positions: dict[int, int] = field(default_factory=dict)  # step index -> position in `steps`
    timed: tuple[int, ...] = ()  # position -> the position of the first timed step from it on (or len)
    cued: tuple[int, ...] = ()  # position -> the position of the first cue's step from it on (or len)

    def __post_init__(self) -> None:
        self.positions = {step.index: at for at, step in enumerate(self.steps)}
        self.timed = self._first_from(lambda step: step.at is not None)
        self.cued = self._first_from(lambda step: step.cue is not None)

    def _first_from(self, kind: Callable[[PlannedStep], bool]) -> tuple[int, ...]:
        """For each position, the first from it on of a step of `kind` (len: none): made once,
        so that a show of 10,000 cues is looked up, never walked, at each redraw."""
        first, later = [len(self.steps)] * (len(self.steps) + 1), len(self.steps)
        for at in range(len(self.steps) - 1, -1, -1):
            later = at if kind(self.steps[at]) else later
            first[at] = later
        return tuple(first)

    @property
    def current(self) -> PlannedStep | None:
        return self.steps[self.at] if self.at >= 0 else None

    def moved_to(self, step: PlannedStep, show_s: float, ended: bool = False) -> None:
        self.at = self.positions.get(step.index, self.at)
        self.ended = ended
        self.started_s = show_s

    def step_ended(self, step: PlannedStep, outcome: str | None = None) -> None:
        """A step ended: its own current one (another robot's shared step is not its end);
        one cut off (`aborted`) is no done, even as the last."""
        current = self.current
        if current is not None and current.index == step.index:
            self.ended = True
            self.aborted = self.aborted or outcome == "aborted"

    def replied(self, latency_ms: float, ok: bool) -> None:
        if ok:
            self.latencies_ms.append(latency_ms)
        else:
            self.failed += 1

    def retried(self) -> None:
        self.retries += 1

    def dues_s(self, skipped: Skipped) -> tuple[float, ...]:
        """When, on the show clock, this robot's runner next wakes to send: the end of the wait
        it is in, and its next timed cue not skipped (a step after a play goes at once: no
        wake-up). Skipped cues one after another are the only walk: the rest is looked up."""
        step = self.current
        at = self.timed[self.at + 1]
        while at < len(self.steps) and skipped(self.name, self.steps[at].index):
            at = self.timed[at + 1]
        dues = [self.steps[at].at or 0.0] if at < len(self.steps) else []
        if step is not None and step.kind is StepKind.WAIT and not self.ended:
            dues.append(self.started_s + (step.seconds or 0.0))
        return tuple(dues)

    def following(self, skipped: Skipped) -> PlannedStep | None:
        """The step that will really run next: a cue the operator skipped is passed over."""
        at = self.at + 1
        while at < len(self.steps) and skipped(self.name, self.steps[at].index):
            at += 1
        return self.steps[at] if at < len(self.steps) else None

    def cue_step(self) -> PlannedStep | None:
        """The cue's step it is on (not over), or the next one it comes to."""
        step = self.current
        if step is not None and step.cue is not None and not self.ended:
            return step
        at = self.cued[self.at + 1]
        return self.steps[at] if at < len(self.steps) else None

    def row(self, skipped: Skipped) -> RobotRow:
        latency = statistics.median(self.latencies_ms) if self.latencies_ms else None
        done = self.ended and self.at == len(self.steps) - 1 and not self.aborted
        return RobotRow(self.name, self.current, self.ended, done, self.following(skipped), self.started_s, latency,
                        self.retries, self.failed, self.dues_s(skipped), self.cue_step(), self.aborted)


@dataclass
class _LinkWatch:
    """A robot's link listener: reply latencies and retries."""

    status: ShowStatus
    robot: str

    def on_tx(self, event: TxEvent) -> None:
        if event.attempt > 1:
            self.status.note_retry(self.robot)

    def on_rx(self, event: RxEvent) -> None:
        self.status.note_reply(self.robot, event.latency_s * 1e3, event.reply.ok)


class ShowStatus:
    """Every robot's step and link health; see the module's docstring. `plans` by robot (a
    one-robot show's under SOLO), `starts`: the index each robot's run starts at (--from)."""

    def __init__(self, plans: Mapping[str, Plan], starts: Mapping[str, int]) -> None:
        self._lock = threading.Lock()
        self._robots = {name: _Robot(name, tuple(s for s in plan.steps[starts.get(name, 0):] if s.is_for(name)))
                        for name, plan in plans.items()}

    # -- listeners (the runners' and the links' threads: note and return) ---------------------

    def on_step(self, event: StepEvent) -> None:
        """A step started, ended, or was skipped (the robot passed it: it stands after it)."""
        robot = self._robots.get(event.robot or SOLO)
        if robot is None:
            return
        with self._lock:
            if event.event == "start":
                robot.moved_to(event.step, event.actual_s)
            elif event.event == "skip":
                robot.moved_to(event.step, event.actual_s, ended=True)
            else:
                robot.step_ended(event.step, event.outcome)

    def on_log(self, level: int, message: str, time_ns: int) -> None:
        """Log lines say nothing of where a robot is."""

    def link_listener(self, robot: str) -> LinkListener:
        """The listener for `robot`'s link; whoever opened the links subscribes it (and closes
        the subscription after)."""
        return _LinkWatch(self, robot)

    def note_retry(self, robot: str) -> None:
        known = self._robots.get(robot)
        if known is not None:
            with self._lock:
                known.retried()

    def note_reply(self, robot: str, latency_ms: float, ok: bool) -> None:
        known = self._robots.get(robot)
        if known is None:
            return
        with self._lock:
            known.replied(latency_ms, ok)

    # -- readers -------------------------------------------------------------------------------

    def robots(self, skipped: Skipped = _none_skipped) -> tuple[RobotRow, ...]:
        """Every robot now, in the show's cast order; `skipped` (the live controls' own,
        `Live.skipped`: lock-free) says which cues' steps will not run, so a robot's next step
        is the one it will really take."""
        with self._lock:
            return tuple(robot.row(skipped) for robot in self._robots.values())
