"""Compile a checked `Show` into the flat, timed `Plan` the runner walks.

Repeats expand in place. Each plan step gets a path back to where it was written: an iteration
of a repeat is marked `#K` (1-based) on the repeat's path, so the second pass over the first
step of a repeat at `steps[3]` is `steps[3]#2.steps[0]`, and repeats nest:
`steps[3]#2.steps[1]#1.steps[0]`. Labels inside a repeat get the same marks after the first
pass (`chorus`, then `chorus#2`, `chorus#3`), so each plan step has its own name for `--from`.

Timing, on the show clock (0 when the first step starts): a step is due at
max(its `at` cue, the end of the step before). A `play` takes no time; `wait X` takes X;
`wait: done` takes what is left of the last played motion's expected duration (its
`duration:` in `motions:`, else `DEFAULT_MOTION_S`) counted from that play's start, and a
second `wait: done` with no play in between takes 0. The runner applies the same rule with
the real end of each motion, so these are estimates only where motions are concerned.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from choreo.wire import protocol
from choreo.wire.layouts import DEFAULT_LAYOUT, Layout, layout_named
from choreo.show.cues import numbered
from choreo.show.load import load_show
from choreo.show.model import DEFAULT_MOTION_S, Plan, PlannedStep, Repeat, Show, Step, StepKind

_DIGITS = 9  # sums are rounded to the nanosecond so that 0.1 + 0.2 plans as 0.3


@dataclass(frozen=True)
class _Flat:
    """A step as it occurs in the run, before timing."""

    step: Step
    path: str
    label: str | None
    at: float | None
    robots: tuple[str, ...] | None = None  # who does it (a repeat's robots pass to its steps)
    at_beat: tuple[int, float] | None = None  # the cue in bars and beats, as written
    go: bool = False  # waits for the operator's GO
    cue: str | None = None  # the cue number the show gives it (`cue:`), if any


def compile_plan(show: Show, layout: Layout | None = None, baud: int | None = None) -> Plan:
    """The plan of a one-robot show (with several robots, the first robot's): the show's steps
    with repeats expanded, each with its planned start and frames.

    The frames are the ones the run sends with `layout` and `baud` (default: the show's
    robot settings); an hth4-2.2 play's suspend and resume show `layouts.EXAMPLE_CONFIG`, as
    the run makes them from the config word it reads from the board.
    """
    first = next(iter(show.cast))
    return compile_plans(show, {first: layout} if layout else {}, {first: baud} if baud else {})[first]


def compile_plans(show: Show, layouts: Mapping[str, Layout] | None = None,
                  bauds: Mapping[str, int] | None = None) -> dict[str, Plan]:
    """Every robot's plan, by name, on the one show clock.

    With `tracks:` each robot's plan is its own track. With shared `steps:` every robot's plan
    holds every step (same index, same planned start), the ones for other robots marked so
    (`PlannedStep.robots`): a step starts when every robot it is for is through the one
    before, so the plans stay in step. `layouts`/`bauds` override the show's per robot.
    """
    layouts = layouts or {}
    bauds = bauds or {}
    links = {name: (layouts.get(name) or layout_named(settings.layout or DEFAULT_LAYOUT),
                    bauds.get(name) or settings.baud or protocol.DEFAULT_BAUD)
             for name, settings in show.cast.items()}
    if show.tracks:
        return numbered({name: _compile(show, _flatten(show.tracks[name]), {name: links[name]}, unison=False)[name]
                         for name in show.cast})
    return numbered(_compile(show, _flatten(show.steps), links, unison=show.ensemble))


def _compile(show: Show, flats: list[_Flat], links: dict[str, tuple[Layout, int]], unison: bool) -> dict[str, Plan]:
    """Time the flat steps: a step is due at max(its cue, the end of the step before), the
    end being, for `wait: done`, the latest expected end of the motions of the robots it is for."""
    names = tuple(links)
    steps: dict[str, list[PlannedStep]] = {name: [] for name in names}
    ends = _Ends(show, names)
    frames = _Frames(links)
    clock = 0.0  # end of the step before, on the show clock
    for index, flat in enumerate(flats):
        step = flat.step
        who = flat.robots or names
        start = max(clock, flat.at or 0.0)  # never rounded below its cue
        expected, motions = ends.take(flat, who, start)
        for name in names:
            motion = step.motion if step.kind is StepKind.PLAY else motions.get(name)
            steps[name].append(PlannedStep(
                index=index, path=flat.path, kind=step.kind, line=step.line, label=flat.label, motion=motion,
                motion_name=step.motion_name if step.kind is StepKind.PLAY else _name_of(show, motion),
                seconds=step.seconds, at=flat.at, at_beat=flat.at_beat, go=flat.go, cue=flat.cue, planned_s=start,
                expected_s=expected, frames=frames.of(name, step) if name in who else (),
                robots=flat.robots if unison else None))
        clock = max(start, _round(start + expected))  # rounding never moves time backwards
    return {name: Plan(tuple(steps[name]), clock, links[name][0].name, name, unison) for name in names}


class _Ends:
    """Per robot, its last play and whether its end has been waited for: what `wait: done` takes."""

    def __init__(self, show: Show, names: tuple[str, ...]) -> None:
        self.show = show
        self.last_play: dict[str, tuple[float, int, float] | None] = dict.fromkeys(names)  # (start, motion, duration)
        self.waited = dict.fromkeys(names, True)

    def take(self, flat: _Flat, who: tuple[str, ...], start: float) -> tuple[float, dict[str, int]]:
        """The step's expected length from `start`, and for `wait: done` the motion each robot waits for."""
        step = flat.step
        if step.kind is StepKind.PLAY:
            assert step.motion is not None, f"{flat.path}: a play step without a motion"
            for name in who:
                self.last_play[name] = (start, step.motion, _duration(self.show, step.motion))
                self.waited[name] = False
            return 0.0, {}
        if step.kind is StepKind.WAIT:
            return float(step.seconds or 0.0), {}
        expected = max((_rest(self.last_play[name], start) for name in who if not self.waited[name]), default=0.0)
        motions = {name: play[1] for name in who if (play := self.last_play[name]) is not None}
        self.waited.update(dict.fromkeys(who, True))
        return expected, motions


class _Frames:
    """The frames each robot's link sends for a step; a play's sequence is built once per robot
    and motion (frames are immutable, and a show plays the same few motions again and again)."""

    def __init__(self, links: dict[str, tuple[Layout, int]]) -> None:
        self.links = links
        self.sequences: dict[tuple[str, int], tuple[protocol.Frame, ...]] = {}

    def of(self, name: str, step: Step) -> tuple[protocol.Frame, ...]:
        layout, baud = self.links[name]
        if step.kind is StepKind.WAIT:
            return ()
        if step.kind is StepKind.WAIT_DONE:
            return (layout.status,)
        assert step.motion is not None, f"{step.path}: a play step without a motion"
        key = (name, step.motion)
        found = self.sequences.get(key)
        if found is None:
            found = self.sequences[key] = layout.play_sequence(step.motion, baud=baud)
        return found


def _rest(play: tuple[float, int, float] | None, now: float) -> float:
    """What is left at `now` of a play's expected duration."""
    if play is None:
        return 0.0
    return max(0.0, _round(play[0] + play[2] - now))


def load_plan(path: str | Path) -> tuple[Show, Plan]:
    """Load, check and compile a show file in one call (`ShowError` if it cannot be run)."""
    show = load_show(path)
    return show, compile_plan(show)


def late_cues(plan: Plan) -> list[PlannedStep]:
    """Steps whose cue the plan already misses: the steps before them take longer than the cue allows."""
    return [s for s in plan.steps if s.at is not None and s.planned_s > s.at + 1e-9]


def _flatten(steps: tuple[Step | Repeat, ...], prefix: str = "", marks: str = "",
             robots: tuple[str, ...] | None = None) -> list[_Flat]:
    """Run order. `prefix` is the enclosing iteration's path; `marks` its `#K` suffixes for
    labels; `robots` the enclosing repeat's robots."""
    out: list[_Flat] = []
    for item in steps:
        path = prefix + _local(item.path)
        who = item.robots or robots
        if isinstance(item, Step):
            out.append(_Flat(item, path, _label(item.label, marks), item.at, who, item.at_beat, item.go, item.cue))
            continue
        for k in range(1, item.count + 1):
            inner = _flatten(item.steps, f"{path}#{k}.", marks + f"#{k}", who)
            if k == 1 and inner and (item.at is not None or item.label is not None or item.go or item.cue):
                first = inner[0]
                cues = [(a, b) for a, b in ((item.at, item.at_beat), (first.at, first.at_beat)) if a is not None]
                at, at_beat = max(cues, key=lambda cue: cue[0]) if cues else (None, None)
                inner[0] = _Flat(first.step, first.path, first.label or _label(item.label, marks), at,
                                 first.robots, at_beat, first.go or item.go, first.cue or item.cue)
            out.extend(inner)
    return out


def _local(path: str) -> str:
    """The last component of a step's source path: `steps[3].steps[1]` -> `steps[1]` (a
    track's own steps keep theirs whole: `tracks.lead[2]`)."""
    at = path.rfind("steps[")
    return path[at:] if at >= 0 else path


def _label(label: str | None, marks: str) -> str | None:
    """Labels keep their own name on every first pass, and get the pass marks after that."""
    if label is None:
        return None
    return label if all(m == "1" for m in marks.split("#")[1:]) else label + marks


def _duration(show: Show, motion: int) -> float:
    given = show.duration_of(motion)
    return DEFAULT_MOTION_S if given is None else given


def _name_of(show: Show, motion: int | None) -> str | None:
    for entry in show.motions.values():
        if entry.number == motion:
            return entry.name
    return None


def _round(seconds: float) -> float:
    return round(seconds, _DIGITS)
