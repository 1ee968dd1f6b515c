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

from dataclasses import dataclass
from pathlib import Path

from choreo import protocol
from choreo.layouts import Layout, layout_named
from choreo.show.model import DEFAULT_MOTION_S, Plan, PlannedStep, Repeat, Show, Step, StepKind

_DIGITS = 9  # sums are rounded to the nanosecond so that 0.1 + 0.2 plans as 0.3


@dataclass(frozen=True)
class _Flat:
    """A step as it occurs in the run, before timing."""

    step: Step
    path: str
    label: str | None
    at: float | None


def compile_plan(show: Show, layout: Layout | None = None, baud: int | None = None) -> Plan:
    """The show's steps with repeats expanded, each with its planned start and frames.

    The frames are the ones the run sends with `layout` and `baud` (default: the show's
    robot settings); an hth4-2.2 play's suspend and resume show `layouts.EXAMPLE_CONFIG`, as
    the run makes them from the config word it reads from the board.
    """
    layout = layout or layout_named(show.robot.layout or "seed")
    baud = baud or show.robot.baud or protocol.DEFAULT_BAUD
    planned: list[PlannedStep] = []
    clock = 0.0  # end of the step before, on the show clock
    last_play: tuple[float, int, float] | None = None  # (start, motion, expected duration)
    waited = True  # whether the last play's end has been waited for already
    sequences: dict[int, tuple[protocol.Frame, ...]] = {}  # frames are immutable: build each once
    status = (layout.status,)
    for index, flat in enumerate(_flatten(show.steps)):
        step = flat.step
        start = max(clock, flat.at or 0.0)  # never rounded below its cue
        motion = step.motion
        if step.kind is StepKind.PLAY:
            assert motion is not None, f"{flat.path}: a play step without a motion"
            expected = 0.0
            last_play = (start, motion, _duration(show, motion))
            waited = False
            frames: tuple[protocol.Frame, ...] = sequences.get(motion) or sequences.setdefault(motion, layout.play_sequence(motion, baud=baud))
        elif step.kind is StepKind.WAIT:
            expected = float(step.seconds or 0.0)
            frames = ()
        else:
            motion = last_play[1] if last_play else None
            expected = 0.0 if waited or last_play is None else max(0.0, _round(last_play[0] + last_play[2] - start))
            waited = True
            frames = status
        planned.append(
            PlannedStep(
                index=index,
                path=flat.path,
                kind=step.kind,
                line=step.line,
                label=flat.label,
                motion=motion,
                motion_name=step.motion_name if step.kind is StepKind.PLAY else _name_of(show, motion),
                seconds=step.seconds,
                at=flat.at,
                planned_s=start,
                expected_s=expected,
                frames=frames,
            )
        )
        clock = max(start, _round(start + expected))  # rounding never moves time backwards
    return Plan(tuple(planned), clock, layout.name)


def load_plan(path: str | Path) -> tuple[Show, Plan]:
    """Load, check and compile a show file in one call (`ShowError` if it cannot be run)."""
    from choreo.show.load import load_show

    show = load_show(path)
    return show, compile_plan(show)


def late_cues(plan: Plan) -> list[PlannedStep]:
    """Steps whose cue the plan already misses: the steps before them take longer than the cue allows."""
    return [s for s in plan.steps if s.at is not None and s.planned_s > s.at + 1e-9]


def _flatten(steps: tuple[Step | Repeat, ...], prefix: str = "", marks: str = "") -> list[_Flat]:
    """Run order. `prefix` is the enclosing iteration's path; `marks` its `#K` suffixes for labels."""
    out: list[_Flat] = []
    for item in steps:
        path = prefix + _local(item.path)
        if isinstance(item, Step):
            out.append(_Flat(item, path, _label(item.label, marks), item.at))
            continue
        for k in range(1, item.count + 1):
            inner = _flatten(item.steps, f"{path}#{k}.", marks + f"#{k}")
            if k == 1 and inner and (item.at is not None or item.label is not None):
                first = inner[0]
                cues = [a for a in (item.at, first.at) if a is not None]
                at = max(cues) if cues else None
                inner[0] = _Flat(first.step, first.path, first.label or _label(item.label, marks), at)
            out.extend(inner)
    return out


def _local(path: str) -> str:
    """The last component of a step's source path: `steps[3].steps[1]` -> `steps[1]`."""
    return path[path.rfind("steps[") :]


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
