"""`load_show`: every rule of the show format and every class of bad input, located exactly.

Each bad file is asserted by (line, column, path) and the gist of its message: what an author
reads is the point, and a wrong column sends them to the wrong character.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from textwrap import dedent

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
import yaml

from choreo.errors import Problem, ShowError
from choreo.show.checks import MAX_PLAN_STEPS
from choreo.show.load import load_schema, load_show, load_show_bytes
from choreo.show.read import MAX_BYTES
from choreo.show.yamlwalk import MAX_DEPTH
from choreo.show.model import DEFAULT_DONE_TIMEOUT_S, Repeat, Step, StepKind
from runlog import HANG_S

ROOT = Path(__file__).resolve().parent.parent
SHOWS = sorted((ROOT / "shows").glob("*.yaml"))


def write(tmp_path: Path, text: str | bytes, name: str = "show.yaml") -> Path:
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(dedent(text).lstrip("\n"), encoding="utf-8")
    return path


def problems(tmp_path: Path, text: str | bytes) -> list[Problem]:
    path = write(tmp_path, text)
    with pytest.raises(ShowError) as info:
        load_show(path)
    found = info.value.problems
    assert found, "a ShowError must carry at least one problem"
    for problem in found:
        assert "\n" not in str(problem), "one line a problem"
        assert problem.file == str(path)
    return found


def located(found: list[Problem]) -> list[tuple[int, int, str]]:
    return [(p.line, p.column, p.path) for p in found]


def only(tmp_path: Path, text: str | bytes) -> Problem:
    found = problems(tmp_path, text)
    assert len(found) == 1, [str(p) for p in found]
    return found[0]


# ------------------------------------------------------------------ valid shows


@pytest.mark.parametrize("path", SHOWS, ids=lambda p: p.name)
def test_every_example_show_loads(path):
    show = load_show(path)
    assert show.steps or all(show.tracks.values())
    assert show.source == path.read_bytes()


@pytest.mark.parametrize("path", SHOWS, ids=lambda p: p.name)
def test_every_example_names_the_schema_for_editors(path):
    assert path.read_text().splitlines()[0] == "# yaml-language-server: $schema=../schemas/show.schema.json"


def test_examples_are_there():
    assert {p.name for p in SHOWS} >= {"dance.yaml", "minimal.yaml", "music.yaml"}


def test_dance_loads_into_records():
    show = load_show(ROOT / "shows" / "dance.yaml")
    assert show.name == "Dance"
    assert show.motions["home"].number == 0 and show.motions["home"].duration == 1.5
    assert show.on_abort == 0  # `on_abort: home`, resolved to its slot
    first = show.steps[0]
    assert isinstance(first, Step)
    assert (first.kind, first.motion, first.motion_name, first.label) == (StepKind.PLAY, 0, "home", "start")
    assert (first.path, first.line, first.column) == ("steps[0]", 23, 5)
    groove = next(s for s in show.steps if isinstance(s, Repeat))
    assert groove.count == 2 and groove.label == "groove" and len(groove.steps) == 6
    assert groove.steps[1].path == "steps[8].steps[1]"
    spin = next(s for s in show.steps if s.label == "spin")
    assert spin.at == 14.0


def test_a_show_loads_from_bytes_too():
    """For a show attached to a log: no file needed, the same checks, the name given used."""
    source = (ROOT / "shows" / "dance.yaml").read_bytes()
    show = load_show_bytes(source, "attached/dance.yaml")
    assert show == dataclasses.replace(load_show(ROOT / "shows" / "dance.yaml"), path="attached/dance.yaml")
    with pytest.raises(ShowError) as info:
        load_show_bytes(b"version: 1\nsteps: [{play: 200}]\n", "log:show.yaml")
    assert info.value.lines() == ["log:show.yaml:2:16: steps[0].play: motion 200 is out of range 0..119"]
    with pytest.raises(ShowError) as info:
        load_show_bytes(b"#" * (MAX_BYTES + 1))
    assert info.value.lines() == ["<show>: the file is over 256 KiB, too big for a show file"]


def test_minimal_show_gets_defaults(tmp_path):
    show = load_show(write(tmp_path, "version: 1\nsteps:\n  - play: 3\n  - wait: done\n", "opening.yaml"))
    assert show.name == "opening"  # the file's name when the show gives none
    assert show.motions == {} and show.on_abort is None
    assert show.robot.port is None and show.robot.baud is None
    assert show.steps[0].motion == 3 and show.steps[0].motion_name is None
    assert show.steps[1].kind is StepKind.WAIT_DONE and show.steps[1].seconds == DEFAULT_DONE_TIMEOUT_S


def test_robot_settings_and_timeout_are_read(tmp_path):
    show = load_show(write(tmp_path, """
        version: 1
        robot: {port: /dev/ttyUSB0, baud: 625000, timeout: 0.5, retries: 0}
        steps:
          - play: 1
          - wait: done
            timeout: 4
          - wait: 1.5
    """))
    robot = show.robot
    assert (robot.port, robot.baud, robot.timeout, robot.retries) == ("/dev/ttyUSB0", 625000, 0.5, 0)
    assert show.steps[1].seconds == 4.0
    assert show.steps[2].kind is StepKind.WAIT and show.steps[2].seconds == 1.5


def test_a_byte_order_mark_is_accepted(tmp_path):
    show = load_show(write(tmp_path, b"\xef\xbb\xbfversion: 1\nsteps: [{play: 1}]\n"))
    assert show.steps[0].motion == 1


def test_quoted_and_date_like_labels_stay_text(tmp_path):
    show = load_show(write(tmp_path, """
        version: 1
        steps:
          - play: 1
            label: 2024-05-01
          - play: 2
            label: "yes"
    """))
    assert [s.label for s in show.steps] == ["2024-05-01", "yes"]


# ------------------------------------------------------------------ the file itself


def test_missing_file(tmp_path):
    with pytest.raises(ShowError) as info:
        load_show(tmp_path / "nope.yaml")
    assert info.value.lines() == [f"{tmp_path / 'nope.yaml'}: cannot read the show file: No such file or directory"]


def test_a_directory_is_not_a_show(tmp_path):
    with pytest.raises(ShowError) as info:
        load_show(tmp_path)
    assert "not a regular file (a folder)" in info.value.lines()[0]


def test_a_huge_file_is_refused_unread(tmp_path):
    problem = only(tmp_path, b"version: 1\n" + b"# padding\n" * (MAX_BYTES // 10 + 1))
    assert (problem.line, problem.path) == (0, "")
    assert "too big for a show file" in problem.message


def test_a_file_at_the_limit_is_read(tmp_path):
    head = b"version: 1\nsteps: [{play: 1}]\n"
    load_show(write(tmp_path, head + b"#" * (MAX_BYTES - len(head) - 1) + b"\n"))


def test_not_utf8_is_located_in_characters(tmp_path):
    problem = only(tmp_path, "version: 1\nname: é\nsteps:\n  - play: é".encode() + b"\xff\n")
    assert (problem.line, problem.column) == (4, 12)
    assert problem.message == "not UTF-8 (byte 0xff): save the file as UTF-8"


@pytest.mark.parametrize(
    "text,line,column,gist",
    [
        ("version: 1\nsteps: [\n", 3, 1, "did not find expected node content"),
        ("version: 1\nsteps:\n  - play: 1\n bad\n", 4, 2, "YAML syntax error"),
        ("version: 1\nname: a: b\n", 2, 8, "mapping values are not allowed"),
        ('version: 1\nname: "\\q"\n', 2, 8, "unknown escape character"),
        ("version: 1\n\tsteps: []\n", 2, 1, "YAML syntax error"),
    ],
)
def test_yaml_syntax_errors_are_located(tmp_path, text, line, column, gist):
    problem = only(tmp_path, text)
    assert (problem.line, problem.column, problem.path) == (line, column, "")
    assert gist in problem.message


def test_a_control_character_is_located(tmp_path):
    problem = only(tmp_path, "version: 1\nname: a\x01b\n")
    assert (problem.line, problem.column) == (2, 8)
    assert "not allowed in a YAML file" in problem.message


@pytest.mark.parametrize("text", ["", "# only a comment\n", "---\n", "~\n"])
def test_an_empty_file(tmp_path, text):
    problem = only(tmp_path, text)
    assert (problem.line, problem.column) == (1, 1)
    assert "holds no show" in problem.message


@pytest.mark.parametrize(
    "text,column,kind",
    [("- play: 1\n", 1, "a list"), ("just text\n", 1, "the text 'just text'"), ("# c\n  42\n", 3, "the number 42")],
)
def test_the_top_level_must_be_a_mapping(tmp_path, text, column, kind):
    problem = only(tmp_path, text)
    assert problem.column == column
    assert problem.message == f"the top level must be a mapping (`version: 1`, `steps:` ...), not {kind}"


def test_one_document_only(tmp_path):
    problem = only(tmp_path, "version: 1\nsteps: [{play: 1}]\n---\nversion: 1\n")
    assert (problem.line, problem.column) == (3, 1)
    assert "one YAML document" in problem.message


# ------------------------------------------------------------------ unsafe YAML


def test_duplicate_keys_point_at_the_second(tmp_path):
    found = problems(tmp_path, """
        version: 1
        steps:
          - play: 1
            play: 2
        version: 1
    """)
    assert located(found) == [(4, 5, "steps[0].play"), (5, 1, "version")]
    assert found[0].message == "duplicate key 'play' (first given at line 3): keep one"
    assert found[1].message == "duplicate key 'version' (first given at line 1): keep one"


def test_aliases_are_refused(tmp_path):
    problem = only(tmp_path, """
        version: 1
        steps:
          - &p {play: 1}
          - *p
    """)
    assert (problem.line, problem.column, problem.path) == (4, 5, "steps[1]")
    assert problem.message == "aliases (*p) are not allowed in a show file: write the value out"


def test_aliases_anywhere_are_one_problem_and_no_crash(tmp_path):
    found = problems(tmp_path, """
        version: 1
        n: &n 2
        steps:
          - repeat: *n
            steps: [{play: 1}]
          - repeat: *n
            steps: [{play: 1}]
            at: *n
    """)
    assert located(found) == [(2, 1, "n"), (4, 13, "steps[0].repeat")]
    assert found[1].message.endswith("(2 more after this one)")


def test_keys_that_are_not_text_do_not_hide_other_problems(tmp_path):
    found = problems(tmp_path, "? [a, b]\n: 1\nsteps: [{play: 1}]\n")
    assert located(found) == [(1, 1, "version"), (1, 3, "")]


def test_merge_keys_are_refused(tmp_path):
    found = problems(tmp_path, """
        version: 1
        steps:
          - &base {play: 1}
          - <<: *base
            label: x
    """)
    assert located(found) == [(4, 5, 'steps[1]["<<"]'), (4, 9, 'steps[1]["<<"]')]
    assert found[0].message.startswith("unknown key '<<'")
    assert found[1].message.startswith("aliases (*base) are not allowed")


def test_a_billion_laughs_is_refused_at_once(tmp_path):
    lines = ['version: 1', 'a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for n in range(1, 10):
        lines.append(f"a{n}: &a{n} [" + ", ".join([f"*a{n - 1}"] * 9) + "]")
    lines.append("steps: *a9")
    path = write(tmp_path, "\n".join(lines) + "\n")
    started = time.perf_counter()
    with pytest.raises(ShowError) as info:
        load_show(path)
    assert time.perf_counter() - started < HANG_S
    aliases = [p for p in info.value.problems if "aliases" in p.message]
    assert len(aliases) == 1  # reported once, counted after that
    assert (aliases[0].line, aliases[0].column) == (3, 10)
    assert aliases[0].message.endswith("(81 more after this one)")


@pytest.mark.parametrize(
    "value,tag",
    [
        ('!!python/object/apply:os.system ["echo hi"]', "!!python/object/apply:os.system"),
        ("!!python/name:os.system ''", "!!python/name:os.system"),
        ("!custom 3", "!custom"),
        ("!!binary aGk=", "!!binary"),
        ("!!set {a, b}", "!!set"),
    ],
)
def test_tags_that_build_objects_are_refused(tmp_path, value, tag):
    found = problems(tmp_path, f"version: 1\nsteps:\n  - play: {value}\n")
    assert located(found)[0] == (3, 11, "steps[0].play")
    assert found[0].message == f"tag {tag} is not allowed in a show file: remove it"


def test_plain_data_tags_are_fine(tmp_path):
    show = load_show(write(tmp_path, 'version: 1\nsteps:\n  - play: !!int "7"\n  - wait: !!float 2\n'))
    assert show.steps[0].motion == 7 and show.steps[1].seconds == 2.0


def test_a_bad_explicit_tag_value_is_located(tmp_path):
    problem = only(tmp_path, 'version: 1\nsteps:\n  - play: !!int "seven"\n')
    assert (problem.line, problem.column, problem.message) == (3, 11, "cannot read 'seven' as int")


def test_keys_must_be_text(tmp_path):
    problem = only(tmp_path, "version: 1\n? [a, b]\n: 1\nsteps: [{play: 1}]\n")
    assert (problem.line, problem.column) == (2, 3)
    assert "a key must be plain text" in problem.message


def test_nesting_is_bounded(tmp_path):
    started = time.perf_counter()
    problem = only(tmp_path, "[" * (MAX_BYTES - 1))
    assert time.perf_counter() - started < HANG_S
    assert (problem.line, problem.column) == (1, MAX_DEPTH)
    assert problem.message == f"nested more than {MAX_DEPTH} levels deep"


class _StrictScanner(yaml.scanner.Scanner):
    """A scanner with a nesting limit of twice choreo's, far below libyaml's 1,000.

    choreo hands the parser text nested at most `MAX_DEPTH` deep in flow plus `MAX_DEPTH` in
    block context, so a parser whose limit is at least twice choreo's never decides the message.
    """

    def _check_level(self) -> None:
        if self.flow_level + len(self.indents) > 2 * MAX_DEPTH + 2:
            raise yaml.scanner.ScannerError("while increasing level", None, "exceeded maximum nesting depth",
                                            self.get_mark())

    def add_indent(self, column):
        added = super().add_indent(column)
        self._check_level()
        return added

    def fetch_flow_collection_start(self, TokenClass):
        super().fetch_flow_collection_start(TokenClass)
        self._check_level()


class _StrictLoader(yaml.reader.Reader, _StrictScanner, yaml.parser.Parser, yaml.composer.Composer,
                    yaml.constructor.SafeConstructor, yaml.resolver.Resolver):
    def __init__(self, stream):
        yaml.reader.Reader.__init__(self, stream)
        _StrictScanner.__init__(self)
        yaml.parser.Parser.__init__(self)
        yaml.composer.Composer.__init__(self)
        yaml.constructor.SafeConstructor.__init__(self)
        yaml.resolver.Resolver.__init__(self)


_PARSERS = {"libyaml": getattr(yaml, "CSafeLoader", yaml.SafeLoader), "python": yaml.SafeLoader,
            "strict": _StrictLoader}
_DEEP = {
    "flow lists": "[" * 5000,
    "flow maps": "{a: " * 5000,
    "lists of maps": "[{a: " * 3000,
    "flow in a step": "version: 1\nsteps:\n  - play: " + "[" * 5000,
    "flow after commas": "steps: [" + "1, [" * 3000,
    "flow over lines": "steps:\n" + "  [ # a comment\n" * 2000,
    "block lists": "- " * 3000 + "x",
    "block maps": "".join(" " * i + "a:\n" for i in range(300)),
    "explicit keys": "? " * 3000,
    # brackets the pre-scan takes for flow (a plain scalar's next line, a compact `- key: |`
    # whose text starts at the key's column) must not hide a deep flow later in the file
    "after a plain scalar's brackets": "steps:\n  - play: abc\n      " + "[" * 45 + "\n  - play: " + "[" * 5000,
    "after a compact block scalar": "steps:\n- play: |\n  x: " + "[" * 5000,
}


@pytest.mark.parametrize("parser", sorted(_PARSERS))
@pytest.mark.parametrize("shape", sorted(_DEEP))
def test_nesting_is_reported_in_choreos_words_whatever_the_parsers_limits(tmp_path, monkeypatch, parser, shape):
    """PyYAML 6.0.4's scanner stops `[[[[…` at its own limit before any event reaches choreo."""
    monkeypatch.setattr("choreo.show.read._Parser", _PARSERS[parser])
    found = problems(tmp_path, _DEEP[shape])
    assert f"nested more than {MAX_DEPTH} levels deep" in [p.message for p in found]
    assert not any("YAML syntax error" in p.message for p in found)


@pytest.mark.parametrize("parser", sorted(_PARSERS))
@pytest.mark.parametrize("text", [
    "version: 1\nsteps:\n- play: |\n  " + "[" * 5000 + "]" * 5000 + ": 1\n",
    "version: 1\nsteps:\n- play: >-\n  " + "{" * 3000 + "}" * 3000 + ": 1\n",
    "version: 1\nsteps:\n  - wait: |\n    " + "[" * 5000 + "]" * 5000 + ": 1\n",
], ids=["seq entry key", "folded", "indented"])
def test_a_deep_key_at_a_block_scalars_column_is_said_in_choreos_words(tmp_path, monkeypatch, parser, text):
    """A flow key at its mapping's column is withheld from the events until its `:`: the walk
    never sees it; libyaml 0.2.5's scanner stops at its nesting limit, PyYAML 6.0's at a key
    longer than 1,024 characters. The text after `play: |` at the key's column is not the block
    scalar's (its text is deeper than the key), so the pre-scan counts its brackets."""
    monkeypatch.setattr("choreo.show.read._Parser", _PARSERS[parser])
    found = problems(tmp_path, text)
    assert [p.message for p in found] == [f"nested more than {MAX_DEPTH} levels deep"]


_DEEP_CONTEXTS = ["", "version: 1\nsteps:\n  - play: ", "- ", "a:\n  b: ", "name: 'x'\nsteps: ", "--- ",
                  "version: 1\nsteps:\n- play: |\n  ", "? ", "a: &x ", "a: !!seq "]


@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.sampled_from(_DEEP_CONTEXTS),
       st.lists(st.tuples(st.sampled_from(["[", "{a: ", "[1, ", "{? ", "[ ", '["s", ', "['q', "]),
                          st.sampled_from(["", " ", "\n  ", " # c\n  ", "\r\n  "])), min_size=41, max_size=600),
       st.booleans())
def test_no_parser_limit_ever_decides_a_deep_files_message(context, parts, closed):
    """Any deep nesting, in any context, read by libyaml, the Python parser or a strict one: the
    parser's own limit never reaches the user; in a plain context the message is choreo's depth."""
    text = context + "".join(opener + gap for opener, gap in parts) + ("1" + "]" * len(parts) if closed else "")
    for name, parser in _PARSERS.items():
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr("choreo.show.read._Parser", parser)
            with pytest.raises(ShowError) as info:
                load_show_bytes(text.encode())
        messages = [p.message for p in info.value.problems]
        assert not any("exceeded" in m or "maximum" in m for m in messages), (name, messages)
        if not any(c in context for c in "|?!&") and "{?" not in text:
            assert f"nested more than {MAX_DEPTH} levels deep" in messages, (name, messages)


@pytest.mark.parametrize("parser", sorted(_PARSERS))
def test_a_parsers_limit_past_a_syntax_error_leaves_the_syntax_error(tmp_path, monkeypatch, parser):
    """libyaml's scanner reads ahead to its nesting limit before its parser reaches `[a[b`."""
    monkeypatch.setattr("choreo.show.read._Parser", _PARSERS[parser])
    found = problems(tmp_path, "version: 1\nsteps:\n  - play: [a[b, " + "[" * 5000)
    assert [(p.line, p.column) for p in found] == [(3, 13)]
    assert "nesting" not in found[0].message and "YAML syntax error" in found[0].message


@pytest.mark.parametrize("parser", sorted(_PARSERS))
@pytest.mark.parametrize("text", [
    'version: 1\nname: "' + "[" * 150 + '"\nsteps:\n  - play: 1\n',
    "version: 1\nname: '" + "[{" * 75 + "'\nsteps:\n  - play: 1\n",
    "version: 1\nname: a" + "[" * 150 + "\nsteps:\n  - play: 1\n",
    "version: 1\nname: |-\n  " + "[" * 150 + "\nsteps:\n  - play: 1\n",
    "# " + "[" * 200 + "\nversion: 1\nsteps: [{play: 1}, " + ", ".join(["{wait: 1}"] * 100) + "]\n",
], ids=["double-quoted", "single-quoted", "plain", "block scalar", "comment and many flat maps"])
def test_brackets_that_are_text_or_flat_are_not_nesting(tmp_path, monkeypatch, parser, text):
    monkeypatch.setattr("choreo.show.read._Parser", _PARSERS[parser])
    assert load_show(write(tmp_path, text)).steps


# ------------------------------------------------------------------ schema


def test_required_keys_point_at_the_mapping(tmp_path):
    found = problems(tmp_path, "# a show\nname: x\n")
    assert located(found) == [(2, 1, "version"), (2, 1, "steps")]
    assert found[0].message == "missing: add `version: 1` (the show format's version)"
    assert found[1].message == ("missing: a show needs `steps:`, the list of what it does "
                                "(or, with `robots:`, `tracks:`)")


def test_an_empty_value_points_at_its_key(tmp_path):
    problem = only(tmp_path, "version: 1\nsteps:\n")
    assert (problem.line, problem.column, problem.path) == (2, 1, "steps")
    assert problem.message == "expected a list (`- item` lines), not an empty value"


def test_unknown_keys_are_located_at_the_key_with_a_suggestion(tmp_path):
    found = problems(tmp_path, """
        version: 1
        robots: {port: x}
        steps:
          - plya: 3
          - play: 1
            lable: hi
    """)
    assert located(found) == [(2, 16, "robots.port"), (4, 5, "steps[0].plya"), (6, 5, "steps[1].lable")]
    assert found[0].message.startswith("robot 'port': expected its settings as a mapping")
    assert found[0].message.endswith("a show for one robot says `robot:`")
    assert found[1].message.startswith("unknown key 'plya': did you mean `play`? expected one of at, cue, label, play")
    assert found[2].message.startswith("unknown key 'lable': did you mean `label`?")


@pytest.mark.parametrize(
    "text,where,message",
    [
        ("version: 2\nsteps: [{play: 1}]\n", (1, 10, "version"),
         "unsupported format version 2: this choreo reads `version: 1`"),
        ('version: "1"\nsteps: [{play: 1}]\n', (1, 10, "version"), "expected a whole number, not the text '1'"),
        ("version: 1\nname: 3\nsteps: [{play: 1}]\n", (2, 7, "name"), "expected text, not the number 3"),
        ("version: 1\nsteps: {play: 1}\n", (2, 8, "steps"), "expected a list (`- item` lines), not a mapping"),
        ("version: 1\nsteps: []\n", (2, 8, "steps"), "must not be empty: list at least one step"),
        ("version: 1\nsteps:\n  - play 3\n", (3, 5, "steps[0]"),
         "expected a mapping (`key: value` lines), not the text 'play 3'"),
        ("version: 1\nsteps:\n  - play: true\n", (3, 11, "steps[0].play"),
         "expected a motion number 0..119 or a name from `motions:`, not true (put the word in quotes to mean text)"),
        ("version: 1\nsteps:\n  - play: on\n", (3, 11, "steps[0].play"),  # YAML 1.2: `on` is text
         "unknown motion 'on': name it in `motions:` with its slot number, or play the number"),
        ("version: 1\nsteps:\n  - play: 3.5\n", (3, 11, "steps[0].play"),
         "expected a motion number 0..119 or a name from `motions:`, not the number 3.5"),
        ("version: 1\nsteps:\n  - play: ''\n", (3, 11, "steps[0].play"), "the motion name is empty"),
        ("version: 1\nsteps:\n  - play: 1\n    label: 7\n", (4, 12, "steps[0].label"),
         "expected text, not the number 7"),
    ],
)
def test_wrong_types_and_values(tmp_path, text, where, message):
    problem = only(tmp_path, text)
    assert (problem.line, problem.column, problem.path) == where
    assert problem.message == message


@pytest.mark.parametrize("value", ["140", "120", "-1"])
def test_play_out_of_range(tmp_path, value):
    path = write(tmp_path, f"version: 1\nmotions:\n  wave: {{number: 3}}\nsteps:\n  - play: wave\n  - wait: 1\n"
                           f"  - play: {value}\n")
    with pytest.raises(ShowError) as info:
        load_show(path)
    assert info.value.lines() == [f"{path}:7:11: steps[2].play: motion {value} is out of range 0..119"]


def test_motion_table_numbers_are_in_range(tmp_path):
    found = problems(tmp_path, """
        version: 1
        motions:
          wave: {number: 140}
          bow:
            duration: 2
        on_abort: 120
        steps: [{play: 1}]
    """)
    assert located(found) == [(3, 18, "motions.wave.number"), (5, 5, "motions.bow.number"), (6, 11, "on_abort")]
    assert [p.message for p in found] == [
        "motion 140 is out of range 0..119",
        "missing: give the motion's slot, e.g. `number: 3`",
        "motion 120 is out of range 0..119",
    ]


@pytest.mark.parametrize(
    "value,message",
    [
        ("0", "wait takes more than 0 seconds, not 0"),
        ("-1.5", "wait takes more than 0 seconds, not -1.5"),
        ("soon", "wait takes seconds (a number > 0) or `done`, not 'soon'"),
        ("Done", "wait takes seconds (a number > 0) or `done`, not 'Done'"),
        (".inf", "wait takes at most 86400 seconds (a day), not .inf"),
        (".nan", "not-a-number (.nan) is not allowed here"),
        ("[1]", "wait takes seconds (a number > 0) or `done`, not a list"),
    ],
)
def test_wait_values(tmp_path, value, message):
    problem = only(tmp_path, f"version: 1\nsteps:\n  - play: 1\n  - wait: {value}\n")
    assert (problem.line, problem.column, problem.path) == (4, 11, "steps[1].wait")
    assert problem.message == message


@pytest.mark.parametrize("value", [
    "1" + "0" * 5000,  # past Python's 4,300 digits for int(text): a ValueError, not a problem
    "-" + "9" * 4400,
    "0" + "1" * 5000,  # the leading-zero message converts it too
    "0x" + "f" * 5000,  # converts, but cannot be printed in a message
    "0o" + "7" * 5000,
    "!!int 0x" + "f" * 5000,
    "!!int 0b" + "1" * 20000,
    "1" + "0" * 40,
])
def test_a_whole_number_too_long_for_any_value_is_a_located_problem(tmp_path, value):
    problem = only(tmp_path, f"version: 1\nsteps:\n  - play: {value}\n")
    assert (problem.line, problem.column, problem.path) == (3, 11, "steps[0].play")
    assert "characters long" in problem.message and len(problem.message) < 120


@pytest.mark.parametrize(("value", "message"), [
    ("0x" + "F" * 28, "motion 5192296858534827628530496329220095 is out of range 0..119"),  # 112 bits, 30 characters
    ("1" * 30, "motion 111111111111111111111111111111 is out of range 0..119"),
    ("!!int " + "1" * 30, "motion 111111111111111111111111111111 is out of range 0..119"),  # 97 bits
    ("!!int 0x" + "F" * 28, "a whole number 30 characters long (0xFFFFFFFFFF…): no value in a show needs more than 30"),
    ("1" * 31, "a whole number 31 characters long (111111111111…): no value in a show needs more than 30"),
])
def test_a_plain_whole_number_is_bounded_by_its_length_a_tagged_one_by_its_value(tmp_path, value, message):
    """Plain numbers are refused past 30 characters before they are converted; a tagged `!!int`
    is converted by PyYAML (any base, underscores), so its value is what is bounded (100 bits)."""
    problem = only(tmp_path, f"version: 1\nsteps:\n  - play: {value}\n")
    assert (problem.line, problem.column, problem.path, problem.message) == (3, 11, "steps[0].play", message)


def test_a_long_value_a_tag_cannot_read_is_shown_cut(tmp_path):
    problem = only(tmp_path, "version: 1\nsteps:\n  - play: !!int 1" + "0" * 5000 + "\n")
    assert problem.message.startswith("cannot read '1000") and len(problem.message) < 80


def test_timeout_goes_with_wait_done_only(tmp_path):
    found = problems(tmp_path, """
        version: 1
        steps:
          - play: 1
            timeout: 3
          - wait: 2
            timeout: 3
          - wait: done
            timeout: 0
    """)
    assert located(found) == [(4, 5, "steps[0].timeout"), (6, 5, "steps[1].timeout"), (8, 14, "steps[2].timeout")]
    assert [p.message for p in found] == [
        "`timeout` goes with `wait: done` only",
        "`timeout` goes with `wait: done` only",
        "must be more than 0, not 0",
    ]


def test_a_step_does_exactly_one_thing(tmp_path):
    found = problems(tmp_path, """
        version: 1
        steps:
          - play: 1
            wait: 2
          - label: nothing
          - {}
          - wait: 1
            repeat: 2
            steps: [{play: 1}]
    """)
    assert located(found) == [(3, 5, "steps[0]"), (5, 5, "steps[1]"), (6, 5, "steps[2]"), (7, 5, "steps[3]")]
    assert found[0].message == "a step does one thing, this one has `play` and `wait`: make them separate steps"
    assert found[1].message == "a step needs one of `play`, `wait` or `repeat`"
    assert found[3].message == "a step does one thing, this one has `wait` and `repeat`: make them separate steps"


def test_repeat_rules(tmp_path):
    found = problems(tmp_path, """
        version: 1
        steps:
          - repeat: 2
          - steps: [{play: 1}]
          - repeat: 0
            steps: [{play: 1}]
          - repeat: 1001
            steps: [{play: 1}]
          - repeat: 2
            steps: []
          - repeat: two
            steps: [{play: 1}]
    """)
    assert located(found) == [
        (3, 5, "steps[0].repeat"),
        (4, 5, "steps[1].steps"),
        (5, 13, "steps[2].repeat"),
        (7, 13, "steps[3].repeat"),
        (10, 12, "steps[4].steps"),
        (11, 13, "steps[5].repeat"),
    ]
    assert [p.message for p in found] == [
        "`repeat` needs the `steps:` to repeat",
        "nested `steps:` need `repeat: N` beside them",
        "must be at least 1, not 0",
        "must be at most 1000, not 1001",
        "must not be empty: list at least one step",
        "expected a whole number, not the text 'two'",
    ]


def test_robot_settings_are_checked(tmp_path):
    found = problems(tmp_path, """
        version: 1
        robot:
          port: ""
          baud: 9600
          timeout: 0
          retries: 11
          parity: even
        steps: [{play: 1}]
    """)
    assert located(found) == [
        (3, 9, "robot.port"),
        (4, 9, "robot.baud"),
        (5, 12, "robot.timeout"),
        (6, 12, "robot.retries"),
        (7, 3, "robot.parity"),
    ]
    assert found[1].message == "baud 9600 is not one the RCB-4 speaks: 115200, 625000 or 1250000"
    assert found[3].message == "must be at most 10, not 11"


def test_motion_names_are_identifiers(tmp_path):
    problem = only(tmp_path, 'version: 1\nmotions:\n  "wave hello": {number: 3}\nsteps: [{play: 1}]\n')
    assert (problem.line, problem.column, problem.path) == (3, 3, 'motions["wave hello"]')
    assert problem.message.startswith("motion name 'wave hello' must start with a letter")


@pytest.mark.parametrize(
    "label,column",
    [("'12'", 12), ("a#b", 12), ('"tab\\there"', 12)],
)
def test_labels_are_names(tmp_path, label, column):
    problem = only(tmp_path, f"version: 1\nsteps:\n  - play: 1\n    label: {label}\n")
    assert (problem.line, problem.column, problem.path) == (4, column, "steps[0].label")
    assert "must not be only digits" in problem.message


# ------------------------------------------------------------------ meaning


def test_unknown_motion_names(tmp_path):
    found = problems(tmp_path, """
        version: 1
        motions:
          wave: {number: 4}
          bow: {number: 1}
        on_abort: hmoe
        steps:
          - play: wav
          - play: jump
    """)
    assert located(found) == [(5, 11, "on_abort"), (7, 11, "steps[0].play"), (8, 11, "steps[1].play")]
    assert found[0].message == "unknown motion 'hmoe': the show's motions are bow, wave"
    assert found[1].message == "unknown motion 'wav': did you mean 'wave'? the show's motions are bow, wave"


def test_a_name_without_a_motion_table(tmp_path):
    problem = only(tmp_path, "version: 1\nsteps:\n  - play: wave\n")
    assert (problem.line, problem.column) == (3, 11)
    assert problem.message == "unknown motion 'wave': name it in `motions:` with its slot number, or play the number"


def test_names_resolve_and_a_slot_may_have_two_names(tmp_path):
    show = load_show(write(tmp_path, """
        version: 1
        motions:
          wave: {number: 4, duration: 1.2}
          hello: {number: 4}
        on_abort: hello
        steps:
          - play: hello
    """))
    assert show.on_abort == 4 and show.steps[0].motion == 4 and show.steps[0].motion_name == "hello"
    assert show.duration_of(4) == 1.2


def test_one_slot_two_durations_is_a_contradiction(tmp_path):
    problem = only(tmp_path, """
        version: 1
        motions:
          wave: {number: 4, duration: 1.2}
          hello: {number: 4, duration: 2}
        steps: [{play: 4}]
    """)
    assert (problem.line, problem.column, problem.path) == (4, 32, "motions.hello.duration")
    assert problem.message == "motion 4 is also 'wave' with duration 1.2: give one duration"


def test_wait_done_needs_a_play_before_it(tmp_path):
    found = problems(tmp_path, """
        version: 1
        steps:
          - wait: done
          - repeat: 2
            steps:
              - wait: done
              - play: 1
          - wait: done
    """)
    assert located(found) == [(3, 11, "steps[0].wait"), (6, 15, "steps[1].steps[0].wait")]
    assert found[0].message == "`wait: done` has no motion to wait for: play one before it"


def test_wait_done_after_a_play_inside_an_earlier_repeat_is_fine(tmp_path):
    load_show(write(tmp_path, """
        version: 1
        steps:
          - repeat: 2
            steps: [{play: 1}, {wait: 1}]
          - wait: done
    """))


def test_cues_must_not_go_back_in_time(tmp_path):
    problem = only(tmp_path, """
        version: 1
        steps:
          - play: 1
            at: 10
          - play: 2
            at: 10
          - play: 3
            at: 9.5
          - play: 4
            at: 12
    """)
    assert (problem.line, problem.column, problem.path) == (8, 9, "steps[2].at")
    assert problem.message == ("cue at 9.5 s comes after the cue at 10 s (steps[1].at, line 6): "
                               "cues must not go back in time")


def test_a_cue_earlier_than_the_repeat_it_is_in(tmp_path):
    problem = only(tmp_path, """
        version: 1
        steps:
          - repeat: 1
            at: 5
            steps:
              - play: 1
                at: 4
    """)
    assert (problem.line, problem.column, problem.path) == (7, 13, "steps[0].steps[0].at")


def test_a_cue_inside_a_repeated_body(tmp_path):
    problem = only(tmp_path, """
        version: 1
        steps:
          - repeat: 3
            steps:
              - play: 1
                at: 4
    """)
    assert (problem.line, problem.column, problem.path) == (6, 13, "steps[0].steps[0].at")
    assert "late on every pass after the first" in problem.message


def test_cues_on_repeats_and_in_single_passes_are_fine(tmp_path):
    show = load_show(write(tmp_path, """
        version: 1
        steps:
          - repeat: 4
            at: 2
            steps: [{play: 1}, {wait: 1}]
          - repeat: 1
            steps:
              - play: 2
                at: 8
    """))
    assert show.steps[0].at == 2.0 and show.steps[1].steps[0].at == 8.0


def test_cue_values(tmp_path):
    problem = only(tmp_path, "version: 1\nsteps:\n  - play: 1\n    at: -1\n")
    assert (problem.line, problem.column, problem.path, problem.message) == (
        4, 9, "steps[0].at", "must be at least 0, not -1")


def test_labels_are_unique(tmp_path):
    problem = only(tmp_path, """
        version: 1
        steps:
          - play: 1
            label: intro
          - repeat: 2
            steps:
              - play: 2
                label: intro
    """)
    assert (problem.line, problem.column, problem.path) == (8, 16, "steps[1].steps[0].label")
    assert problem.message == "label 'intro' is already used by steps[0] (line 4): labels must be unique"


def test_a_repeat_label_and_its_first_step_label_collide(tmp_path):
    problem = only(tmp_path, """
        version: 1
        steps:
          - repeat: 2
            label: chorus
            steps:
              - play: 2
                label: first
    """)
    assert (problem.line, problem.column, problem.path) == (7, 16, "steps[0].steps[0].label")
    assert "the repeat's label 'chorus' (line 4) would name the same step" in problem.message


def test_expansion_is_bounded(tmp_path):
    started = time.perf_counter()
    problem = only(tmp_path, """
        version: 1
        steps:
          - repeat: 1000
            steps:
              - repeat: 1000
                steps: [{play: 1}]
    """)
    assert time.perf_counter() - started < HANG_S
    assert (problem.line, problem.column, problem.path) == (2, 1, "steps")
    assert problem.message == (f"the show expands to {MAX_PLAN_STEPS + 1:,} steps or more; "
                               f"the limit is {MAX_PLAN_STEPS:,}")


# ------------------------------------------------------------------ reporting


def test_every_problem_is_reported_in_file_order_each_once(tmp_path):
    path = write(tmp_path, """
        version: 1
        motions:
          wave: {number: 4}
        steps:
          - play: 140
          - play: wave
            play: 3
          - wait: -1
          - play: wav
          - bogus: 1
    """)
    with pytest.raises(ShowError) as info:
        load_show(path)
    assert info.value.lines() == [
        f"{path}:5:11: steps[0].play: motion 140 is out of range 0..119",
        f"{path}:7:5: steps[1].play: duplicate key 'play' (first given at line 6): keep one",
        f"{path}:8:11: steps[2].wait: wait takes more than 0 seconds, not -1",
        f"{path}:9:11: steps[3].play: unknown motion 'wav': did you mean 'wave'? the show's motions are wave",
        f"{path}:10:5: steps[4].bogus: unknown key 'bogus': "
        "expected one of at, cue, label, play, repeat, robots, steps, timeout, wait",
    ]
    assert info.value.exit_code == 2


def test_a_bad_node_is_not_reported_twice(tmp_path):
    # out of range (schema) must not also be "unknown motion" or anything else (meaning)
    assert len(problems(tmp_path, "version: 1\nsteps:\n  - play: 200\n  - wait: done\n")) == 1
    # a misspelt key alone: not also "a step needs play, wait or repeat"
    assert len(problems(tmp_path, "version: 1\nsteps:\n  - plya: 1\n")) == 1


def test_the_message_format_is_file_line_column_path_what(tmp_path):
    path = write(tmp_path, "version: 1\nsteps:\n  - play: 140\n")
    with pytest.raises(ShowError) as info:
        load_show(path)
    assert str(info.value) == f"{path}:3:11: steps[0].play: motion 140 is out of range 0..119"


# ------------------------------------------------------------------ the schema


def _subschemas(schema: dict, where: str = "#"):
    """Every schema a field is described by: properties, $defs, propertyNames, anyOf branches."""
    for name, sub in schema.get("properties", {}).items():
        yield f"{where}/properties/{name}", sub
        yield from _subschemas(sub, f"{where}/properties/{name}")
    for name, sub in schema.get("$defs", {}).items():
        yield f"{where}/$defs/{name}", sub
        yield from _subschemas(sub, f"{where}/$defs/{name}")
    if isinstance(schema.get("propertyNames"), dict):
        yield f"{where}/propertyNames", schema["propertyNames"]
    for i, sub in enumerate(schema.get("anyOf", [])):
        if "type" in sub:
            yield f"{where}/anyOf/{i}", sub


def test_the_schema_is_valid_draft_2020_12():
    from jsonschema import Draft202012Validator

    schema = load_schema()
    Draft202012Validator.check_schema(schema)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["$id"] == "https://choreo.dev/schemas/show.schema.json"
    assert schema["properties"]["version"]["const"] == 1


def test_every_field_has_a_title_and_description():
    schema = load_schema()
    assert schema["title"] and schema["description"]
    subs = list(_subschemas(schema))
    assert len(subs) > 20
    for where, sub in subs:
        assert sub.get("title") and sub.get("description"), where


def test_every_object_refuses_unknown_keys():
    schema = load_schema()
    for where, sub in [("#", schema), *_subschemas(schema)]:
        if sub.get("type") == "object" and "properties" in sub:
            assert sub.get("additionalProperties") is False, where


def test_the_shipped_schema_is_the_file_editors_use():
    assert load_schema() == json.loads((ROOT / "schemas" / "show.schema.json").read_text())
    assert not (ROOT / "schemas" / "placeholder.json").exists()


@pytest.mark.parametrize("path", SHOWS, ids=lambda p: p.name)
def test_editors_see_the_examples_as_valid(path):
    """What an editor checks (plain YAML + the schema) agrees with choreo on the examples."""
    from jsonschema import Draft202012Validator

    errors = list(Draft202012Validator(load_schema()).iter_errors(yaml.safe_load(path.read_text())))
    assert errors == []
