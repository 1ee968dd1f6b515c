"""The show's cue list, as a stage manager reads it: every cued step (a GO cue, a timed cue)
numbered, QLab style, in show order.

A cue is a step with `at:` (a time, a bar and beat, or `go`). Its number is the one the show
file gives (`cue: 12.5`) or, for the others, the next whole number after the cue before it that
no cue of the show has taken: `1, 2, 3` in a show that gives none, `1, 2, 2.5, 3` when one is
put between. Numbers are text (`12.5` is not `12.50`), compared as written; labels name cues too.

Pure: plans in, numbered plans and a cue list out; the live controls, the console, OSC, the
plan's text and the reviews all read numbers from here, so a cue has one number everywhere.
"""

from __future__ import annotations

import difflib
import re
import unicodedata
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, replace
from decimal import Decimal
from typing import Any

from choreo.errors import ChoreoError
from choreo.show.model import Plan, PlannedStep

NUMBER_RE = re.compile(r"[0-9]+(\.[0-9]+)?")  # a cue number that counts: `12`, `12.5`
MAX_NUMBER_CHARS = 16  # the longest cue number a show may give (the schema's `maxLength` says the same)


class CueNotFound(ChoreoError):
    """A cue named (by number or label) that the show does not have, or a label two cues share."""


@dataclass(frozen=True)
class Cue:
    """One cue of the list: its number, label, who it is for and when the plan puts it.

    `steps`: the step each robot starts at it, `(robot, index)`; a shared step (`steps:` of a
    show for one robot or several) is one index for every robot, a track's cue is one robot's."""

    number: str
    label: str | None
    robots: tuple[str, ...]
    planned_s: float
    go: bool  # waits for the operator's GO; else timed (`at` seconds, bars and beats resolved)
    at: float | None = None
    at_beat: tuple[int, float] | None = None
    steps: tuple[tuple[str, int], ...] = ()

    @property
    def name(self) -> str:
        """How messages name it: `cue 3 'bow'`, `cue 3`."""
        return f"cue {self.number}" + (f" '{self.label}'" if self.label else "")

    def starts(self, robot: str, index: int) -> bool:
        """Is step `index` of `robot`'s plan where this cue starts?"""
        return (robot, index) in self.steps

    def to_json(self) -> dict[str, Any]:
        """The cue as every JSON output gives it (`choreo plan --json`, `/choreo/status`)."""
        return {"number": self.number, "label": self.label, "robots": list(self.robots),
                "planned_s": round(self.planned_s, 6), "go": self.go, "at": self.at,
                "bar": self.at_beat[0] if self.at_beat else None, "beat": self.at_beat[1] if self.at_beat else None}


@dataclass(frozen=True)
class CueList:
    """Every cue of a show, in show order; see the module's docstring.

    Indexed once when made, so that a show of 10,000 cues answers `of_step` (asked at every
    step), `find` and `position` without a walk of the list."""

    cues: tuple[Cue, ...] = ()
    _index: _Index = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_index", _Index.of(self.cues))

    def __iter__(self) -> Iterator[Cue]:
        return iter(self.cues)

    def __len__(self) -> int:
        return len(self.cues)

    def position(self, cue: Cue) -> int:
        """Where `cue` is in the list (ValueError if it is not one of its cues)."""
        found = self._index.positions.get(cue)
        if found is None:
            raise ValueError(f"{cue.name} is not in this cue list")
        return found

    def of_step(self, robot: str, index: int) -> Cue | None:
        """The cue `robot`'s step `index` starts, if it starts one."""
        return self._index.steps.get((robot, index))

    def find(self, ref: str) -> Cue:
        """The cue `ref` names: a number as the list writes it, a number of the same value
        (`12.50` for `12.5`), else a label. CueNotFound, with what there is, otherwise."""
        index = self._index
        found = index.numbers.get(ref)
        value = _value(ref) if found is None else None
        if value is not None:
            found = index.values.get(value)
        if found is not None:
            return found
        named = index.labels.get(unicodedata.normalize("NFC", ref), ())  # é typed or sent either way
        if len(named) > 1:
            numbers = ", ".join(cue.number for cue in named[:12]) + (", ..." if len(named) > 12 else "")
            raise CueNotFound(f"cue {quoted(ref)} is ambiguous: cues {numbers} are all labelled so; give the number")
        if named:
            return named[0]
        known = ", ".join(cue.number for cue in self.cues[:12]) + (", ..." if len(self.cues) > 12 else "")
        near = _nearest(self.cues, ref)
        meant = f": did you mean {near.name}?" if near is not None else ""
        raise CueNotFound(f"no cue {quoted(ref)} in this show (cues: {known or 'none'}){meant}")


@dataclass(frozen=True)
class _Index:
    """A cue list's lookups; the first cue wins where two share a key (a show's checks refuse that)."""

    positions: dict[Cue, int]
    steps: dict[tuple[str, int], Cue]
    numbers: dict[str, Cue]
    values: dict[Decimal, Cue]
    labels: dict[str, tuple[Cue, ...]]

    @classmethod
    def of(cls, cues: tuple[Cue, ...]) -> _Index:
        positions: dict[Cue, int] = {}
        steps: dict[tuple[str, int], Cue] = {}
        numbers: dict[str, Cue] = {}
        values: dict[Decimal, Cue] = {}
        labels: dict[str, tuple[Cue, ...]] = {}
        for position, cue in enumerate(cues):
            positions.setdefault(cue, position)
            for step in cue.steps:
                steps.setdefault(step, cue)
            numbers.setdefault(cue.number, cue)
            value = _value(cue.number)
            if value is not None:
                values.setdefault(value, cue)
            if cue.label is not None:
                label = unicodedata.normalize("NFC", cue.label)
                labels[label] = (*labels.get(label, ()), cue)
        return cls(positions, steps, numbers, values, labels)


def _nearest(cues: tuple[Cue, ...], ref: str) -> Cue | None:
    """The cue a mistyped reference most likely meant: the first whose label (in any case:
    `curt`, `curtain`) or number (`12`, `12.5`) starts with it, else, in a list of at most
    NEAREST_AMONG cues, the closest label's start (difflib). A typed or sent reference may be
    anything: it is cut first, and a long list only looked through once."""
    typed = ref.strip().casefold()[:NEAREST_CHARS]
    if not typed:
        return None
    found = next((cue for cue in cues if (cue.label or "").casefold().startswith(typed)
                  or cue.number.startswith(typed)), None)
    if found is not None or len(cues) > NEAREST_AMONG:
        return found
    size = len(typed) + 8  # a label is compared by its start: the cost stays bounded by what was typed
    labels = {cue.label.casefold()[:size]: cue for cue in reversed(cues) if cue.label}
    close = difflib.get_close_matches(typed, list(labels), n=1, cutoff=0.6)
    return labels[close[0]] if close else None


NEAREST_AMONG = 100  # cues a mistyped reference is compared with (difflib) for a suggestion
NEAREST_CHARS = 24  # of a reference, compared for a suggestion (a label longer than that is typed by number)


def quoted(ref: str) -> str:
    """A cue reference as every message quotes it (the cue list's and the live controls'):
    escaped (`repr`) and cut, since it was typed or sent."""
    return repr(ref) if len(ref) <= SHOWN_CHARS else repr(ref[:SHOWN_CHARS]) + "…"


SHOWN_CHARS = 40  # of a typed or sent cue reference, repeated in a message


def _value(number: str) -> Decimal | None:
    """A number that counts as its value (`12.50` is `12.5`); None for text (`A3`), and for a
    reference longer than any cue number (a typed or sent one may be anything)."""
    return Decimal(number) if len(number) <= MAX_NUMBER_CHARS and NUMBER_RE.fullmatch(number) else None


def number_key(number: str) -> Decimal | str:
    """What makes two cue numbers the same: a number's value (`12.5`, `12.50`), text as written.
    The show's checks refuse a second cue by this key, and numbering never takes one."""
    value = _value(number)
    return number if value is None else value


def _shared(plans: Mapping[str, Plan]) -> bool:
    """One step list for every robot (`steps:`): a step index is the same cue in every plan."""
    return len(plans) == 1 or any(plan.unison for plan in plans.values())


def _cued(plans: Mapping[str, Plan]) -> list[tuple[PlannedStep, tuple[tuple[str, int], ...], tuple[str, ...]]]:
    """Each cued step once, in show order, with the (robot, index) pairs it starts and its robots."""
    names = list(plans)
    if _shared(plans):
        first = plans[names[0]]
        out = []
        for step in first.steps:
            if step.at is None and not step.go:
                continue
            robots = tuple(name for name in names if step.is_for(name))
            out.append((step, tuple((name, step.index) for name in robots), robots))
        return out
    tracked = [(step.planned_s, names.index(name), step.index, name, step)
               for name, plan in plans.items() for step in plan.steps if step.at is not None or step.go]
    tracked.sort(key=lambda item: item[:3])
    return [(step, ((name, step.index),), (name,)) for _, _, _, name, step in tracked]


def _numbers(given: list[str | None]) -> list[str]:
    """Each cue's number: the one given, else the next whole number after the cue before that
    no cue has taken (see the module's docstring)."""
    taken = {number_key(number) for number in given if number is not None}
    jumps: dict[int, int] = {}  # a taken whole number -> a later one to look from
    out: list[str] = []
    last = Decimal(0)
    for number in given:
        if number is None:
            candidate = _free(int(last) + 1, taken, jumps)
            number = str(candidate)
            taken.add(Decimal(candidate))
        value = _value(number)
        if value is not None:
            last = value
        out.append(number)
    return out


def _free(candidate: int, taken: set[Decimal | str], jumps: dict[int, int]) -> int:
    """The first whole number from `candidate` on that no cue has taken. The numbers walked
    past remember where the walk ended, so a run of taken numbers is crossed once, not once
    a cue (a show of cues `1.1, ?, 1.2, ?, ...` before `2 .. 5000` would cost millions)."""
    walked = []
    while Decimal(candidate) in taken:
        walked.append(candidate)
        candidate = jumps.get(candidate, candidate + 1)
    for number in walked:
        jumps[number] = candidate
    return candidate


def numbered(plans: Mapping[str, Plan]) -> dict[str, Plan]:
    """The plans with every cued step's `cue` set to its number (the show's own, or its place)."""
    cued = _cued(plans)
    numbers = _numbers([step.cue for step, _, _ in cued])
    by_step: dict[tuple[str, int], str] = {}
    for (_, steps, _), number in zip(cued, numbers, strict=True):
        for key in steps:
            by_step[key] = number
    return {name: replace(plan, steps=tuple(replace(step, cue=by_step[(name, step.index)])
                                            if (name, step.index) in by_step else step for step in plan.steps))
            for name, plan in plans.items()}


def cue_list(plans: Mapping[str, Plan]) -> CueList:
    """The cue list of numbered plans (`numbered`), in show order."""
    cues = []
    for step, steps, robots in _cued(plans):
        assert step.cue is not None, "cue_list reads numbered plans"
        cues.append(Cue(step.cue, step.label, robots, step.planned_s, step.go, step.at, step.at_beat, steps))
    return CueList(tuple(cues))
