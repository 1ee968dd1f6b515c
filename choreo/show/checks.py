"""What a schema cannot say about a show: the checks of its meaning.

Motion names exist, `wait: done` follows a play, cues do not go back in time, labels are
unique, no two robots share a port, every declared robot has a track, the music can be played,
the show does not expand to an absurd number of steps. The checks run after the schema's, on
what it left standing: a value the schema (or the reading) has already found wrong is skipped
(`_Walk.ok`), so that one mistake gets one message.
"""

from __future__ import annotations

import unicodedata
from dataclasses import dataclass, field
from decimal import Decimal
from pathlib import Path
from typing import Any, TypeGuard

from choreo.show.build import cue_text, tempo_of
from choreo.show.cues import MAX_NUMBER_CHARS, NUMBER_RE, number_key
from choreo.show.model import (
    GO,
    LINK,
    LINK_NO_GO,
    LINK_MIN_BPM,
    LINK_NO_MAP,
    LINK_NO_MUSIC,
    LINK_NO_OFFSET,
    MAX_BPM,
    MAX_CUE_S,
    MUSIC_FORMATS,
    SOLO,
    Tempo,
    hidden_character,
    is_simulator,
    same_port,
)
from choreo.show.report import Doc, JsonPath, Report, closest, format_path, value_text
from choreo.userfile import problem as file_problem

MAX_PLAN_STEPS = 100_000  # steps after repeats expand


@dataclass
class _Walk:
    """What the semantic pass carries along the steps, in run order."""

    doc: Doc
    report: Report
    motions: dict[str, Any] = field(default_factory=dict)  # name -> entry, the well-formed ones
    labels: dict[str, JsonPath] = field(default_factory=dict)
    cues: dict[Decimal | str, tuple[str, JsonPath]] = field(default_factory=dict)  # cue numbers given: text, where
    last_cue: tuple[float, JsonPath] | None = None
    played: set[str] = field(default_factory=set)  # robots that have played a motion so far
    robots: tuple[str, ...] = (SOLO,)  # the robots of the step list being walked
    declared: tuple[str, ...] = ()  # `robots:` (empty for a one-robot show)
    in_track: bool = False
    tempo: Tempo | None = None  # the show's tempo when it is usable (checked)
    link: bool = False  # `clock: link`: the Link session's beat keeps the show clock

    def ok(self, path: JsonPath) -> bool:
        """Whether the value at `path` passed the schema (so it is the type it should be)."""
        return self.report.passed(path)

    def problem(self, path: JsonPath, message: str) -> None:
        """A problem with the value at `path`."""
        self.report.add(self.doc.mark(path), path, message)

    def key_problem(self, path: JsonPath, message: str) -> None:
        """A problem with the key at `path` (what it names), pointed at the key."""
        self.report.add(self.doc.key_mark(path), path, message)


def check_meaning(doc: Doc, report: Report, folder: Path | None = None) -> None:
    """Report every meaning check the document fails. `folder`: where the show file is, to
    look for its music there (None: not looked for). None when the schema stopped looking:
    a value past where it stopped may be of any type."""
    if report.stopped():
        return
    data = doc.data
    walk = _Walk(doc, report)
    motions = data.get("motions") if isinstance(data.get("motions"), dict) else {}
    walk.motions = {name: entry for name, entry in motions.items()
                    if isinstance(entry, dict) and walk.ok(("motions", name))}
    _check_motion_table(walk)
    if isinstance(data.get("name"), str) and walk.ok(("name",)):
        _check_visible(walk, ("name",), data["name"], "the show's name")
    if "on_abort" in data and walk.ok(("on_abort",)):
        _check_motion_ref(walk, ("on_abort",), data["on_abort"])
    _check_robots(walk)
    _check_link(walk)
    _check_hosts(walk)
    if not walk.link:  # on the Link clock `music:` is refused, its file not looked for
        _check_music(walk, folder)
    walk.tempo = _checked_tempo(walk)
    steps = data.get("steps")
    if isinstance(steps, list) and walk.ok(("steps",)):
        walk.robots = walk.declared or (SOLO,)
        _check_total(walk, ("steps",), _check_steps(walk, steps, ("steps",), looping=False))
    tracks = data.get("tracks")
    if isinstance(tracks, dict) and walk.ok(("tracks",)) and walk.declared:
        _check_tracks(walk, tracks)


def _check_music(walk: _Walk, folder: Path | None) -> None:
    """A sound file choreo can decode, which exists beside the show (when it has a folder)."""
    music = walk.doc.data.get("music")
    path = ("music", "file")
    if not isinstance(music, dict) or not isinstance(music.get("file"), str) or not walk.ok(path):
        return
    file = music["file"]
    if Path(file).suffix.lower() not in MUSIC_FORMATS:
        walk.problem(path, f"{file}: choreo plays {', '.join(f[1:] for f in MUSIC_FORMATS)} "
                           "files: convert it, or give one of those")
    elif folder is not None:
        where = folder / file
        what = file_problem(where, "sound file")
        if what is not None:
            walk.problem(path, f"{file}: {what} ({where}; the path is relative to the show file)")


def _check_total(walk: _Walk, path: JsonPath, total: int) -> None:
    if total > MAX_PLAN_STEPS:
        walk.key_problem(path, f"the show expands to {total:,} steps or more; the limit is {MAX_PLAN_STEPS:,}")


# --------------------------------------------------------------------------- robots


def _check_robots(walk: _Walk) -> None:
    """Each robot's abort motion is a motion; no two robots share a port; `on_fault` is for
    a robot among several."""
    data = walk.doc.data
    robot = data.get("robot")
    if isinstance(robot, dict) and "on_fault" in robot and walk.ok(("robot", "on_fault")):
        walk.key_problem(("robot", "on_fault"),
                         "`on_fault` decides what the other robots do: it is for a robot in `robots:`")
    if isinstance(robot, dict) and "on_abort" in robot and walk.ok(("robot", "on_abort")):
        _check_motion_ref(walk, ("robot", "on_abort"), robot["on_abort"])
    robots = data.get("robots")
    if not isinstance(robots, dict) or not walk.ok(("robots",)):
        return
    walk.declared = tuple(robots)
    ports: dict[tuple[str | None, str], str] = {}
    host_of = _host_of(data.get("hosts"))  # robots on different hosts (computers) may each have a ttyUSB0
    for name, settings in robots.items():
        here = ("robots", name)
        if not isinstance(settings, dict) or not walk.ok(here):
            continue
        if "on_abort" in settings and walk.ok(here + ("on_abort",)):
            _check_motion_ref(walk, here + ("on_abort",), settings["on_abort"])
        port = settings.get("port")
        if not isinstance(port, str) or is_simulator(port.strip()):
            continue  # every simulator is a board of its own
        first = ports.setdefault((host_of.get(name), same_port(port)), name)
        if first != name:
            walk.problem(here + ("port",), f"port {port} is already robot {first}'s: each robot needs its own port")


def _host_of(hosts: Any) -> dict[str, str]:
    """Each robot's host as `hosts:` says (the first that names it), before its checks."""
    if not isinstance(hosts, dict):
        return {}
    return {name: host for host, robots in reversed(hosts.items()) if isinstance(robots, list)
            for name in robots if isinstance(name, str)}


# --------------------------------------------------------------------------- the Link clock, hosts


def _check_link(walk: _Walk) -> None:
    """`clock: link`: the session's beat keeps the show clock, so nothing else may: no music,
    no tempo map, no offset to bar 1 (GO cues: `_check_cue`). `bpm: link` needs the session."""
    data = walk.doc.data
    walk.link = data.get("clock") == LINK and walk.ok(("clock",))
    tempo = data.get("tempo")
    tempo = tempo if isinstance(tempo, dict) and walk.ok(("tempo",)) else {}
    if tempo.get("bpm") == LINK and not walk.link:
        walk.problem(("tempo", "bpm"), "`bpm: link` takes the Ableton Link session's tempo: add `clock: link`, "
                                       "or give the beats a minute")
    if not walk.link:
        return
    offset = tempo.get("offset")
    if _number(offset) and offset != 0 and walk.ok(("tempo", "offset")):
        walk.problem(("tempo", "offset"), f"{LINK_NO_OFFSET}: leave out `offset:` (or write 0), or use "
                                          "`clock: machine`")
    if "bars" in tempo:
        walk.key_problem(("tempo", "bars"), f"{LINK_NO_MAP}: give one tempo (`bpm: 120`, or `bpm: link`: the "
                                            "session's), or use `clock: machine`")
    if "music" in data:
        walk.key_problem(("music",), f"{LINK_NO_MUSIC}: leave out `music:` (a peer such as Live plays it), or "
                                     "use `clock: machine`")
    bpm = tempo.get("bpm")
    if _number(bpm) and bpm < LINK_MIN_BPM and walk.ok(("tempo", "bpm")):
        walk.problem(("tempo", "bpm"), f"{bpm:g} bpm: an Ableton Link session's tempo is {LINK_MIN_BPM:g} bpm at "
                                       "the least (Link would take another without a word): write the tempo in "
                                       "beats Link can have, or use `clock: machine`")


def _check_hosts(walk: _Walk) -> None:
    """`hosts:` shares the show's `robots:` among computers on the Link clock: each robot on
    exactly one host, every name a robot's."""
    data = walk.doc.data
    hosts = data.get("hosts")
    if not isinstance(hosts, dict) or not walk.ok(("hosts",)):
        return
    if "robots" not in data:
        walk.key_problem(("hosts",), "`hosts:` shares a show's `robots:` among computers, and this show has one "
                                     "robot (`robot:`): leave out `hosts:`")
        return
    if not walk.link:
        walk.key_problem(("hosts",), "hosts play in unison on the Ableton Link session's beat: add `clock: link` "
                                     "(`choreo run --clock machine` still rehearses one host's robots)")
    if not walk.declared:
        return  # `robots:` is wrong: the schema has said how
    seen: dict[str, JsonPath] = {}
    complete = all(_check_host_list(walk, host, robots, seen) for host, robots in hosts.items())
    missing = [name for name in walk.declared if name not in seen]
    if complete and missing:
        walk.key_problem(("hosts",), f"robot {missing[0]!r} is on no host: add it to the list of the host that "
                                     "drives it")


def _check_host_list(walk: _Walk, host: str, robots: Any, seen: dict[str, JsonPath]) -> bool:
    """One host's robots: each a robot of the show, on no other host (`seen`: where each was
    named first). False when the list is unreadable (the schema has said why)."""
    here = ("hosts", host)
    if not isinstance(robots, list) or not walk.ok(here):
        return False
    for index, name in enumerate(robots):
        path = here + (index,)
        if not isinstance(name, str) or not walk.ok(path):
            continue
        if name not in walk.declared:
            walk.problem(path, _unknown_robot(name, walk.declared, f"host {host!r} drives"))
            continue
        first = seen.setdefault(name, path)
        if first != path:
            line = walk.doc.mark(first)[0]
            walk.problem(path, f"robot {name!r} is already on host {first[1]!r} (line {line}): one host drives "
                               "each robot: keep it on one list")
    return True


def _check_tracks(walk: _Walk, tracks: dict[str, Any]) -> None:
    """A track for each declared robot and for no other; each track is walked as a show of
    its own (cues in order, `wait: done` after a play), labels unique across them all."""
    total = 0
    for name, steps in tracks.items():
        here = ("tracks", name)
        if name not in walk.declared:
            walk.key_problem(here, _unknown_robot(name, walk.declared, "a track for"))
            continue
        if not isinstance(steps, list) or not walk.ok(here):
            continue
        walk.robots, walk.in_track, walk.last_cue, walk.played = (name,), True, None, set()
        total += _check_steps(walk, steps, here, looping=False)
    missing = [name for name in walk.declared if name not in tracks]
    if missing:
        walk.key_problem(("tracks",), f"robot {missing[0]!r} has no track: give it one (a robot that stands "
                                      "still can `wait:` for the show's length), or leave it out of `robots:`")
    _check_total(walk, ("tracks",), total)


def _unknown_robot(name: str, declared: tuple[str, ...], what: str) -> str:
    close = closest(name, declared)
    hint = f"did you mean {close!r}? " if close else ""
    return f"{what} robot {name!r}, which `robots:` does not name: {hint}the robots are {', '.join(declared)}"


def _step_robots(walk: _Walk, step: dict[str, Any], here: JsonPath) -> tuple[str, ...]:
    """The robots a step is for, after checking its `robots:`; unknown names are reported."""
    given = step.get("robots")
    path = here + ("robots",)
    if given is None or not walk.ok(path):
        return walk.robots
    if not walk.declared:
        walk.key_problem(path, "a step's `robots:` picks among the show's `robots:`; this show has one robot "
                               "(`robot:`)")
        return walk.robots
    if walk.in_track:
        walk.key_problem(path, "a step in a track is that robot's own: leave out `robots:` (or write the step "
                               "in the shared `steps:`)")
        return walk.robots
    known = [name for name in given if isinstance(name, str) and name in walk.robots]
    for index, name in enumerate(given):
        if not isinstance(name, str):
            continue  # the schema has said what is wrong with it
        if name not in walk.declared:
            walk.problem(path + (index,), _unknown_robot(name, walk.declared, "a step for"))
        elif name not in walk.robots:
            walk.problem(path + (index,), f"robot {name!r} is not among the repeat's robots ({', '.join(walk.robots)})")
    return tuple(known) or walk.robots


# --------------------------------------------------------------------------- motions


def _check_motion_table(walk: _Walk) -> None:
    """Two names for one slot are fine; two different durations for it are a contradiction."""
    durations: dict[int, tuple[float, str]] = {}
    for name, entry in walk.motions.items():
        hth4 = ("motions", name, "hth4_name")
        if isinstance(entry.get("hth4_name"), str) and walk.ok(hth4):
            _check_visible(walk, hth4, entry["hth4_name"], "the Heart to Heart 4 name")
        path = ("motions", name, "duration")
        number, duration = entry.get("number"), entry.get("duration")
        if not (walk.ok(path) and walk.ok(("motions", name, "number"))) or duration is None \
                or not isinstance(number, (int, float)):
            continue
        first = durations.setdefault(int(number), (duration, name))
        if first[0] != duration:
            walk.problem(path, f"motion {int(number)} is also {first[1]!r} with duration {value_text(first[0])}: "
                               "give one duration")


def _check_motion_ref(walk: _Walk, path: JsonPath, ref: Any) -> None:
    if isinstance(ref, str) and ref not in walk.motions:
        walk.problem(path, _unknown_motion(ref, sorted(walk.motions)))


def _unknown_motion(name: str, known: list[str]) -> str:
    if not known:
        return f"unknown motion {name!r}: name it in `motions:` with its slot number, or play the number"
    close = closest(name, known)
    hint = f"did you mean {close!r}? " if close else ""
    return f"unknown motion {name!r}: {hint}the show's motions are {', '.join(known)}"


# --------------------------------------------------------------------------- steps


def _check_steps(walk: _Walk, steps: list[Any], path: JsonPath, looping: bool) -> int:
    """Check a list of steps in run order; the number of plan steps it expands to."""
    total = 0
    for index, step in enumerate(steps):
        here = path + (index,)
        total = min(total + _check_step(walk, step, here, looping), MAX_PLAN_STEPS + 1)
    return total


def _check_step(walk: _Walk, step: Any, here: JsonPath, looping: bool) -> int:
    """Check one step; the number of plan steps it expands to (capped past the limit)."""
    if not isinstance(step, dict) or not walk.ok(here):
        return 1
    _check_cue(walk, step, here, looping)
    _check_cue_number(walk, step, here, looping)
    _check_label(walk, step, here)
    robots = _step_robots(walk, step, here)
    if "play" in step:
        if walk.ok(here + ("play",)):
            _check_motion_ref(walk, here + ("play",), step["play"])
        walk.played.update(robots)
    elif step.get("wait") == "done" and not walk.played.issuperset(robots):
        idle = [name for name in robots if name not in walk.played]
        whose = f" (robot {idle[0]!r} has played nothing yet)" if walk.declared and not walk.in_track else ""
        walk.problem(here + ("wait",), f"`wait: done` has no motion to wait for{whose}: play one before it")
    elif "repeat" in step and isinstance(step.get("steps"), list) and walk.ok(here + ("steps",)):
        return _check_repeat(walk, step, here, robots, looping)
    return 1


def _check_repeat(walk: _Walk, step: dict[str, Any], here: JsonPath, robots: tuple[str, ...], looping: bool) -> int:
    """A repeat's steps, walked once for the robots it is for; the plan steps of every pass."""
    repeat = step["repeat"]
    count = int(repeat) if walk.ok(here + ("repeat",)) and isinstance(repeat, (int, float)) else 1
    _check_repeat_label(walk, step, here)
    outer, walk.robots = walk.robots, robots
    inner = _check_steps(walk, step["steps"], here + ("steps",), looping or count > 1)
    walk.robots = outer
    _check_repeat_cue(walk, step, here)
    return min(count * inner, MAX_PLAN_STEPS + 1)


def _check_cue(walk: _Walk, step: dict[str, Any], here: JsonPath, looping: bool) -> None:
    at = step.get("at")
    path = here + ("at",)
    if at == GO and walk.link and walk.ok(path):
        walk.problem(path, f"{LINK_NO_GO}: cue the step in bars and beats or in seconds, or use `clock: machine`")
    if at is None or not walk.ok(path) or isinstance(at, bool) or at == GO:
        return  # a GO cue may be anywhere: in a repeat, every pass waits for its GO
    if isinstance(at, dict):
        at = _beat_seconds(walk, at, path)
        if at is None:
            return
    if looping:
        walk.problem(path, "a cue inside a repeat would be late on every pass after the first: "
                           "put `at:` on the repeat step")
        return
    if walk.last_cue is not None and at < walk.last_cue[0]:
        prev, prev_path = walk.last_cue
        line = walk.doc.mark(prev_path)[0]
        walk.problem(path, f"cue at {at:g} s comes after the cue at {prev:g} s ({format_path(prev_path)}, "
                           f"line {line}): cues must not go back in time")
        return
    walk.last_cue = (at, path)


def _check_cue_number(walk: _Walk, step: dict[str, Any], here: JsonPath, looping: bool) -> None:
    """`cue:` numbers a cue: on a step with `at:`, written as digits (`12.5`) or short text,
    once in the show (`12.50` is `12.5`), and not on a step every pass of a repeat runs."""
    path = here + ("cue",)
    if "cue" not in step or not walk.ok(path):
        return
    value = step["cue"]
    text = cue_text(walk.doc, value, path)
    if "at" not in step:
        walk.key_problem(path, f"`cue: {_shown(text)}` numbers a cue, and this step is none: add `at:` "
                               "(seconds, a bar and beat, or `go`)")
        return
    problem = _cue_number_problem(value, text, looping)
    if problem is not None:
        walk.problem(path, problem)
        return
    first = walk.cues.setdefault(number_key(text), (text, path))
    if first[1] != path:
        same = "" if first[0] == text else f" (the same number as {first[0]})"
        line = walk.doc.mark(first[1])[0]
        walk.problem(path, f"cue {text} is already the cue of {format_path(first[1][:-1])} (line {line}){same}: "
                           "cue numbers must be unique in the show")


def _cue_number_problem(value: Any, text: str, looping: bool) -> str | None:
    """What is wrong with the cue number of a cued step that passed the schema, if anything."""
    if not isinstance(value, str) and not NUMBER_RE.fullmatch(text):
        return (f"cue number {_shown(text)} is a number YAML reads as {value_text(value)}: write digits with at "
                "most one `.` (`12.5`), or put it in quotes to mean text")
    if len(text) > MAX_NUMBER_CHARS:
        return f"cue number {_shown(text)} is {len(text)} characters long: at most {MAX_NUMBER_CHARS}"
    if looping:
        return ("`cue:` inside a repeat that runs more than once would number every pass alike: put `at:` and "
                "`cue:` on the repeat step (its first pass is the cue), or leave `cue:` out (each pass is "
                "numbered in show order)")
    return None


def _shown(text: str) -> str:
    """A cue number as messages show it: cut past twice the longest (a number has no hidden characters)."""
    return text if len(text) <= 2 * MAX_NUMBER_CHARS else text[:2 * MAX_NUMBER_CHARS] + "…"


def _check_repeat_cue(walk: _Walk, step: dict[str, Any], here: JsonPath) -> None:
    """A repeat's cue number numbers its first plan step, which cannot carry a second one
    (checked after its steps: a number they refused already is not said twice)."""
    if "cue" not in step or not walk.ok(here + ("cue",)):
        return
    inner, path = step, here
    while isinstance(inner.get("steps"), list) and inner["steps"] and isinstance(inner["steps"][0], dict):
        inner, path = inner["steps"][0], path + ("steps", 0)
        if "cue" in inner and walk.ok(path + ("cue",)):
            line = walk.doc.mark(here + ("cue",))[0]
            mine = cue_text(walk.doc, step["cue"], here + ("cue",))
            walk.problem(path + ("cue",), f"this cue number and the repeat's `cue: {mine}` (line {line}) would "
                                          "number the same step: keep one")
            return
        if "repeat" not in inner:
            return


def _beat_seconds(walk: _Walk, at: dict[str, Any], path: JsonPath) -> float | None:
    """A bar-and-beat cue in seconds; None (reported) without a usable tempo, past the bar, or
    later than a cue in seconds may be (a slow tempo, or a short map carried on, reaches far)."""
    if not isinstance(walk.doc.data.get("tempo"), dict):
        walk.problem(path, "a cue in bars and beats needs the music's `tempo:` "
                           "(e.g. `tempo: {bpm: 120, offset: 0.5, meter: 4}`), or give seconds")
        return None
    bar, beat = at.get("bar"), at.get("beat", 1)
    fields_ok = all(walk.ok(path + (key,)) for key in at)
    tempo = walk.tempo
    if tempo is None or not fields_ok or not _number(bar) or not _number(beat):
        return None  # the schema or the tempo's checks have said what is wrong
    if float(beat) >= tempo.meter + 1:
        walk.problem(path + ("beat",), f"beat {value_text(at.get('beat'))}: a bar has {tempo.meter} beats "
                                       f"(tempo.meter), so beats run from 1 to below {tempo.meter + 1}")
        return None
    seconds = tempo.seconds(int(bar), float(beat))
    if seconds > MAX_CUE_S:  # a slow tempo or a short map carried far: a cue no seconds cue could be
        walk.problem(path, f"bar {bar} beat {value_text(beat)} falls {seconds:,.0f} s into the show, "
                           f"past the {MAX_CUE_S:,.0f} s (a day) a cue may be")
        return None
    return seconds


def _checked_tempo(walk: _Walk) -> Tempo | None:
    """The show's `tempo:` when it can place cues; None when it has none, or it is broken (said)."""
    tempo = walk.doc.data.get("tempo")
    if not isinstance(tempo, dict) or not walk.ok(("tempo",)) or not all(walk.ok(("tempo", key)) for key in tempo):
        return None
    bars = tempo.get("bars")
    if bars is not None and not _check_bars(walk, bars, int(tempo.get("meter", 4))):
        return None
    return tempo_of(tempo)


def _check_bars(walk: _Walk, bars: list[Any], meter: int) -> bool:
    """A tempo map's bars are numbers (the schema's to say) that go forward in time: a bar that
    starts no later than the one before would run the music backwards or stop it. No bar is
    faster than one tempo may be (`MAX_BPM`): a bar of a microsecond is a typo, and carried on
    past the map it would pile every later cue onto one instant."""
    path = ("tempo", "bars")
    if not all(walk.ok(path + (index,)) for index in range(len(bars))):
        return False
    shortest = meter * 60.0 / MAX_BPM
    for index in range(1, len(bars)):
        start, end = bars[index - 1], bars[index]
        if end <= start:
            walk.problem(path + (index,), f"bar {index + 1} starts at {value_text(end)} s, not after bar "
                                          f"{index}'s {value_text(start)} s: each bar of the map "
                                          "starts later than the one before")
            return False
        if end - start < shortest:
            walk.problem(path + (index,), f"bar {index} lasts {end - start:.3g} s ({value_text(start)} to "
                                          f"{value_text(end)} s), faster than {MAX_BPM:g} bpm: its {meter} "
                                          f"beats take {shortest:g} s or more")
            return False
    return True


def _number(value: Any) -> TypeGuard[int | float]:
    """A number as the schema means it (YAML's true and false are not 1 and 0)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


# --------------------------------------------------------------------------- text


def _check_visible(walk: _Walk, path: JsonPath, text: str, what: str) -> bool:
    """Text that choreo prints (names, labels) holds no control or invisible characters: they
    would reach terminals and logs raw (an escape sequence, a right-to-left override)."""
    hidden = hidden_character(text)
    if hidden is None:
        return True
    name = unicodedata.name(hidden, "a control character")
    walk.problem(path, f"{what} holds U+{ord(hidden):04X} ({name}), which is invisible or controls the "
                       "terminal: remove it")
    return False


def _check_label(walk: _Walk, step: dict[str, Any], here: JsonPath) -> None:
    label = step.get("label")
    path = here + ("label",)
    if not isinstance(label, str) or not walk.ok(path) or not _check_visible(walk, path, label, "the label"):
        return
    first = walk.labels.get(label)
    if first is not None:
        line = walk.doc.mark(first)[0]
        walk.problem(path, f"label {label!r} is already used by {format_path(first[:-1])} (line {line}): "
                           "labels must be unique")
        return
    walk.labels[label] = path


def _check_repeat_label(walk: _Walk, step: dict[str, Any], here: JsonPath) -> None:
    """A repeat's label names its first plan step, which cannot carry a second label."""
    if not isinstance(step.get("label"), str):
        return
    inner, path = step, here
    while isinstance(inner.get("steps"), list) and inner["steps"] and isinstance(inner["steps"][0], dict):
        inner, path = inner["steps"][0], path + ("steps", 0)
        if isinstance(inner.get("label"), str):
            line = walk.doc.mark(here + ("label",))[0]
            walk.problem(path + ("label",), f"this label and the repeat's label {step['label']!r} (line {line}) "
                                            "would name the same step: keep one")
            return
        if "repeat" not in inner:
            return
