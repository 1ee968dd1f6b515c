"""Which part of a show a run plays: `--from STEP` (from there to the end) or `--loop FROM..TO`
(that section, again and again), as step indices per robot and the show time they start at.

Shared steps are found by index or label, the same step for every robot; tracks by a label's
planned moment, each track from its first step at or after it (a label names a moment of the
show, whichever track it is written in). Everything here is read off the compiled plans before
anything opens: a bad reference is a usage error (exit 2), never a robot that moved.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from choreo.errors import UsageError, did_you_mean
from choreo.show.model import Plan, Show, StepKind

MIN_LOOP_S = 0.1  # a --loop pass's least show time: its motions restart at most 10 times a second


@dataclass(frozen=True)
class Sections:
    """Where each robot's plan starts and (with --loop) stops, and the show time of the start."""

    starts: Mapping[str, int]  # where each robot's plan starts (--from, --loop's FROM), by robot
    origin: float = 0.0  # show time of the first step played, 0 for a whole show
    ends: Mapping[str, int] = field(default_factory=dict)  # where each robot's plan stops (--loop), by robot
    loop: tuple[str, str] | None = None  # `--loop FROM..TO`, as given


def select(show: Show, plans: Mapping[str, Plan], from_step: str | None, loop_text: str | None) -> Sections:
    """The section `--from` or `--loop` names (the whole show without either)."""
    if loop_text is not None and from_step is not None:
        raise UsageError(f"--loop {loop_text}: it starts where it says; leave out --from")
    if loop_text is None:
        starts, origin = _starts(show, plans, from_step, "--from")
        return Sections(starts, origin)
    loop = loop_range(loop_text)
    starts, origin = _starts(show, plans, loop[0], "--loop")
    ends = _ends(show, plans, loop[1], starts, "--loop")
    _check_loop_plays(plans, starts, ends, loop_text)
    _check_loop_length(plans, starts, ends, origin, loop_text)
    return Sections(starts, origin, ends, loop)


def _starts(show: Show, plans: Mapping[str, Plan], ref: str | None,
            option: str = "--from") -> tuple[dict[str, int], float]:
    """Where each robot's plan starts with `--from`, and that step's show time.

    Shared steps: the step by index or label, for every robot. Tracks: the labelled step's
    planned time, and each track from its first step planned at or after it (a label names a
    moment of the show, whichever track it is written in)."""
    if ref is None:
        return dict.fromkeys(plans, 0), 0.0
    if not show.tracks:
        first = next(iter(plans.values()))
        index = start_index(first, ref, option)
        return dict.fromkeys(plans, index), first.steps[index].planned_s if index < len(first.steps) else 0.0
    moment = _moment(plans, ref, f"{option} {ref}")
    return {name: next((s.index for s in plan.steps if s.planned_s >= moment - 1e-9), len(plan.steps))
            for name, plan in plans.items()}, moment


def _moment(plans: Mapping[str, Plan], ref: str, given: str) -> float:
    """The show time of the step labelled `ref` in any track: tracks are named by labels."""
    moment = next((step.planned_s for plan in plans.values() for step in plan.steps if step.label == ref), None)
    if moment is None:
        labels = [s.label for plan in plans.values() for s in plan.steps if s.label]
        raise UsageError(f"{given}: no step with that label in any track{did_you_mean(ref, labels)}"
                         f"{'; labels: ' + ', '.join(labels[:12]) if labels else ''} (tracks are named by labels, "
                         "not indices)")
    return moment


def loop_range(text: str) -> tuple[str, str]:
    """`--loop verse..chorus` -> ("verse", "chorus")."""
    first, sep, last = text.partition("..")
    if not sep or not first.strip() or not last.strip():
        raise UsageError(f"--loop {text}: give FROM..TO, two labels (or step indices from `choreo plan`), "
                         "e.g. --loop verse..chorus")
    return first.strip(), last.strip()


def _ends(show: Show, plans: Mapping[str, Plan], ref: str, starts: Mapping[str, int],
          option: str) -> dict[str, int]:
    """Where each robot's plan stops for --loop's TO (that step included): shared steps by index
    or label; tracks, each at its last step planned at or before the labelled moment."""
    if not show.tracks:
        first = next(iter(plans.values()))
        index = start_index(first, ref, f"{option} ..") + 1
        if index <= starts[first.robot]:
            raise UsageError(f"{option} ..{ref}: it comes before the loop's first step")
        return dict.fromkeys(plans, index)
    moment = _moment(plans, ref, f"{option} ..{ref}")
    ends = {name: 1 + max((s.index for s in plan.steps if s.planned_s <= moment + 1e-9), default=-1)
            for name, plan in plans.items()}
    if all(ends[name] <= starts[name] for name in plans):
        raise UsageError(f"{option} ..{ref}: it comes before the loop's first step")
    return ends


def section_end(plans: Mapping[str, Plan], ends: Mapping[str, int]) -> float:
    """The show time a --loop pass ends at: where the step after the section is planned (the
    show's expected end after the last step), the latest of every robot's."""
    return max(plan.steps[ends[name]].planned_s if ends[name] < len(plan.steps) else plan.estimated_s
               for name, plan in plans.items())


def _check_loop_plays(plans: Mapping[str, Plan], starts: Mapping[str, int], ends: Mapping[str, int],
                      given: str) -> None:
    """A pass of waits alone repeats nothing a robot does (`--loop 1..1` on a lone `wait: done`
    polled a motion it never played, every 0.6 s): a loop is for rehearsing motions."""
    if not any(step.kind is StepKind.PLAY for name, plan in plans.items()
               for step in plan.steps[starts[name]:ends[name]]):
        raise UsageError(f"--loop {given}: the section plays no motion, only waits; a loop repeats plays: "
                         "start it at a `play` step (see `choreo plan` for the steps)")


def _check_loop_length(plans: Mapping[str, Plan], starts: Mapping[str, int], ends: Mapping[str, int],
                       origin: float, given: str) -> None:
    """A pass over (nearly) no show time would restart its motions as fast as the port allows
    (a section of plays and zero-length waits: 1,899 restarts in 2.3 s); a GO cue in it paces it
    by hand, anything else must last MIN_LOOP_S."""
    if any(step.go for name, plan in plans.items() for step in plan.steps[starts[name]:ends[name]]):
        return
    length = section_end(plans, ends) - origin
    if length < MIN_LOOP_S - 1e-9:
        raise UsageError(f"--loop {given}: one pass lasts {max(length, 0.0):.3f} s of show time; a loop needs "
                         f"{MIN_LOOP_S:g} s at least (its motions would restart {_rate(length)}): end it at a "
                         "later step (a `wait: done` after its last play), or add a GO cue to pace it")


def _rate(length: float) -> str:
    return "without pause" if length <= 0 else f"{1 / length:.0f} times a second"


def start_index(plan: Plan, ref: str | None, option: str = "--from") -> int:
    """The index of the step `ref` names (an index or a label); UsageError listing the labels."""
    if ref is None:
        return 0
    try:
        return plan.find(ref)
    except KeyError:
        labels = [s.label for s in plan.steps if s.label]
        shown = ", ".join(labels[:12]) + (", ..." if len(labels) > 12 else "")
        known = f"; labels: {shown}" if labels else ""
        space = "" if option.endswith("..") else " "
        raise UsageError(f"{option}{space}{ref}: no step with that index (0..{len(plan.steps) - 1}) "
                         f"or label{did_you_mean(ref, labels)}{known}") from None
