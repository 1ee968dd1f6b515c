"""`choreo validate SHOW...` and `choreo plan SHOW`: check show files, print the compiled timeline.

Both exit 2 with one located line a problem when a file is bad (the CLI's `main` prints
`ShowError`'s lines). The show loader and planner are imported inside the handlers: `choreo
--help` must not pay for YAML or jsonschema.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from choreo.cli.jsonout import problem_record
from choreo.cli.terminal import columns, print_fitted
from choreo.errors import ShowError, one_line
from choreo.textfit import display_width, fit, pad, visible
from choreo.wire.layouts import EXAMPLE_CONFIG, layout_named

if TYPE_CHECKING:  # the model is imported by the handlers, not by `choreo --help`
    from choreo.show.model import Plan, PlannedStep, Show, Tempo


def register(subparsers: argparse._SubParsersAction) -> None:
    validate = subparsers.add_parser(
        "validate",
        help="check show files",
        description="Check show files against the format (YAML, schema, motion names, cues) and "
        "print one line for each valid file: its steps, motions and estimated duration. "
        "Every problem of every file is listed, one a line, with exit status 2.",
    )
    validate.add_argument("shows", nargs="+", metavar="SHOW", help="a show file (YAML)")
    validate.add_argument("--json", action="store_true", help="one JSON object on stdout: every file, "
                          "ok with its figures or its problems (exit status as without)")
    validate.set_defaults(handler=run_validate)

    plan = subparsers.add_parser(
        "plan",
        help="print a show's compiled timeline",
        description="Print the plan a show compiles to, repeats expanded: one line a step with its "
        "index, cue number, label, planned start, what it does, its path and the frames it sends "
        "(hex), then the estimated total duration.",
    )
    plan.add_argument("show", metavar="SHOW", help="a show file (YAML)")
    plan.add_argument("--json", action="store_true", help="the plan as one JSON object on stdout")
    plan.set_defaults(handler=run_plan)


def run_validate(args: argparse.Namespace) -> int:
    from choreo.show.load import load_show
    from choreo.show.plan import compile_plans

    problems = []
    files = []
    for path in args.shows:
        try:
            show = load_show(path)
        except ShowError as exc:
            problems.extend(exc.problems)
            files.append({"path": path, "ok": False, "problems": [problem_record(p) for p in exc.problems]})
            continue
        plans = compile_plans(show)
        if args.json:
            record = _show_record(show, *plans.values()) if not show.ensemble else _plans_record(show, plans)
            files.append({"path": path, "ok": True, **record, "cues": cues_record(plans)})
        else:
            print_fitted(one_line(summary_line(show, plans)))  # a file named with a line break
    if args.json:  # its files' record says the problems; stderr as without --json
        print(json.dumps({"ok": not problems, "exit": 2 if problems else 0, "files": files}, ensure_ascii=False))
        for line in ShowError(problems).lines():
            print(line, file=sys.stderr)
        return 2 if problems else 0
    if problems:
        raise ShowError(problems)
    return 0


def _show_record(show: Show, plan: Plan) -> dict[str, Any]:
    return {"name": show.name, "layout": plan.layout, "steps": len(plan.steps),
            "motions": plan.motions_used(), "estimated_s": plan.estimated_s, **_clock_record(show)}


def _clock_record(show: Show) -> dict[str, Any]:
    """The show's music and tempo, where it has them."""
    record: dict[str, Any] = {}
    if show.music is not None:
        record["music"] = {"file": show.music.file, "start": show.music.start}
    if show.tempo is not None:
        tempo = show.tempo
        record["tempo"] = {"bpm": tempo.bpm, "offset": tempo.offset, "meter": tempo.meter,
                           **({"bars": list(tempo.bars)} if tempo.bars else {})}
    if show.link is not None:  # `tempo.bpm` is then the plan's; `link.bpm` None: the session's, at run time
        record["link"] = {"bpm": show.link.bpm, "meter": show.link.meter}
    if show.hosts:
        record["hosts"] = {host: list(robots) for host, robots in show.hosts.items()}
    return record


def _clock_lines(show: Show) -> list[str]:
    """What the start times are measured on: the music's position, and its bars."""
    lines = []
    if show.music is not None:
        lines.append(f"music: {show.music.file} from {show.music.start:g} s: show time is the music's position "
                     "(--no-music: the machine's clock)")
    if show.link is not None:  # the session's tempo, when the show takes it, is known only at run time
        from choreo.show.model import NOMINAL_BPM

        tempo = f"{show.link.bpm:g} bpm proposed to the session" if show.link.bpm is not None \
            else f"the session's (planned here at {NOMINAL_BPM:g} bpm)" if show.tempo is not None else "the session's"
        lines.append(f"clock: Ableton Link, {show.link.meter} beats a bar; tempo: {tempo}")
    elif show.tempo is not None:
        lines.append(tempo_line(show.tempo))
    return lines


def tempo_line(tempo: Tempo) -> str:
    """`tempo: 120 bpm, 4 beats a bar, bar 1 at 0.5 s`; a map's bars and the range of its tempo:
    `tempo map: 24 bars, 4 beats a bar, 118.2-121.9 bpm, bar 1 at 0.512 s`."""
    if not tempo.bars:
        return f"tempo: {tempo.bpm:g} bpm, {tempo.meter} beats a bar, bar 1 at {tempo.offset:g} s"
    low, high = f"{min(tempo.bar_bpm):.1f}", f"{max(tempo.bar_bpm):.1f}"
    span = low if low == high else f"{low}-{high}"
    return (f"tempo map: {len(tempo.bars)} bars, {tempo.meter} beats a bar, {span} bpm, "
            f"bar 1 at {tempo.offset:g} s")


def _plan_record(show: Show, plan: Plan) -> dict[str, Any]:
    steps = [{"index": step.index, "path": step.path, "label": step.label, "kind": step.kind.value,
              "start_s": step.planned_s, "cue": step.at, "cue_number": step.cue,
              **({"cue_bar": step.at_beat[0], "cue_beat": step.at_beat[1]} if step.at_beat else {}),
              **({"go": True} if step.go else {}), "motion": step.motion,
              "motion_name": step.motion_name, "seconds": step.seconds, "text": step.describe(),
              "frames": [frame.hex for frame in step.frames]} for step in plan.steps]
    return {"path": show.path, **_show_record(show, plan), "plan": steps}


def cues_record(plans: dict[str, Plan]) -> list[dict[str, Any]]:
    """The show's cue list for `--json`: one record a cue, in show order, as the console lists it."""
    from choreo.show.cues import cue_list

    return [cue.to_json() for cue in cue_list(plans)]


def cue_numbers_text(numbers: Sequence[str], most: int = 8) -> str:
    """`5 cues (1-5)`, `4 cues (1, 2.5, A3, 4)`: runs of whole numbers one apart said as a range,
    the first `most` parts only (a show of 10,000 cues is still one line); '' without cues."""
    if not numbers:
        return ""
    runs: list[list[str]] = []
    for number in numbers:
        if runs and _follows(runs[-1][-1], number):
            runs[-1].append(number)
        else:
            runs.append([number])
    parts = [run[0] if len(run) == 1 else f"{run[0]}-{run[-1]}" for run in runs[:most]]
    shown = ", ".join(parts) + (", ..." if len(runs) > most else "")
    return f"{len(numbers)} cue{'s' if len(numbers) != 1 else ''} ({shown})"


def _follows(before: str, number: str) -> bool:
    """Whether `number` is the whole number after `before` (`4` after `3`; not `04`, not `3.5`)."""
    return bool(_WHOLE.fullmatch(before) and _WHOLE.fullmatch(number)) and int(number) == int(before) + 1


_WHOLE = re.compile(r"[1-9][0-9]{0,15}")  # a whole cue number as numbering writes one


def summary_line(show: Show, plans: dict[str, Plan]) -> str:
    """`shows/x.yaml: ok, 26 steps, 3 cues (1-3), motions 0 home, 1 bow, estimated 22.0 s` (with
    several robots: `ok, 2 robots, 30 steps, ...`, steps counted per robot)."""
    from choreo.show.cues import cue_list

    names: dict[int, str] = {}
    for entry in show.motions.values():
        names.setdefault(entry.number, entry.name)
    used = sorted({m for plan in plans.values() for m in plan.motions_used()})
    motions = ", ".join(f"{n} {names[n]}" if n in names else str(n) for n in used)
    late = "".join(_late_note(plan) for plan in plans.values()) + _past_map_note(show, plans)
    count = sum(1 for plan in plans.values() for step in plan.steps if step.is_for(plan.robot))
    steps = f"{count} step{'s' if count != 1 else ''}"
    robots = f"{len(plans)} robots, " if show.ensemble else ""
    played = f"motions {motions}" if motions else "no motions"
    total = max(plan.estimated_s for plan in plans.values())
    cues = cue_numbers_text([cue.number for cue in cue_list(plans)])
    cues = f", {cues}" if cues else ""
    return f"{show.path}: ok, {robots}{steps}{cues}, {played}, estimated {_seconds(total)}{late}"


def run_plan(args: argparse.Namespace) -> int:
    from choreo.show.load import load_show
    from choreo.show.plan import compile_plans

    show = load_show(args.show)
    plans = compile_plans(show)
    if args.json:
        print(json.dumps(_plans_record(show, plans), ensure_ascii=False))
        return 0
    width = columns()
    lines = plan_lines(show, *plans.values()) if not show.ensemble else ensemble_lines(show, plans)
    for line in lines:
        print(fit(line, width))
    return 0


def _plans_record(show: Show, plans: dict[str, Plan]) -> dict[str, Any]:
    """One robot: the plan as before; several: `robots`, each robot's plan by name."""
    if not show.ensemble:
        return {**_plan_record(show, *plans.values()), "cues": cues_record(plans)}
    robots = {}
    for name, plan in plans.items():
        mine = replace(plan, steps=tuple(step for step in plan.steps if step.is_for(name)))
        robots[name] = {key: value for key, value in _plan_record(show, mine).items() if key not in ("path", "name")}
    return {"path": show.path, "name": show.name, "tracks": bool(show.tracks),
            "estimated_s": max(plan.estimated_s for plan in plans.values()), **_clock_record(show), "robots": robots,
            "cues": cues_record(plans)}


def ensemble_lines(show: Show, plans: dict[str, Plan]) -> list[str]:
    """A section per robot: the steps it does (shared steps keep their index, so a gap is a step
    for other robots), then the show's total."""
    form = "tracks, one per robot" if show.tracks else "shared steps"
    lines = [f"{show.name} ({show.path}): {len(plans)} robots, {form}, one show clock", *_clock_lines(show)]
    for name, plan in plans.items():
        lines.append("")
        host = f" (host {show.host_of(name)})" if show.hosts else ""
        lines.append(f"robot {name}{host}: layout {plan.layout}{_layout_note(plan)}")
        mine = [step for step in plan.steps if step.is_for(name)]
        lines.extend(_step_table(mine, show.tracks == {} and show.ensemble, show.tempo))
    total = max(plan.estimated_s for plan in plans.values())
    lines.append("")
    lines.append(f"estimated total {_seconds(total)}" + "".join(_late_note(plan) for plan in plans.values()))
    return lines


def plan_lines(show: Show, plan: Plan) -> list[str]:
    """The plan as aligned text: a header, one line a step, the total."""
    lines = [f"{show.name} ({show.path}), layout {plan.layout}{_layout_note(plan)}", *_clock_lines(show)]
    lines.extend(_step_table(plan.steps, tempo=show.tempo))
    lines.append(f"estimated total {_seconds(plan.estimated_s)} ({len(plan.steps)} steps){_late_note(plan)}")
    return lines


def _step_table(steps: Sequence[PlannedStep], shared: bool = False, tempo: Tempo | None = None) -> list[str]:
    """Header and one aligned line a step; `shared`: who else does each step; `tempo`: the
    show's, to say which bar-and-beat cues lie past a tempo map."""
    digits = max((len(f"{step.planned_s:.3f}") for step in steps), default=1)
    rows = [
        (
            str(step.index),
            step.cue or "-",
            step.label or "-",
            _start(step, digits, tempo),
            step.describe() + (f" [{', '.join(step.robots)}]" if shared and step.robots else ""),
            step.path,
            " | ".join(frame.hex for frame in step.frames) or "-",
        )
        for step in steps
    ]
    # the operator's columns first (cue number, label, start, what it does), so that 80 columns
    # show them; the author's path and the frames after, cut first on a narrow terminal
    header = ("#", "cue", "label", "start", "step", "path", "frames")
    # by the columns a terminal gives each cell (a Japanese name takes two a character), as shown
    cells = [tuple(visible(cell) for cell in row) for row in [header, *rows]]
    widths = [max(display_width(row[i]) for row in cells) for i in range(6)]
    return ["  ".join([row[0].rjust(widths[0])] + [pad(row[i], widths[i]) for i in range(1, 6)] + [row[6]])
            for row in cells]


def _layout_note(plan: Plan) -> str:
    if not layout_named(plan.layout).reads_config:
        return ""
    return (f" (suspend and resume shown for config 0x{EXAMPLE_CONFIG:04x}: the run makes them "
            "from the config word it reads from the board)")


def _start(step: PlannedStep, digits: int, tempo: Tempo | None = None) -> str:
    """` 4.000 s`, with the cue when the step has one: `14.000 s (at 14)`, late ones flagged."""
    text = f"{step.planned_s:{digits}.3f} s"
    if step.go:
        return f"{text} (waits for GO)"
    if step.at is None:
        return text
    from choreo.show.model import beat_text

    cue = f"{step.at:g}"
    if step.at_beat is not None:
        cue += f" = bar {step.at_beat[0]} beat {beat_text(step.at_beat[1])}"
    if step.at_beat is not None and tempo is not None and tempo.past_map(*step.at_beat):
        cue += ", past the tempo map"
    if step.planned_s > step.at + 1e-9:
        return f"{text} (at {cue}, late {step.planned_s - step.at:.3f} s)"
    return f"{text} (at {cue})"


def _past_map_note(show: Show, plans: dict[str, Plan]) -> str:
    """`; 2 cues past the tempo map's last bar (24): ...`: cues the map does not reach are timed
    by its last bar's length, which a song that keeps drifting will not follow."""
    tempo = show.tempo
    if tempo is None or not tempo.bars:
        return ""
    past = {(step.path, step.at_beat) for plan in plans.values() for step in plan.steps
            if step.at_beat is not None and tempo.past_map(*step.at_beat)}
    if not past:
        return ""
    return (f"; {len(past)} cue{'s' if len(past) != 1 else ''} past the tempo map's last bar ({len(tempo.bars)}), "
            "timed at its length")


def _late_note(plan: Plan) -> str:
    from choreo.show.plan import late_cues

    late = late_cues(plan)
    if not late:
        return ""
    names = ", ".join(step.name for step in late[:3]) + (", ..." if len(late) > 3 else "")
    return f"; {len(late)} cue{'s' if len(late) != 1 else ''} planned late ({names})"


def _seconds(seconds: float) -> str:
    return f"{seconds:.1f} s" if seconds < 60 else f"{seconds:.1f} s ({int(seconds // 60)} min {seconds % 60:04.1f} s)"
