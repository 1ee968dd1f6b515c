"""The `Show` records built from a document that passed every check.

By the time this runs, the schema and the checks have said everything that can be wrong, so
types are what the schema says and every name resolves: building only converts (motion names to
slot numbers, bars and beats to seconds, defaults filled in) and never reports. A step keeps
its path, line and column, so that the plan and the run can still say where it was written.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypedDict

from choreo.show.model import (
    DEFAULT_DONE_TIMEOUT_S,
    GO,
    LINK,
    LINK_METER,
    MACHINE,
    NOMINAL_BPM,
    LinkClock,
    Motion,
    Music,
    Repeat,
    RobotSettings,
    Show,
    Step,
    StepKind,
    Tempo,
)
from choreo.show.report import Doc, JsonPath, format_path


def build_show(file: str, source: bytes, doc: Doc, folder: Path | None = None) -> Show:
    """The records from data that passed every check (so types are what the schema says)."""
    data = doc.data
    motions = {
        name: Motion(name, int(entry["number"]), _seconds(entry.get("duration")))
        for name, entry in (data.get("motions") or {}).items()
    }
    robots = {name: _robot(entry or {}, motions) for name, entry in (data.get("robots") or {}).items()}
    robot = _robot(data.get("robot") or {}, motions) if not robots else next(iter(robots.values()))
    abort = data.get("on_abort")
    tempo = tempo_of(data["tempo"]) if data.get("tempo") else None
    steps = _Steps(doc, motions, tempo)
    return Show(
        path=file,
        name=data.get("name") or Path(file).stem,
        source=source,
        robot=robot,
        motions=motions,
        on_abort=None if abort is None else _motion_number(abort, motions),
        steps=steps.build(data["steps"], ("steps",)) if "steps" in data else (),
        robots=robots,
        tracks={name: steps.build(track, ("tracks", name)) for name, track in (data.get("tracks") or {}).items()},
        tempo=tempo,
        music=_music(data.get("music"), folder),
        clock=data.get("clock", MACHINE),
        link=link_clock(data.get("tempo")) if data.get("clock") == LINK else None,
        hosts={name: tuple(robots) for name, robots in (data.get("hosts") or {}).items()},
    )


def tempo_of(entry: dict[str, Any]) -> Tempo:
    """`tempo:` as written (checked): beats a minute, the offset to bar 1 and the meter, or a
    tempo map (`bars:`, each bar's beat 1 in show seconds) and the meter."""
    meter = int(entry.get("meter", 4))
    if "bars" in entry:
        return Tempo.of_bars(tuple(float(start) for start in entry["bars"]), meter)
    bpm = NOMINAL_BPM if entry["bpm"] == LINK else float(entry["bpm"])  # `bpm: link`: a plan at a nominal tempo
    return Tempo(bpm, float(entry.get("offset", 0.0)), meter)


def link_clock(tempo: dict[str, Any] | None) -> LinkClock:
    """A show's Link clock from its `tempo:` (checked: one tempo, no offset): the tempo it
    proposes (None for `bpm: link`, or no `tempo:`: the session's) and its meter."""
    if not tempo:
        return LinkClock(None, LINK_METER)
    bpm = tempo.get("bpm")
    return LinkClock(None if bpm in (None, LINK) else float(bpm), int(tempo.get("meter", LINK_METER)))


def _music(entry: dict[str, Any] | None, folder: Path | None) -> Music | None:
    if not entry:
        return None
    return Music(entry["file"], float(entry.get("start", 0.0)), str(folder) if folder is not None else ".")


def _robot(entry: dict[str, Any], motions: dict[str, Motion]) -> RobotSettings:
    abort = entry.get("on_abort")
    return RobotSettings(
        port=entry.get("port"),
        baud=entry.get("baud"),
        timeout=_seconds(entry.get("timeout")),
        retries=entry.get("retries"),
        layout=entry.get("layout"),
        on_abort=None if abort is None else _motion_number(abort, motions),
        on_fault=entry.get("on_fault", "stop"),
    )


class _Common(TypedDict):
    """What every step and repeat has, whatever it does."""

    path: str
    line: int
    column: int
    label: str | None
    at: float | None
    at_beat: tuple[int, float] | None
    go: bool
    cue: str | None
    robots: tuple[str, ...] | None


class _Steps:
    """Builds step lists (`steps:` or a track) of one show: its motions and tempo at hand."""

    def __init__(self, doc: Doc, motions: dict[str, Motion], tempo: Tempo | None) -> None:
        self.doc = doc
        self.motions = motions
        self.tempo = tempo

    def build(self, steps: list[dict[str, Any]], path: JsonPath) -> tuple[Step | Repeat, ...]:
        return tuple(self._one(step, path + (index,)) for index, step in enumerate(steps))

    def _one(self, step: dict[str, Any], here: JsonPath) -> Step | Repeat:
        common = self._common(step, here)
        if "repeat" in step:
            return Repeat(count=int(step["repeat"]), steps=self.build(step["steps"], here + ("steps",)), **common)
        if "play" in step:
            ref = step["play"]
            name = ref if isinstance(ref, str) else None
            return Step(kind=StepKind.PLAY, motion=_motion_number(ref, self.motions), motion_name=name, **common)
        if step["wait"] == "done":
            timeout = _seconds(step.get("timeout"))
            seconds = DEFAULT_DONE_TIMEOUT_S if timeout is None else timeout
            return Step(kind=StepKind.WAIT_DONE, seconds=seconds, **common)
        return Step(kind=StepKind.WAIT, seconds=float(step["wait"]), **common)

    def _common(self, step: dict[str, Any], here: JsonPath) -> _Common:
        line, column = self.doc.mark(here)
        go = step.get("at") == GO
        at, at_beat = self._cue(None if go else step.get("at"))
        cue = cue_text(self.doc, step["cue"], here + ("cue",)) if "cue" in step else None
        return _Common(path=format_path(here), line=line, column=column, label=step.get("label"), at=at,
                       at_beat=at_beat, go=go, cue=cue, robots=tuple(step["robots"]) if "robots" in step else None)

    def _cue(self, at: Any) -> tuple[float | None, tuple[int, float] | None]:
        """A cue as seconds, and as bar and beat if it was written so (checked: tempo exists)."""
        if isinstance(at, dict):
            bar, beat = int(at["bar"]), float(at.get("beat", 1))
            assert self.tempo is not None, "a bar-and-beat cue without a tempo passed the checks"
            return self.tempo.seconds(bar, beat), (bar, beat)
        return _seconds(at), None


def cue_text(doc: Doc, value: str | int | float, path: JsonPath) -> str:
    """A cue number as the file wrote it: text as it is, a number as its digits were typed
    (`12.50`, which YAML reads as the float 12.5), so the operator calls it by what they wrote."""
    if isinstance(value, str):
        return value
    return doc.text(path) or str(value)


def _motion_number(ref: int | float | str, motions: dict[str, Motion]) -> int:
    return motions[ref].number if isinstance(ref, str) else int(ref)


def _seconds(value: Any) -> float | None:
    return None if value is None else float(value)
