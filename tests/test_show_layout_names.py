"""`robot.layout` and motion names in any script: what the show format accepts, and how it says no.

Heart to Heart 4 users name motions in Japanese (`歩く`, `ウェーブ`); those are names. Brackets,
arrows and spaces are not (they would not read as one word in a step or a log). The schema's
pattern is what an editor checks; choreo also applies `is_motion_name`: the pattern must never
refuse a name choreo accepts, and in ECMAScript (the editor's regex) it must mean the same.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import pytest

from choreo.errors import ShowError
from choreo.wire.layouts import LAYOUT_NAMES
from choreo.show.load import load_schema, load_show_bytes
from choreo.show.model import MOTION_NAME_MAX, is_motion_name


def show(body: str) -> bytes:
    return ("version: 1\n" + body).encode("utf-8")


def problem_lines(source: bytes) -> list[str]:
    with pytest.raises(ShowError) as info:
        load_show_bytes(source, "s.yaml")
    return [str(p) for p in info.value.problems]


# ------------------------------------------------------------------ robot.layout


@pytest.mark.parametrize("layout", LAYOUT_NAMES)
def test_a_known_layout_is_read_into_the_robot_settings(layout):
    loaded = load_show_bytes(show(f"robot:\n  layout: {layout}\nsteps:\n  - play: 1\n"))
    assert loaded.robot.layout == layout


def test_no_layout_is_none_so_the_run_can_tell_it_was_not_given():
    assert load_show_bytes(show("steps:\n  - play: 1\n")).robot.layout is None
    assert load_show_bytes(show("robot:\n  baud: 115200\nsteps:\n  - play: 1\n")).robot.layout is None


@pytest.mark.parametrize("value", ["hth4", "HTH4-2.2", "\"2.2\"", "''"])
def test_an_unknown_layout_is_one_located_line_naming_the_known_ones(value):
    lines = problem_lines(show(f"robot:\n  layout: {value}\nsteps:\n  - play: 1\n"))
    assert len(lines) == 1
    assert lines[0].startswith("s.yaml:3:11: robot.layout: unknown layout ")
    assert "`seed` or `hth4-2.2`" in lines[0]


def test_a_layout_that_is_not_text_says_so():
    lines = problem_lines(show("robot:\n  layout: 2.2\nsteps:\n  - play: 1\n"))
    assert lines == ["s.yaml:3:11: robot.layout: expected text, not the number 2.2"]


def test_the_schema_lists_the_layouts_choreo_knows_with_seed_the_default():
    layout = load_schema()["$defs"]["robot"]["properties"]["layout"]
    assert tuple(layout["enum"]) == LAYOUT_NAMES
    assert layout["default"] == "seed" == LAYOUT_NAMES[0]


# ------------------------------------------------------------------ motion names


@pytest.mark.parametrize("name", ["wave", "_x", "a-b", "歩く", "ウェーブ", "右手2", "々", "Ｗａｖｅ", "ｳｪｰﾌﾞ", "café",
                                  "नमस्ते", "𠮷野"])
def test_a_name_in_any_script_names_a_motion_and_can_be_played(name):
    loaded = load_show_bytes(show(f"motions:\n  {name}: {{number: 3}}\nsteps:\n  - play: {name}\n  - wait: done\n"))
    assert loaded.motions[name].number == 3
    assert loaded.steps[0].motion == 3 and loaded.steps[0].motion_name == name


@pytest.mark.parametrize(
    "name",
    ["歩く（前）→", "歩く（前）", "右・左", "a b", "a\u3000b", "1a", "１a", "-a", "a.b", "wave→", "a‿b", "\u3099a",
     "a\u200bb", "a\tb"],
)
def test_punctuation_symbols_spaces_and_a_leading_digit_are_refused_at_the_key(name):
    key = json.dumps(name, ensure_ascii=False)
    lines = problem_lines(show(f"motions:\n  {key}: {{number: 3}}\nsteps:\n  - play: 3\n"))
    assert len(lines) == 1
    assert lines[0].startswith("s.yaml:3:3: motions")
    assert "must start with a letter or `_` and hold only letters, digits, `_` and `-`" in lines[0]


def test_a_name_over_the_limit_has_its_own_message():
    name = "歩" * (MOTION_NAME_MAX + 1)
    lines = problem_lines(show(f"motions:\n  {name}: {{number: 3}}\nsteps:\n  - play: 3\n"))
    assert lines == [f"s.yaml:3:3: motions.{name}: motion name is longer than {MOTION_NAME_MAX} characters"]


def test_the_schema_and_the_model_agree_on_the_length_limit():
    assert load_schema()["properties"]["motions"]["propertyNames"]["maxLength"] == MOTION_NAME_MAX


def _pattern() -> str:
    return load_schema()["properties"]["motions"]["propertyNames"]["pattern"]


def test_the_schema_pattern_never_refuses_a_name_choreo_accepts():
    """Checked for every code point, as a later and as a first character."""
    pattern = re.compile(_pattern())
    every = (chr(code) for code in range(0x110000) if not 0xD800 <= code <= 0xDFFF)
    later = [ch for ch in every if is_motion_name("a" + ch)]
    first = [ch for ch in later if is_motion_name(ch)]
    if not pattern.fullmatch("a" + "".join(later)):
        assert [hex(ord(ch)) for ch in later if not pattern.fullmatch("a" + ch)] == []
    assert [hex(ord(ch)) for ch in first if not pattern.fullmatch(ch)] == []


SAMPLES = ["wave", "_x", "a-b", "歩く", "ウェーブ", "歩く（前）→", "a b", "1a", "-a", "a.b", "wave\n", "右・左", "𠮷野",
           "Ｗａｖｅ", "（"]


@pytest.mark.skipif(shutil.which("node") is None, reason="no node to run the pattern as an editor does")
def test_the_schema_pattern_means_the_same_in_an_editors_regex_engine():
    """Editors (the YAML language server) run `pattern` as an ECMAScript regex, with or without `u`."""
    script = (
        "const [pattern, names] = JSON.parse(process.argv[1]);"
        'console.log(JSON.stringify(["", "u"].map(f => names.map(n => new RegExp(pattern, f).test(n)))));'
    )
    out = subprocess.run(["node", "-e", script, json.dumps([_pattern(), SAMPLES])], capture_output=True, text=True,
                         timeout=30, check=True)
    # Whole-string matches: Python's `$` also matches before a final newline (`is_motion_name`
    # refuses such a name); ECMAScript's does not.
    python = [bool(re.fullmatch(_pattern(), name)) for name in SAMPLES]
    assert json.loads(out.stdout) == [python, python]

