"""Cue numbers: how `choreo.show.cues` numbers a show's cues (QLab style) and finds one by number
or label, what the show file may give as `cue:`, and what `choreo plan` / `choreo validate` say."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from choreo.cli import main
from choreo.errors import ShowError
from choreo.show.cues import MAX_NUMBER_CHARS, Cue, CueList, CueNotFound, cue_list, numbered
from choreo.show.load import load_show, load_show_bytes
from choreo.show.model import Plan, PlannedStep, StepKind
from choreo.show.plan import compile_plans
from choreo.show.schema import load_schema
from runlog import write_show

ROOT = Path(__file__).resolve().parent.parent


def cues_of(tmp_path: Path, body: str) -> CueList:
    return cue_list(compile_plans(load_show(write_show(tmp_path, body))))


def numbers_of(tmp_path: Path, body: str) -> list[str]:
    return [cue.number for cue in cues_of(tmp_path, body)]


def go_steps(*numbers: str | None) -> str:
    """A one-robot show of GO cues, `cue:` given where a number is."""
    lines = ["version: 1", "steps:"]
    for number in numbers:
        lines += ["  - play: 1", "    at: go"] + ([f"    cue: {number}"] if number is not None else [])
    return "\n".join(lines) + "\n"


def problems(text: str) -> list[str]:
    """`path: message` of every problem the show file has ([] if it loads)."""
    try:
        load_show_bytes(text.encode("utf-8"), "show.yaml")
    except ShowError as exc:
        return [f"{p.path}: {p.message}" for p in exc.problems]
    return []


def located(text: str) -> list[tuple[int, int, str]]:
    try:
        load_show_bytes(text.encode("utf-8"), "show.yaml")
    except ShowError as exc:
        return [(p.line, p.column, p.path) for p in exc.problems]
    return []


# --------------------------------------------------------------------------- numbering


@pytest.mark.parametrize(("given", "expected"), [
    ((None, None, None), ["1", "2", "3"]),  # none given: show order
    ((None, "5", None), ["1", "5", "6"]),  # the next whole number after the cue before
    ((None, None, "2.5", None), ["1", "2", "2.5", "3"]),  # one put between
    ((None, "A3", None), ["1", "A3", "2"]),  # text does not count
    ((None, None, "2"), ["1", "3", "2"]),  # a number given later is not taken by an earlier cue
    ((None, None, '"02"'), ["1", "3", "02"]),  # taken by value: `02` is 2
    (("12.50", None), ["12.50", "13"]),  # as written
    ((None, "1.1", None, "1.2", None, "2", "3", "4"), ["1", "1.1", "5", "1.2", "6", "2", "3", "4"]),
])
def test_cues_are_numbered_in_show_order_around_the_ones_given(tmp_path, given, expected):
    assert numbers_of(tmp_path, go_steps(*given)) == expected


def test_plans_carry_each_cue_number_on_its_step(tmp_path):
    plans = compile_plans(load_show(write_show(tmp_path, go_steps(None, "7") + "  - play: 2\n")))
    assert [step.cue for step in plans["robot"].steps] == ["1", "7", None]


def test_tracks_are_ordered_by_time_then_by_cast_order(tmp_path):
    cues = cues_of(tmp_path, """\
        version: 1
        robots: {a: {}, b: {}}
        tracks:
          b:
            - {play: 1, at: 1, label: b-early}
            - {play: 1, at: 5, label: b-tie}
          a:
            - {play: 1, at: 2, label: a-second}
            - {play: 1, at: 5, label: a-tie, cue: 40}
            - {play: 1, at: 9}
    """)
    assert [(cue.number, cue.label, cue.robots) for cue in cues] == [
        ("1", "b-early", ("b",)), ("2", "a-second", ("a",)), ("40", "a-tie", ("a",)), ("41", "b-tie", ("b",)),
        ("42", None, ("a",))]
    assert cues.of_step("a", 1) is cues.find("40") and cues.of_step("b", 1) is cues.find("b-tie")


def test_a_shared_step_for_some_robots_is_their_cue_only(tmp_path):
    cues = cues_of(tmp_path, """\
        version: 1
        robots: {left: {}, right: {}}
        steps:
          - {play: 1, at: go, robots: [left], label: left-only}
          - {play: 2, at: go, cue: 2.5}
    """)
    only, both = cues
    assert only.robots == ("left",) and only.steps == (("left", 0),)
    assert cues.of_step("left", 0) is only and cues.of_step("right", 0) is None
    assert both.number == "2.5" and both.robots == ("left", "right") and both.starts("right", 1)


def test_a_cue_on_a_repeat_numbers_the_first_step_of_its_first_pass_only(tmp_path):
    plans = compile_plans(load_show(write_show(tmp_path, """\
        version: 1
        steps:
          - play: 1
            at: go
          - repeat: 3
            at: go
            cue: 10
            label: verse
            steps:
              - play: 2
              - wait: 1
          - play: 3
            at: go
    """)))
    steps = plans["robot"].steps
    assert [(step.index, step.cue) for step in steps if step.cue] == [(0, "1"), (1, "10"), (7, "11")]
    cues = cue_list(plans)
    assert cues.find("verse") is cues.find("10") and cues.find("10").steps == (("robot", 1),)


def test_a_go_cue_inside_a_repeat_is_numbered_on_every_pass(tmp_path):
    numbers = numbers_of(tmp_path, "version: 1\nsteps:\n  - repeat: 3\n    steps:\n      - {play: 1, at: go}\n")
    assert numbers == ["1", "2", "3"]


def plan_of(robot: str, cued: list[tuple[int, str | None, str | None]], length: int) -> Plan:
    """A plan of `length` waits; `cued`: (index, given number, label) of its GO cues."""
    marks = {index: (number, label) for index, number, label in cued}
    steps = tuple(PlannedStep(index=i, path=f"steps[{i}]", kind=StepKind.WAIT, seconds=1.0, planned_s=float(i),
                              go=i in marks, cue=marks.get(i, (None, None))[0], label=marks.get(i, (None, None))[1])
                  for i in range(length))
    return Plan(steps, float(length), robot=robot)


def test_numbering_10000_cues_is_bounded(tmp_path):
    """10,000 cues of which half are given in the order most costly for a walk of taken
    numbers (each unnumbered cue after a `1.k` would cross 2..5001 again): right numbers, and
    every lookup answers (the cost is counted below, not timed)."""
    pairs = [(2 * k, f"1.{k + 1}", None) for k in range(2500)] + [(2 * k + 1, None, None) for k in range(2500)]
    taken = [(5000 + k, str(k + 2), None) for k in range(5000)]
    plans = numbered({"robot": plan_of("robot", pairs + taken, 10_000)})
    cues = cue_list(plans)
    numbers = [cue.number for cue in cues]
    assert len(numbers) == 10_000 == len(set(numbers))
    assert numbers[:4] == ["1.1", "5002", "1.2", "5003"] and numbers[-1] == "5001"
    assert cues.position(cues.find("7501")) == 4999
    assert cues.of_step("robot", 9999) is cues.find("5001")


class CountingSet(set):
    """A set of taken numbers that counts the looks into it."""

    looks = 0

    def __contains__(self, item: object) -> bool:
        CountingSet.looks += 1
        return super().__contains__(item)


def test_a_run_of_taken_numbers_is_crossed_once():
    """What keeps numbering bounded, counted: each free number found from 1 across 2..5001,
    taken, costs a few looks, not one a taken number (12.5 million for 2,500 cues)."""
    from decimal import Decimal

    from choreo.show.cues import _free

    taken = CountingSet(Decimal(n) for n in range(2, 5002))
    jumps: dict[int, int] = {}
    CountingSet.looks = 0
    found = []
    for _ in range(2500):
        free = _free(2, taken, jumps)
        taken.add(Decimal(free))
        found.append(free)
    assert found == list(range(5002, 7502))
    assert CountingSet.looks < 20 * 2500


def test_a_show_of_10000_cues_loads_plans_and_validates(tmp_path):
    """The file's limit (256 KiB) allows 10,000 cues written out through a repeat; every one is
    numbered, and `validate`'s line still says them in short."""
    from choreo.cli.show import summary_line

    inner = "".join(f"      - {{play: 1, at: go, label: c{k}}}\n" for k in range(10))
    path = write_show(tmp_path, f"version: 1\nsteps:\n  - repeat: 1000\n    steps:\n{inner}")
    show = load_show(path)
    plans = compile_plans(show)
    cues = cue_list(plans)
    assert len(cues) == 10_000 and cues.cues[-1].number == "10000" and cues.find("c3#1000").number == "9994"
    line = summary_line(show, plans)
    assert "10000 cues (1-10000)" in line and len(line) < 200


# --------------------------------------------------------------------------- find


def listed(*cues: tuple[str, str | None]) -> CueList:
    return CueList(tuple(Cue(number, label, ("robot",), float(i), True, steps=(("robot", i),))
                         for i, (number, label) in enumerate(cues)))


def test_find_by_number_then_by_same_value_then_by_label():
    cues = listed(("1", "intro"), ("12.5", "bow"), ("A3", "12"), ("13", None))
    assert cues.find("12.5").label == "bow"
    assert cues.find("12.50").label == "bow"  # the same value
    assert cues.find("bow").number == "12.5"
    assert cues.find("A3").label == "12"
    assert cues.find("12").number == "A3"  # no cue numbered 12: the label
    assert cues.find("13").name == "cue 13"


def test_find_says_what_is_ambiguous_or_missing():
    cues = listed(("1", "bow"), ("2", "bow"), ("3", None))
    with pytest.raises(CueNotFound, match=r"cue 'bow' is ambiguous: cues 1, 2 are all labelled so; give the number"):
        cues.find("bow")
    with pytest.raises(CueNotFound, match=r"no cue '4' in this show \(cues: 1, 2, 3\)"):
        cues.find("4")
    with pytest.raises(CueNotFound, match=r"cues: none"):
        CueList().find("1")


@pytest.mark.parametrize("ref", ["x" * 1_000_000, "\x1b[2J\u202e", "１２", "1" * 5000, "12.5.", " 1", "-1", "+1"])
def test_find_is_safe_against_any_ref(ref):
    """A typed or sent reference: bounded cost, an escaped and short message, no number by look-alikes."""
    cues = listed(("1", None), ("12", None))
    with pytest.raises(CueNotFound) as raised:
        cues.find(ref)
    message = str(raised.value)
    assert len(message) < 120 and "\x1b" not in message and "\u202e" not in message


def test_position_and_of_step():
    cues = listed(("1", None), ("2", None))
    assert cues.position(cues.find("2")) == 1 and cues.of_step("robot", 0) is cues.find("1")
    assert cues.of_step("robot", 5) is None and cues.of_step("other", 0) is None
    with pytest.raises(ValueError, match="cue 9"):
        cues.position(Cue("9", None, ("robot",), 0.0, True))


# --------------------------------------------------------------------------- the show file


def one_step(cue: str, at: str | None = "go") -> str:
    return "version: 1\nsteps:\n  - play: 1\n" + (f"    at: {at}\n" if at else "") + f"    cue: {cue}\n"


@pytest.mark.parametrize(("cue", "number"), [
    ("12.5", "12.5"), ("12.50", "12.50"), ("3", "3"), ('"12.50"', "12.50"), ("A3", "A3"), ("b_2-x.1", "b_2-x.1"),
    ("!!float 2.50", "2.50"), ("0", "0"), ("9" * MAX_NUMBER_CHARS, "9" * MAX_NUMBER_CHARS),
])
def test_a_cue_number_is_kept_as_written(tmp_path, cue, number):
    assert numbers_of(tmp_path, one_step(cue)) == [number]


@pytest.mark.parametrize(("cue", "said"), [
    ("1e3", "steps[0].cue: cue number 1e3 is a number YAML reads as 1000.0: write digits with at most one `.` "
            "(`12.5`), or put it in quotes to mean text"),
    (".inf", "steps[0].cue: cue number .inf is a number YAML reads as .inf"),
    (".5", "steps[0].cue: cue number .5 is a number YAML reads as 0.5"),
    ("0x10", "steps[0].cue: cue number 0x10 is a number YAML reads as 16"),
    ("+3", "steps[0].cue: cue number +3 is a number YAML reads as 3"),
    (".nan", "steps[0].cue: not-a-number (.nan) is not allowed here"),
    ("true", "steps[0].cue: expected a cue number (`12.5`) or short text (`A3`), not true (put the word in quotes "
             "to mean text)"),
    ("", "steps[0].cue: expected a cue number (`12.5`) or short text (`A3`), not an empty value"),
    ("[1]", "steps[0].cue: expected a cue number (`12.5`) or short text (`A3`), not a list"),
    ("{a: 1}", "steps[0].cue: expected a cue number (`12.5`) or short text (`A3`), not a mapping"),
    ("-1", "steps[0].cue: a cue number is 0 or more, not -1"),
    ("1" * 17, f"steps[0].cue: cue number {'1' * 17} is 17 characters long: at most {MAX_NUMBER_CHARS}"),
    ("1" * 30, f"steps[0].cue: cue number {'1' * 30} is 30 characters long: at most {MAX_NUMBER_CHARS}"),
    ("1" * 31, "steps[0].cue: a whole number 31 characters long"),
    ("1." + "1" * 400, f"steps[0].cue: cue number 1.{'1' * 30}… is 402 characters long: at most 16"),
    ("1" * 400 + ".5", "steps[0].cue: cue number"),  # a float's digits, however many
    ('"abcdefghijklmnopq"', "steps[0].cue: cue number 'abcdefghijklmnopq' is longer than 16 characters: name the "
                            "cue with `label:`"),
    ('"big finish"', "steps[0].cue: cue number 'big finish' may hold only letters, digits, `.`, `-` and `_`, "
                     "starting with a letter or digit: name the cue with `label:`"),
    ('"１２"', "steps[0].cue: cue number '１２' may hold only letters"),  # digits of another script
    ('"١٢"', "steps[0].cue: cue number '١٢' may hold only letters"),
    ('"a\\u0007"', "steps[0].cue: cue number 'a\\x07' may hold only letters"),
    ('"a\\u202e"', "steps[0].cue: cue number 'a\\u202e' may hold only letters"),
    ('".5"', "steps[0].cue: cue number '.5' may hold only letters"),  # text starts with a letter or digit
    ('""', "steps[0].cue: the cue number is empty: give one (`12.5`, `A3`) or leave `cue:` out"),
    ('"' + "x" * 5000 + '"', "steps[0].cue: cue number 'xxxxxxxxxxxxxxxxxxxxxxxx'… is longer than 16 characters"),
])
def test_each_wrong_cue_number_gets_one_located_line(cue, said):
    found = problems(one_step(cue))
    assert len(found) == 1 and found[0].startswith(said), found
    assert len(found[0]) < 240 and "\x07" not in found[0] and "\u202e" not in found[0]


def test_a_cue_number_needs_a_cue():
    text = one_step("12.5", at=None)
    assert problems(text) == ["steps[0].cue: `cue: 12.5` numbers a cue, and this step is none: add `at:` "
                              "(seconds, a bar and beat, or `go`)"]
    assert located(text) == [(4, 5, "steps[0].cue")]  # at the key, where `at:` goes
    repeat = "version: 1\nsteps:\n  - repeat: 2\n    cue: A\n    steps:\n      - play: 1\n"
    assert problems(repeat) == ["steps[0].cue: `cue: A` numbers a cue, and this step is none: add `at:` "
                                "(seconds, a bar and beat, or `go`)"]


def test_a_cue_number_is_unique_across_the_show_naming_both_places():
    text = """\
version: 1
robots: {a: {}, b: {}}
tracks:
  a:
    - {play: 1, at: 1, cue: 5}
    - {play: 1, at: 2, cue: A3}
  b:
    - {play: 1, at: 1, cue: 5.0}
    - {play: 1, at: 3, cue: A3}
    - {play: 1, at: 4, cue: a3}
"""
    assert problems(text) == [
        "tracks.b[0].cue: cue 5.0 is already the cue of tracks.a[0] (line 5) (the same number as 5): cue numbers "
        "must be unique in the show",
        "tracks.b[1].cue: cue A3 is already the cue of tracks.a[1] (line 6): cue numbers must be unique in the show",
    ]
    assert [where[:2] for where in located(text)] == [(8, 29), (9, 29)]


def test_a_cue_number_inside_a_repeat_that_runs_again_is_refused():
    text = "version: 1\nsteps:\n  - repeat: 2\n    steps:\n      - {play: 1, at: go, cue: 4}\n"
    assert problems(text) == [
        "steps[0].steps[0].cue: `cue:` inside a repeat that runs more than once would number every pass alike: "
        "put `at:` and `cue:` on the repeat step (its first pass is the cue), or leave `cue:` out (each pass is "
        "numbered in show order)"]
    assert problems(text.replace("repeat: 2", "repeat: 1")) == []


def test_a_repeat_and_its_first_step_cannot_both_number_it():
    text = ("version: 1\nsteps:\n  - repeat: 1\n    at: go\n    cue: 4\n    steps:\n"
            "      - repeat: 1\n        steps:\n          - {play: 1, at: go, cue: 5}\n")
    assert problems(text) == ["steps[0].steps[0].steps[0].cue: this cue number and the repeat's `cue: 4` (line 5) "
                              "would number the same step: keep one"]
    first = "          - {play: 1, at: go, cue: 5}"
    second = text.replace(first, "          - play: 2\n" + first)
    assert problems(second) == []


def test_the_schema_says_what_a_cue_number_is_for():
    step = load_schema()["$defs"]["step"]["properties"]["cue"]
    assert "/choreo/cue/12.5/go" in step["description"] and "`at:`" in step["description"]
    text = next(form for form in step["anyOf"] if form["type"] == "string")
    assert text["maxLength"] == MAX_NUMBER_CHARS


# --------------------------------------------------------------------------- plan and validate


SHOW = """\
version: 1
tempo: {bpm: 120}
steps:
  - {play: 1, at: 0}
  - {play: 2, at: go, cue: 12.50, label: big finish}
  - {play: 3}
  - {play: 4, at: {bar: 5, beat: 2}, cue: B}
"""


def test_plan_shows_each_cue_number_within_80_columns(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    assert main(["plan", str(write_show(tmp_path, SHOW))]) == 0
    lines = capsys.readouterr().out.splitlines()
    table = lines[lines.index(next(line for line in lines if line.startswith("#"))):-1]
    assert table[0].split()[:5] == ["#", "cue", "label", "start", "step"]
    assert [line.split()[1] for line in table[1:]] == ["1", "12.50", "-", "B"]
    assert "big finish  0.000 s (waits for GO)" in table[2] and "play 2" in table[2]
    assert "(at 8.5 = bar 5 beat 2)  play 4" in table[4]
    assert all(len(line) <= 80 for line in lines)


def test_plan_json_lists_the_cues(tmp_path, capsys):
    assert main(["plan", "--json", str(write_show(tmp_path, SHOW))]) == 0
    record = json.loads(capsys.readouterr().out)
    assert [step["cue_number"] for step in record["plan"]] == ["1", "12.50", None, "B"]
    assert record["cues"] == [
        {"number": "1", "label": None, "robots": ["robot"], "planned_s": 0.0, "go": False, "at": 0.0,
         "bar": None, "beat": None},
        {"number": "12.50", "label": "big finish", "robots": ["robot"], "planned_s": 0.0, "go": True, "at": None,
         "bar": None, "beat": None},
        {"number": "B", "label": None, "robots": ["robot"], "planned_s": 8.5, "go": False, "at": 8.5,
         "bar": 5, "beat": 2.0},
    ]


def test_plan_json_of_several_robots_lists_the_show_cues_once(capsys):
    assert main(["plan", "--json", str(ROOT / "shows" / "canon.yaml")]) == 0
    record = json.loads(capsys.readouterr().out)
    assert [(cue["number"], cue["robots"]) for cue in record["cues"]] == [
        ("1", ["lead"]), ("2", ["follow"]), ("3", ["lead"]), ("4", ["follow"])]
    assert [step["cue_number"] for step in record["robots"]["follow"]["plan"] if step["cue_number"]] == ["2", "4"]


def test_validate_says_the_cue_numbers(tmp_path, capsys):
    path = write_show(tmp_path, SHOW)
    assert main(["validate", str(path), str(ROOT / "shows" / "minimal.yaml")]) == 0
    good, minimal = capsys.readouterr().out.splitlines()
    assert good == f"{path}: ok, 4 steps, 3 cues (1, 12.50, B), motions 1, 2, 3, 4, estimated 8.5 s"
    assert "cue" not in minimal
    assert main(["validate", "--json", str(path)]) == 0
    record = json.loads(capsys.readouterr().out)
    assert [cue["number"] for cue in record["files"][0]["cues"]] == ["1", "12.50", "B"]


@pytest.mark.parametrize(("numbers", "said"), [
    (["1", "2", "3"], "3 cues (1-3)"),
    (["1"], "1 cue (1)"),
    (["1", "2", "2.5", "3", "4", "A", "7"], "7 cues (1-2, 2.5, 3-4, A, 7)"),
    (["01", "02", "3"], "3 cues (01, 02, 3)"),
    ([str(n) for n in range(1, 40, 2)], "20 cues (1, 3, 5, 7, 9, 11, 13, 15, ...)"),
    ([], ""),
])
def test_the_cue_numbers_are_said_in_short(numbers, said):
    from choreo.cli.show import cue_numbers_text

    assert cue_numbers_text(numbers) == said
