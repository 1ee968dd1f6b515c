"""Load a show file into a checked `Show`, or fail with every problem in it, each one located.

Three passes, each reporting everything it finds before the next runs on what survived:

1. Read and parse. The file is read whole (refused over `MAX_BYTES`), decoded as strict UTF-8
   and fed to the YAML *parser* only: we never let PyYAML build Python objects. Instead
   `_Builder` turns the event stream into plain JSON-like data itself, recording the line and
   column of every value and key as it goes. That is what makes messages point at the right
   character, and it is also the safety story: no tag can construct an object, aliases are
   refused outright (so an alias bomb costs nothing), duplicate keys are caught (PyYAML would
   keep the last one silently), and nesting is bounded without recursion.
2. The JSON Schema (`schemas/show.schema.json`, draft 2020-12), the same file editors use, so
   the file and the editor agree. Each jsonschema error is reworded for a show author and
   mapped back to its node.
3. What a schema cannot say: motion names exist, `wait: done` follows a play, cues do not go
   back in time, labels are unique, the show does not expand to an absurd number of steps.

Messages are `FILE:LINE:COL: PATH: WHAT` (`choreo.errors.Problem`); paths are written
`steps[3].play`, list indexes 0-based as in the file's order.
"""

from __future__ import annotations

import os

import json
import math
import re
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

import yaml

from choreo.errors import Problem, ShowError
from choreo.show.nesting import too_deep_at
from choreo.show.model import (
    hidden_character,
    same_port,
    SOLO,
    Tempo,
    DEFAULT_DONE_TIMEOUT_S,
    MOTION_NAME_FORMAT,
    MUSIC_FORMATS,
    Motion,
    Music,
    Repeat,
    RobotSettings,
    Show,
    Step,
    StepKind,
)

# An hour-long show with a step a second is about 50 KiB. The limit bounds the work a file can
# cause: checking costs about 0.1 ms a step, so the largest file answers in a few seconds.
MAX_BYTES = 256 * 1024
GO = "go"  # `at: go`
MAX_DEPTH = 40  # nesting levels of YAML lists and mappings (repeats inside repeats, ...)
MAX_PLAN_STEPS = 100_000  # steps after repeats expand
SCHEMA_FILE = "show.schema.json"

JsonPath = tuple[Union[str, int], ...]
_Mark = tuple[int, int]  # 1-based line and column

_STR = "tag:yaml.org,2002:str"
_INT = "tag:yaml.org,2002:int"
_FLOAT = "tag:yaml.org,2002:float"
_BOOL = "tag:yaml.org,2002:bool"
_NULL = "tag:yaml.org,2002:null"
_TIMESTAMP = "tag:yaml.org,2002:timestamp"
_MAP = "tag:yaml.org,2002:map"
_SEQ = "tag:yaml.org,2002:seq"

# libyaml's parser when available: the pure-Python one is about 20 times slower on big files.
_Parser = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def load_show(path: str | Path) -> Show:
    """The checked show at `path`; `ShowError` listing every problem if it cannot be run."""
    report = _Report(str(path))
    source = _read(Path(path), report)
    if source is None:
        raise ShowError(report.problems())
    return load_show_bytes(source, str(path), folder=Path(path).parent)


def load_show_bytes(source: bytes, path: str = "<show>", folder: Path | None = None) -> Show:
    """A show from its bytes (e.g. attached to a log); `path` names it in messages and records.

    `folder`: where the show file is, so that its music is looked for there (None: a show with
    no folder, as one attached to a log: its music is not looked for)."""
    report = _Report(path)
    if len(source) > MAX_BYTES:
        report.add((0, 0), "", f"the file is over {MAX_BYTES // 1024} KiB, too big for a show file")
        raise ShowError(report.problems())
    text = _decode(source, report)
    doc = _parse(text, report) if text is not None else None
    if doc is None:
        raise ShowError(report.problems())
    _check_schema(doc, report)
    _check_meaning(doc, report, folder)
    if report.any():
        raise ShowError(report.problems())
    return _build_show(path, source, doc, folder)


def load_schema() -> dict[str, Any]:
    """The show format's JSON Schema, as shipped inside the package."""
    return json.loads(schema_path().read_text(encoding="utf-8"))


def schema_path() -> Path:
    """Where the installed show schema is: what an editor's `$schema=` modeline points at."""
    from importlib.resources import files

    return Path(str(files("choreo.schemas") / SCHEMA_FILE)).resolve()


# --------------------------------------------------------------------------- problems


class _Report:
    """Collects problems, dropping a second report of the same path at the same place."""

    def __init__(self, file: str) -> None:
        self.file = file
        self._problems: list[Problem] = []
        self._seen: set[tuple[int, int, str]] = set()
        self.flagged: set[JsonPath] = set()  # paths that already have a problem
        self.silenced: set[JsonPath] = set()  # values replaced by a placeholder: no schema reports below

    def add(self, mark: _Mark, path: JsonPath | str, message: str) -> None:
        text = path if isinstance(path, str) else format_path(path)
        key = (mark[0], mark[1], text)
        if key in self._seen:
            return
        self._seen.add(key)
        if not isinstance(path, str):
            self.flagged.add(path)
        self._problems.append(Problem(self.file, mark[0], mark[1], text, message))

    def any(self) -> bool:
        return bool(self._problems)

    def problems(self) -> list[Problem]:
        """In file order, which is how an author fixes them."""
        return sorted(self._problems, key=lambda p: (p.line, p.column))


def format_path(path: JsonPath) -> str:
    """`('steps', 3, 'play')` as `steps[3].play`; odd keys quoted: `motions["a b"]`."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part.isidentifier():
            out += f".{part}" if out else part
        else:
            out += f"[{json.dumps(part, ensure_ascii=False)}]"
    return out


# --------------------------------------------------------------------------- reading


def _read(path: Path, report: _Report) -> bytes | None:
    from choreo.errors import InputError
    from choreo.userfile import read_input

    try:
        return read_input(path, "show file", MAX_BYTES)
    except InputError as exc:
        report.add((0, 0), "", exc.reason)
        return None


def _decode(data: bytes, report: _Report) -> str | None:
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line_start = data.rfind(b"\n", 0, exc.start) + 1
        line = data.count(b"\n", 0, exc.start) + 1
        column = len(data[line_start : exc.start].decode("utf-8", "replace")) + 1
        report.add((line, column), "", f"not UTF-8 (byte 0x{data[exc.start]:02x}): save the file as UTF-8")
        return None
    return text[1:] if text.startswith("\ufeff") else text


# --------------------------------------------------------------------------- parsing


@dataclass(frozen=True)
class _Where:
    """Where a value sits: its own mark, and its key's mark when it is a mapping value."""

    value: _Mark
    key: _Mark | None = None
    empty: bool = False  # `key:` with nothing after it: point at the key


@dataclass
class _Doc:
    """The parsed file: plain data, and where each path came from."""

    data: Any
    where: dict[JsonPath, _Where]

    def mark(self, path: JsonPath) -> _Mark:
        """The value at `path` (its key if the value is empty), else its nearest ancestor."""
        while path not in self.where and path:
            path = path[:-1]
        where = self.where.get(path)
        if where is None:
            return (1, 1)
        return where.key if where.empty and where.key else where.value

    def key_mark(self, path: JsonPath) -> _Mark:
        where = self.where.get(path)
        if where is not None and where.key is not None:
            return where.key
        return self.mark(path)


class _Stop(Exception):
    """Parsing cannot usefully go on (a second document, nesting too deep)."""


_DISCARD = object()  # the pending key of a mapping entry whose value is thrown away


@dataclass
class _Frame:
    """An open list or mapping while the event stream is walked."""

    container: dict[str, Any] | list[Any] | None  # None: inside something thrown away
    path: JsonPath
    is_key: bool = False  # this collection is itself a mapping key (refused)
    key: Any = None  # mapping: the key waiting for its value (or _DISCARD)
    key_mark: _Mark | None = None
    expect_key: bool = True
    keys: dict[str, _Mark] = field(default_factory=dict)


def _mark_of(event: yaml.Event) -> _Mark:
    return (event.start_mark.line + 1, event.start_mark.column + 1)


class _Builder:
    """Turns YAML events into JSON-like data and a map of marks, refusing what is unsafe."""

    def __init__(self, report: _Report) -> None:
        self.report = report
        self.where: dict[JsonPath, _Where] = {}
        self.stack: list[_Frame] = []
        self.root: Any = None
        self.root_mark: _Mark | None = None
        self.documents = 0
        self.first_alias: tuple[_Mark, JsonPath, str] | None = None
        self.more_aliases = 0
        self.constructor = yaml.constructor.SafeConstructor()

    def feed(self, event: yaml.Event) -> None:
        if isinstance(event, yaml.DocumentStartEvent):
            self.documents += 1
            if self.documents > 1:
                self.report.add(_mark_of(event), "", "a show file holds one YAML document; remove the second `---`")
                raise _Stop
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            self._close()
        elif isinstance(event, (yaml.ScalarEvent, yaml.AliasEvent, yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            self._node(event)

    def _node(self, event: yaml.Event) -> None:
        parent = self.stack[-1] if self.stack else None
        if parent is not None and isinstance(parent.container, dict) and parent.expect_key:
            self._key(parent, event)
            return
        if parent is not None and parent.container is None:
            path, discard = parent.path, True
        elif parent is not None and isinstance(parent.container, dict):
            discard = parent.key is _DISCARD
            path = parent.path + (parent.key,) if not discard else parent.path
        elif parent is not None:
            assert isinstance(parent.container, list)
            path, discard = parent.path + (len(parent.container),), False
        else:
            path, discard = (), False
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            self._open(event, path, discard)
            return
        if discard:
            if parent is not None and isinstance(parent.container, dict):
                parent.expect_key = True
            return
        if isinstance(event, yaml.AliasEvent):
            self._alias(event, path)
            value: Any = None
        else:
            value = self._scalar(event, path)
        self._attach(path, value, _mark_of(event), empty=_is_empty(event))

    def _alias(self, event: yaml.AliasEvent, path: JsonPath) -> None:
        """Refused: reported once at the first, counted after it (a bomb holds thousands)."""
        self.report.silenced.add(path)
        self.report.flagged.add(path)
        if self.first_alias is None:
            self.first_alias = (_mark_of(event), path, event.anchor)
        else:
            self.more_aliases += 1

    def finish(self) -> None:
        """Report what is counted along the way rather than reported one by one."""
        if self.first_alias is not None:
            mark, path, anchor = self.first_alias
            more = f" ({self.more_aliases} more after this one)" if self.more_aliases else ""
            self.report.add(mark, path, f"aliases (*{anchor}) are not allowed in a show file: write the value out{more}")

    def _key(self, parent: _Frame, event: yaml.Event) -> None:
        parent.expect_key = False
        mark = _mark_of(event)
        if not isinstance(event, yaml.ScalarEvent):
            self.report.add(mark, parent.path, "a key must be plain text (no lists, mappings or aliases as keys)")
            parent.key = _DISCARD
            if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                self._push(_Frame(None, parent.path, is_key=True))
            return
        name = _restore_breaks(event.value)
        first = parent.keys.get(name)
        if first is not None:
            self.report.add(mark, parent.path + (name,), f"duplicate key {name!r} (first given at line {first[0]}): keep one")
            parent.key = _DISCARD
            return
        parent.keys[name] = mark
        parent.key, parent.key_mark = name, mark

    def _open(self, event: yaml.Event, path: JsonPath, discard: bool) -> None:
        mark = _mark_of(event)
        is_map = isinstance(event, yaml.MappingStartEvent)
        if discard:
            self._push(_Frame(None, path))
            return
        allowed = (None, "!", _MAP if is_map else _SEQ)
        if event.tag not in allowed:
            self.report.add(mark, path, f"tag {_tag(event.tag)} is not allowed in a show file: remove it")
        if self.root_mark is None:
            self.root_mark = mark
        key_mark = self.stack[-1].key_mark if self.stack and isinstance(self.stack[-1].container, dict) else None
        self.where[path] = _Where(mark, key_mark)
        self._push(_Frame({} if is_map else [], path))

    def _push(self, frame: _Frame) -> None:
        if len(self.stack) >= MAX_DEPTH:
            mark = (1, 1) if not self.stack else self.where.get(self.stack[-1].path, _Where((1, 1))).value
            self.report.add(mark, self.stack[-1].path if self.stack else (), f"nested more than {MAX_DEPTH} levels deep")
            raise _Stop
        self.stack.append(frame)

    def _close(self) -> None:
        frame = self.stack.pop()
        parent = self.stack[-1] if self.stack else None
        if frame.is_key:
            return
        if frame.container is None:
            if parent is not None and isinstance(parent.container, dict):
                parent.expect_key = True
            return
        if parent is None:
            self.root = frame.container
        elif isinstance(parent.container, dict):
            if parent.key is not _DISCARD:
                parent.container[parent.key] = frame.container
            parent.expect_key = True
        elif isinstance(parent.container, list):
            parent.container.append(frame.container)

    def _attach(self, path: JsonPath, value: Any, mark: _Mark, empty: bool) -> None:
        parent = self.stack[-1] if self.stack else None
        if parent is None:
            self.root, self.root_mark = value, mark
            self.where[path] = _Where(mark)
            return
        if isinstance(parent.container, dict):
            self.where[path] = _Where(mark, parent.key_mark, empty)
            parent.container[parent.key] = value
            parent.expect_key = True
        else:
            assert isinstance(parent.container, list)
            self.where[path] = _Where(mark)
            parent.container.append(value)

    def _scalar(self, event: yaml.ScalarEvent, path: JsonPath) -> Any:
        """The scalar's value by YAML's core rules; only plain data tags are accepted."""
        tag = event.tag
        if tag is None and event.implicit[0]:  # plain: YAML 1.2's core schema, as editors read it
            return self._core(event, path)
        if tag in (None, "!"):  # quoted, or the non-specific `!`: a string
            return _restore_breaks(event.value)
        node = yaml.ScalarNode(tag, event.value)
        construct = {
            _STR: self.constructor.construct_yaml_str,
            _INT: self.constructor.construct_yaml_int,
            _FLOAT: self.constructor.construct_yaml_float,
            _BOOL: self.constructor.construct_yaml_bool,
            _NULL: self.constructor.construct_yaml_null,
            _TIMESTAMP: lambda n: n.value,  # a date-like name or label: keep the text as written
        }.get(tag)
        if construct is None:
            self.report.add(_mark_of(event), path, f"tag {_tag(tag)} is not allowed in a show file: remove it")
            return None
        try:
            value = construct(node)
        except (ValueError, KeyError, TypeError, ArithmeticError, yaml.YAMLError):
            shown = event.value if len(event.value) <= 40 else event.value[:40] + "…"
            self.report.add(_mark_of(event), path, f"cannot read {shown!r} as {tag.rsplit(':', 1)[-1]}")
            return None
        if isinstance(value, float) and math.isnan(value):
            self.report.add(_mark_of(event), path, "not-a-number (.nan) is not allowed here")
            return None
        if isinstance(value, int) and abs(value).bit_length() > _NUMBER_BITS_MAX:
            self._too_long_number(event, path)
            return None
        return value

    def _too_long_number(self, event: yaml.ScalarEvent, path: JsonPath) -> None:
        """A whole number far past any value a show holds: Python would not even turn one of more
        than 4,300 digits into text (a ValueError in the middle of a message)."""
        self.report.add(_mark_of(event), path, f"a whole number {len(event.value)} characters long "
                        f"({event.value[:12]}…): no value in a show needs more than {_NUMBER_DIGITS_MAX}")


    def _core(self, event: yaml.ScalarEvent, path: JsonPath) -> Any:
        """A plain scalar by YAML 1.2's core schema; a whole number with a leading zero is refused.

        PyYAML reads YAML 1.1, where `010` is 8 (octal), `1:30` is 90 (base 60) and `yes` is
        true, while editors and the YAML 1.2 language server read 10, text and text: the same
        file would mean two things. A wrong slot is the worst error a show runner can make.
        """
        text = event.value
        if len(text) > _NUMBER_DIGITS_MAX and _WHOLE_NUMBER.fullmatch(text):
            self._too_long_number(event, path)
            return None
        if _LEADING_ZERO.fullmatch(text):
            digits = text.lstrip("+-")
            sign = "-" if text.startswith("-") else ""
            self.report.add(_mark_of(event), path,
                            f"{text} is ambiguous: YAML 1.1 reads a leading zero as octal "
                            f"({sign}{int(digits, 8) if set(digits) <= set('01234567') else 'not octal'}), "
                            f"YAML 1.2 as decimal ({sign}{int(digits, 10)}): write it without the leading zero")
            return None
        value = _core_value(text)
        if isinstance(value, float) and math.isnan(value):
            self.report.add(_mark_of(event), path, "not-a-number (.nan) is not allowed here")
            return None
        return _restore_breaks(value) if isinstance(value, str) else value


# YAML 1.2 core schema (https://yaml.org/spec/1.2.2/#1032-tag-resolution).
_CORE_NULL = re.compile(r"~|null|Null|NULL|")
_CORE_TRUE = re.compile(r"true|True|TRUE")
_CORE_FALSE = re.compile(r"false|False|FALSE")
_CORE_INT = re.compile(r"[-+]?[0-9]+")
_CORE_OCT = re.compile(r"0o[0-7]+")
_CORE_HEX = re.compile(r"0x[0-9a-fA-F]+")
_CORE_FLOAT = re.compile(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?")
_CORE_INF = re.compile(r"[-+]?\.(inf|Inf|INF)")
_CORE_NAN = re.compile(r"\.(nan|NaN|NAN)")
_LEADING_ZERO = re.compile(r"[-+]?0[0-9]+")
_WHOLE_NUMBER = re.compile(r"[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+")
_NUMBER_DIGITS_MAX = 30  # characters of a whole number; a show's largest values have 6
_NUMBER_BITS_MAX = 100  # and its value (a tagged `!!int` is converted by PyYAML, not here)


def _core_value(text: str) -> Any:
    if _CORE_NULL.fullmatch(text):
        return None
    if _CORE_TRUE.fullmatch(text) or _CORE_FALSE.fullmatch(text):
        return text.lower() == "true"
    if _CORE_INT.fullmatch(text):
        return int(text, 10)
    if _CORE_OCT.fullmatch(text):
        return int(text[2:], 8)
    if _CORE_HEX.fullmatch(text):
        return int(text[2:], 16)
    if _CORE_FLOAT.fullmatch(text):
        return float(text)
    if _CORE_INF.fullmatch(text):
        return -math.inf if text.startswith("-") else math.inf
    if _CORE_NAN.fullmatch(text):
        return math.nan
    return text


# YAML 1.2 has two line breaks, LF and CR; PyYAML (YAML 1.1) also breaks lines at NEL, LS and PS,
# which shifts every line number after one (editors do not count them) and ends a comment in the
# middle. They are parsed as stand-ins from Unicode's private use area and put back in text.
_BREAKS_1_1 = {"\x85": "\ue085", "\u2028": "\ue028", "\u2029": "\ue029"}
_HIDE_BREAKS = str.maketrans(_BREAKS_1_1)
_SHOW_BREAKS = str.maketrans({v: k for k, v in _BREAKS_1_1.items()})


def _restore_breaks(text: str) -> str:
    return text.translate(_SHOW_BREAKS)


def _tag(tag: str) -> str:
    """A tag as it is written in YAML: `!!python/object`, not `tag:yaml.org,2002:python/object`."""
    return "!!" + tag[len("tag:yaml.org,2002:"):] if tag.startswith("tag:yaml.org,2002:") else tag


def _is_empty(event: yaml.Event) -> bool:
    return isinstance(event, yaml.ScalarEvent) and event.value == "" and event.implicit[0] and event.tag is None


def _mark_at(text: str, index: int) -> _Mark:
    """The 1-based line and column of a character of the text."""
    return text.count("\n", 0, index) + 1, index - (text.rfind("\n", 0, index) + 1) + 1


def _too_deep(text: str, report: _Report) -> bool:
    """True (and the depth reported in choreo's words) if the text nests past `MAX_DEPTH`.

    The parser's scanner reads ahead of its events and has nesting limits of its own that vary
    between PyYAML releases; handing it only the text before the first bracket past the limit
    (found by `nesting.too_deep_at`) keeps its limits out of reach, and the event walk then
    places the problem exactly. Shows rarely hold that many brackets, so most skip the scan.
    """
    if text.count("[") + text.count("{") <= MAX_DEPTH:
        return False
    deep = too_deep_at(text, MAX_DEPTH)
    if deep is None:
        return False
    prefix = text[:deep.index + 1]
    found = _walk_prefix(prefix, report)
    if found is _TOO_DEEP:
        return True
    if isinstance(found, yaml.MarkedYAMLError) and found.problem_mark is not None \
            and found.problem_mark.index in (deep.outermost, len(prefix)):
        # The walk saw no events of the deep collection (a key at its mapping's column is
        # withheld until its `:`), and the parser's only complaint is the collection itself
        # (at its start, or where it was cut), not something inside it: the brackets are
        # nesting, whatever the parser would say of the whole (libyaml 0.2.5: its depth limit;
        # PyYAML 6.0: a key over 1,024 characters).
        report.add(_mark_at(text, deep.index), "", f"nested more than {MAX_DEPTH} levels deep")
        return True
    return False


_TOO_DEEP = "too deep"


def _walk_prefix(prefix: str, report: _Report) -> yaml.YAMLError | str | None:
    """Walk the events of the text's first part: `_TOO_DEEP` (reported) if it nests past the
    limit, else the parser's error on it (None if it parses); other problems are not reported."""
    scratch = _Report(report.file)
    builder = _Builder(scratch)
    try:
        for event in yaml.parse(prefix, Loader=_Parser):
            builder.feed(event)
    except _Stop:
        for problem in scratch.problems():
            report.add((problem.line, problem.column), problem.path, problem.message)
        return _TOO_DEEP
    except yaml.YAMLError as exc:
        return exc
    return None


def _earlier_problem(text: str, exc: yaml.MarkedYAMLError, report: _Report) -> bool:
    """True (and it reported) if the text before the parser's error holds a problem of its own.

    The scanner reads ahead of the events: its own limits (libyaml's nesting depth) can stop it
    past a depth choreo's walk would have stopped at, or past a syntax error its parser had not
    yet reached. The pre-scan of `_too_deep` is a reading of YAML, not YAML, so this is the
    guard that holds whatever it missed: the text before the error, walked again, tells.
    """
    mark = exc.problem_mark
    if mark is None or mark.index <= 0:
        return False
    prefix = text[:mark.index]
    for _ in range(2):  # the token the parser stopped on may end at its mark: then without it
        found = _walk_prefix(prefix, report)
        if found is _TOO_DEEP:
            return True
        earlier = found.problem_mark if isinstance(found, yaml.MarkedYAMLError) else None
        if earlier is not None and prefix[earlier.index:].strip():
            _report_syntax(found, report)
            return True
        prefix = prefix.rstrip()[:-1]  # an error at the prefix's end is its cut, not the file's
    return False


def _report_syntax(exc: yaml.MarkedYAMLError, report: _Report) -> None:
    """The parser's error located; its own nesting limit (reached where the walk could not judge
    the text before it: a key the scanner had not resolved) is said in choreo's words."""
    mark = exc.problem_mark or exc.context_mark
    where = (mark.line + 1, mark.column + 1) if mark else (0, 0)
    what = exc.problem or "syntax error"
    if "nesting" in what:
        report.add(where, "", f"nested more than {MAX_DEPTH} levels deep")
        return
    context = f" ({exc.context})" if exc.context else ""
    report.add(where, "", f"YAML syntax error: {what}{context}")


def _parse(text: str, report: _Report) -> _Doc | None:
    """The document as data with marks; None (and problems reported) if there is none to check."""
    builder = _Builder(report)
    stand_in = next((ch for ch in _BREAKS_1_1.values() if ch in text), None)
    if stand_in is not None:
        report.add(_mark_at(text, text.index(stand_in)), "",
                   f"character U+{ord(stand_in):04X} (private use) is not allowed in a show file")
        return None
    text = text.translate(_HIDE_BREAKS)
    if _too_deep(text, report):
        return None
    try:
        try:
            for event in yaml.parse(text, Loader=_Parser):
                builder.feed(event)
        finally:
            builder.finish()
    except _Stop:
        return None
    except yaml.MarkedYAMLError as exc:
        if not _earlier_problem(text, exc, report):
            _report_syntax(exc, report)
        return None
    except yaml.YAMLError as exc:  # the reader: a character YAML does not allow
        character = getattr(exc, "character", None)
        what = f"character {character!r}" if isinstance(character, str) else "a character"
        report.add(_mark_at(text, getattr(exc, "position", 0) or 0), "", f"{what} is not allowed in a YAML file")
        return None
    if builder.documents == 0 or builder.root is None:
        report.add((1, 1), "", "the file holds no show: start with `version: 1` and `steps:`")
        return None
    if not isinstance(builder.root, dict):
        report.add(builder.root_mark or (1, 1), "", f"the top level must be a mapping (`version: 1`, `steps:` ...), not {_kind(builder.root)}")
        return None
    # Aliases, tags and duplicate keys reported so far do not stop the checks: the rest of the
    # file is still checked, and a second report at the same node is dropped by `_Report`.
    return _Doc(builder.root, builder.where)


# --------------------------------------------------------------------------- schema

_validator_cache: Any = None


def _validator() -> Any:
    """The schema's validator, built once: jsonschema is imported only when a show is checked."""
    global _validator_cache
    if _validator_cache is None:
        from jsonschema import Draft202012Validator, FormatChecker

        from choreo.show.model import is_motion_name

        # Only our own format: a name's letters are Unicode categories, which the schema's
        # pattern cannot say portably (editors run it as an ECMAScript regex).
        formats = FormatChecker(formats=())
        formats.checks(MOTION_NAME_FORMAT)(is_motion_name)
        _validator_cache = Draft202012Validator(load_schema(), format_checker=formats)
    return _validator_cache


def _check_schema(doc: _Doc, report: _Report) -> None:
    errors = list(_validator().iter_errors(doc.data))
    # A wrong type explains everything else wrong at the same node: report it first.
    errors.sort(key=lambda e: (e.validator != "type", len(e.absolute_path)))
    for error in errors:
        for path, message, on_key in _explain(error, doc.data):
            if not on_key and any(path[:n] in report.silenced for n in range(len(path) + 1)):
                continue
            mark = doc.key_mark(path) if on_key else doc.mark(path)
            report.add(mark, path, message)


_TYPE_WORDS = {
    "object": "a mapping (`key: value` lines)",
    "array": "a list (`- item` lines)",
    "string": "text",
    "integer": "a whole number",
    "number": "a number",
    "boolean": "true or false",
}

_STEP_KINDS = ("play", "wait", "repeat")
_STEP_KEYS = frozenset(("play", "wait", "timeout", "repeat", "steps", "at", "label", "robots"))

_REQUIRED = {
    "version": "missing: add `version: 1` (the show format's version)",
    "steps": "missing: a show needs `steps:`, the list of what it does (or, with `robots:`, `tracks:`)",
    "number": "missing: give the motion's slot, e.g. `number: 3`",
}


def _explain(error: Any, data: Any) -> list[tuple[JsonPath, str, bool]]:
    """One jsonschema error as (path, message, point at the key?) in a show author's words."""
    path: JsonPath = tuple(error.absolute_path)
    schema_path = list(error.absolute_schema_path)
    validator, instance, expected = error.validator, error.instance, error.validator_value
    if "dependentSchemas" in schema_path:
        trigger = schema_path[schema_path.index("dependentSchemas") + 1]
        step = path[:-1] if path and not isinstance(path[-1], int) else path
        if trigger == "timeout":
            return [(step + ("timeout",), "`timeout` goes with `wait: done` only", True)]
        here = _value_at(data, step)
        return [(step, _step_kind_problem(here if isinstance(here, dict) else {}), False)]
    if not path and validator in ("oneOf", "not") or validator == "dependentRequired" and not path:
        return [_whole_show_problem(validator, instance)]
    if validator == "type" and len(path) == 2 and path[0] == "robots" and not isinstance(instance, dict):
        return [(path, f"robot {path[1]!r}: expected its settings as a mapping (`port: ...`, or `{{}}` for "
                       f"none), not {_kind(instance)}; a show for one robot says `robot:`", False)]
    if "propertyNames" in schema_path and schema_path[1:2] in (["robots"], ["tracks"]):
        return [(path + (str(instance),), f"robot name {instance!r} must start with a letter and hold only "
                                          "letters, digits, `_` and `-` (at most 32 characters)", True)]
    if "propertyNames" in schema_path:
        if validator == "maxLength":
            return [(path + (instance,), f"motion name is longer than {expected} characters", True)]
        return [(path + (str(instance),), f"motion name {instance!r} must start with a letter or `_` and hold only letters, digits, `_` and `-`", True)]
    if validator == "additionalProperties" and expected is False and isinstance(instance, dict):
        allowed = sorted(error.schema.get("properties", {}))
        extra = [key for key in instance if key not in allowed]
        return [(path + (key,), _unknown_key(key, allowed), True) for key in extra]
    if validator == "required" and isinstance(instance, dict):
        return [(path + (key,), _REQUIRED.get(key, f"missing: `{key}` is required"), False) for key in expected if key not in instance]
    if validator == "anyOf" and isinstance(instance, dict) and path and isinstance(path[-1], int):
        if not any(k in instance for k in _STEP_KINDS) and ("steps" in instance or any(k not in _STEP_KEYS for k in instance)):
            return []  # `plya: 3`, or `steps:` alone: the unknown-key or `repeat` report says it better
        return [(path, _step_kind_problem(instance), False)]
    if validator == "dependentRequired" and isinstance(instance, dict):
        if "steps" in instance and "repeat" not in instance:
            return [(path + ("steps",), "nested `steps:` need `repeat: N` beside them", True)]
        return [(path + ("repeat",), "`repeat` needs the `steps:` to repeat", True)]
    if validator == "anyOf" and path and path[-1] == "at":
        return [_cue_problem(path, instance, error.context)]
    if validator == "anyOf":
        return [(path, _either_problem(path, instance, error.context), False)]
    return [(path, _simple_problem(path, validator, instance, expected), False)]


def _cue_problem(path: JsonPath, instance: Any, context: list[Any]) -> tuple[JsonPath, str, bool]:
    """`at:` is seconds or `{bar: N, beat: B}`: say what is wrong with the form it was given in."""
    if isinstance(instance, dict):
        for e in context:
            inner = tuple(e.absolute_path)[len(path):]
            if e.validator == "additionalProperties":
                extra = next(key for key in instance if key not in ("bar", "beat"))
                return path + (extra,), _unknown_key(extra, ["bar", "beat"]), True
            if e.validator == "required":
                return path, "a cue in bars and beats needs its `bar:` (from 1), e.g. `{bar: 12, beat: 3}`", False
            if inner and e.validator != "type":
                return path + inner, _simple_problem(path + inner, e.validator, e.instance, e.validator_value), False
            if inner:
                return path + inner, f"expected a number, not {_kind(e.instance)}", False
    for e in context:
        if e.validator not in ("type", "$ref") and not tuple(e.absolute_path)[len(path):]:
            return path, _simple_problem(path, e.validator, e.instance, e.validator_value), False
    return path, f"expected seconds (a number) or a bar and beat (`{{bar: 12, beat: 3}}`), not {_kind(instance)}", False


def _whole_show_problem(validator: str, show: Any) -> tuple[JsonPath, str, bool]:
    """What the show as a whole lacks or has twice: its steps, its robots."""
    if validator == "not":
        return (("robots",), "a show has `robot:` (one robot) or `robots:` (several, by name), not both", True)
    if validator == "dependentRequired":
        return (("tracks",), "`tracks:` are per robot: name the robots in `robots:` first", True)
    if isinstance(show, dict) and "steps" in show and "tracks" in show:
        return (("tracks",), "a show has `steps:` (every robot together) or `tracks:` (one list per robot), "
                             "not both", True)
    return (("steps",), _REQUIRED["steps"], False)


def _value_at(data: Any, path: JsonPath) -> Any:
    for part in path:
        data = data[part]
    return data


def _unknown_key(key: str, allowed: list[str]) -> str:
    import difflib

    close = difflib.get_close_matches(key, allowed, n=1)
    hint = f"did you mean `{close[0]}`? " if close else ""
    return f"unknown key {key!r}: {hint}expected one of {', '.join(allowed)}"


def _step_kind_problem(step: dict[str, Any]) -> str:
    kinds = [key for key in _STEP_KINDS if key in step]
    if not kinds:
        return "a step needs one of `play`, `wait` or `repeat`"
    named = [f"`{k}`" for k in kinds]
    listed = named[0] if len(named) == 1 else ", ".join(named[:-1]) + " and " + named[-1]
    return f"a step does one thing, this one has {listed}: make them separate steps"


def _either_problem(path: JsonPath, instance: Any, context: list[Any]) -> str:
    """`play`/`on_abort` (number or name) and `wait` (seconds or `done`)."""
    leaf = path[-1] if path else ""
    near = [e for e in context if e.validator != "type"]
    if leaf == "wait":
        for e in near:
            if e.validator in ("exclusiveMinimum", "minimum"):
                return f"wait takes more than 0 seconds, not {_value(instance)}"
            if e.validator in ("maximum", "exclusiveMaximum"):
                return f"wait takes at most {_value(e.validator_value)} seconds (a day), not {_value(instance)}"
        return f"wait takes seconds (a number > 0) or `done`, not {_value(instance)}"
    for e in near:
        if e.validator in ("minimum", "maximum"):
            return f"motion {_value(instance)} is out of range 0..119"
        if e.validator == "minLength":
            return "the motion name is empty"
    return f"expected a motion number 0..119 or a name from `motions:`, not {_kind(instance)}{_quote_hint(instance)}"


_ROBOT_LISTS = {
    "minProperties": "is empty: name at least one robot",
    "maxProperties": "names more than {expected} robots: at most {expected} in one show",
    "uniqueItems": "names a robot twice: list each once",
    "minItems": "is empty: name at least one robot (or leave it out: every robot)",
}


def _simple_problem(path: JsonPath, validator: str, instance: Any, expected: Any) -> str:
    leaf = path[-1] if path else ""
    if path and path[0] in ("robots", "tracks") and len(path) == 1 and validator in _ROBOT_LISTS:
        return f"`{path[0]}:` {_ROBOT_LISTS[validator].format(expected=expected)}"
    if "robots" in path[-2:] and validator in _ROBOT_LISTS:
        return f"a step's `robots:` {_ROBOT_LISTS[validator].format(expected=expected)}"
    if validator == "pattern" and len(path) >= 2 and path[-2] == "robots" and isinstance(path[-1], int):
        return (f"robot name {instance!r} must start with a letter and hold only letters, digits, `_` and `-` "
                "(at most 32 characters)")
    if validator == "type":
        want = expected if isinstance(expected, list) else [expected]
        words = " or ".join(_TYPE_WORDS.get(t, t) for t in want)
        return f"expected {words}, not {_kind(instance)}{_quote_hint(instance) if 'string' in want else ''}"
    if validator == "const" and leaf == "version":
        return f"unsupported format version {_value(instance)}: this choreo reads `version: 1`"
    if validator == "enum" and leaf == "baud":
        return f"baud {_value(instance)} is not one the RCB-4 speaks: 115200, 625000 or 1250000"
    if validator == "enum" and leaf == "layout":
        known = " or ".join(f"`{name}`" for name in expected)
        return f"unknown layout {_value(instance)}: choreo knows {known} (`choreo import` reads a board's layout from its Heart to Heart 4 project)"
    if leaf == "number" and validator in ("minimum", "maximum"):
        return f"motion {_value(instance)} is out of range 0..119"
    if validator == "minimum":
        return f"must be at least {_value(expected)}, not {_value(instance)}"
    if validator == "exclusiveMinimum":
        return f"must be more than {_value(expected)}, not {_value(instance)}"
    if validator in ("maximum", "exclusiveMaximum"):
        return f"must be at most {_value(expected)}, not {_value(instance)}"
    if validator == "minItems":
        return "must not be empty: list at least one step"
    if validator == "minLength":
        return "must not be empty"
    if validator == "maxLength":
        return f"is longer than {expected} characters"
    if validator == "pattern" and leaf == "label":
        return f"label {instance!r} must not be only digits (those name steps by index) nor hold `#` or control characters"
    if validator == "const":
        return f"must be {_value(expected)}, not {_value(instance)}"
    if validator == "enum":
        return f"must be one of {', '.join(_value(v) for v in expected)}, not {_value(instance)}"
    return f"{validator}: not allowed here ({_kind(instance)})"


def _value(value: Any) -> str:
    """A value as the author would write it in YAML."""
    if value is None:
        return "nothing"
    if value is True or value is False:
        return "true" if value else "false"
    if isinstance(value, float) and math.isinf(value):
        return ".inf" if value > 0 else "-.inf"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return repr(value)
    return _kind(value)


def _kind(value: Any) -> str:
    """What a value is, for `expected X, not Y`."""
    if value is None:
        return "an empty value"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return f"the number {_value(value)}"
    if isinstance(value, str):
        return f"the text {value!r}"
    if isinstance(value, list):
        return "a list"
    return "a mapping"


def _quote_hint(value: Any) -> str:
    """YAML reads `yes`, `off`, `null` as true/false/nothing: say how to mean the word."""
    if value is None or isinstance(value, bool):
        return " (put the word in quotes to mean text)"
    return ""


# --------------------------------------------------------------------------- meaning


@dataclass
class _Walk:
    """What the semantic pass carries along the steps, in run order."""

    doc: _Doc
    report: _Report
    motions: dict[str, Any]  # name -> entry, the well-formed ones
    labels: dict[str, JsonPath] = field(default_factory=dict)
    last_cue: tuple[float, JsonPath] | None = None
    played: set[str] = field(default_factory=set)  # robots that have played a motion so far
    robots: tuple[str, ...] = (SOLO,)  # the robots of the step list being walked
    declared: tuple[str, ...] = ()  # `robots:` (empty for a one-robot show)
    in_track: bool = False

    def ok(self, path: JsonPath) -> bool:
        """Whether the value at `path` passed the schema (so it is the type it should be)."""
        return all(path[:n] not in self.report.flagged for n in range(len(path) + 1))


def _check_meaning(doc: _Doc, report: _Report, folder: Path | None = None) -> None:
    data = doc.data
    motions = data.get("motions") if isinstance(data.get("motions"), dict) else {}
    walk = _Walk(doc, report, {})
    walk.motions = {name: entry for name, entry in motions.items() if isinstance(entry, dict) and walk.ok(("motions", name))}
    _check_motion_table(walk)
    if isinstance(data.get("name"), str) and walk.ok(("name",)):
        _check_visible(walk, ("name",), data["name"], "the show's name")
    if "on_abort" in data and walk.ok(("on_abort",)):
        _check_motion_ref(walk, ("on_abort",), data["on_abort"])
    _check_robots(walk)
    _check_music(walk, folder)
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
        walk.report.add(walk.doc.mark(path), path, f"{file}: choreo plays {', '.join(f[1:] for f in MUSIC_FORMATS)} "
                        "files: convert it, or give one of those")
    elif folder is not None:
        from choreo.userfile import problem

        where = folder / file
        what = problem(where, "sound file")
        if what is not None:
            walk.report.add(walk.doc.mark(path), path, f"{file}: {what} ({where}; the path is relative to the show file)")


def _check_total(walk: _Walk, path: JsonPath, total: int) -> None:
    if total > MAX_PLAN_STEPS:
        walk.report.add(walk.doc.key_mark(path), path,
                        f"the show expands to {total:,} steps or more; the limit is {MAX_PLAN_STEPS:,}")


def _check_robots(walk: _Walk) -> None:
    """Each robot's abort motion is a motion; no two robots share a port; `on_fault` is for
    a robot among several."""
    data = walk.doc.data
    robot = data.get("robot")
    if isinstance(robot, dict) and "on_fault" in robot and walk.ok(("robot", "on_fault")):
        walk.report.add(walk.doc.key_mark(("robot", "on_fault")), ("robot", "on_fault"),
                        "`on_fault` decides what the other robots do: it is for a robot in `robots:`")
    if isinstance(robot, dict) and "on_abort" in robot and walk.ok(("robot", "on_abort")):
        _check_motion_ref(walk, ("robot", "on_abort"), robot["on_abort"])
    robots = data.get("robots")
    if not isinstance(robots, dict) or not walk.ok(("robots",)):
        return
    walk.declared = tuple(robots)
    ports: dict[str, str] = {}
    for name, settings in robots.items():
        here = ("robots", name)
        if not isinstance(settings, dict) or not walk.ok(here):
            continue
        if "on_abort" in settings and walk.ok(here + ("on_abort",)):
            _check_motion_ref(walk, here + ("on_abort",), settings["on_abort"])
        port = settings.get("port")
        if not isinstance(port, str) or port.strip().lower().startswith("sim://"):
            continue  # every simulator is a board of its own
        first = ports.setdefault(same_port(port), name)
        if first != name:
            walk.report.add(walk.doc.mark(here + ("port",)), here + ("port",),
                            f"port {port} is already robot {first}'s: each robot needs its own port")


def _check_tracks(walk: _Walk, tracks: dict[str, Any]) -> None:
    """A track for each declared robot and for no other; each track is walked as a show of
    its own (cues in order, `wait: done` after a play), labels unique across them all."""
    total = 0
    for name, steps in tracks.items():
        here = ("tracks", name)
        if name not in walk.declared:
            walk.report.add(walk.doc.key_mark(here), here, _unknown_robot(name, walk.declared, "a track for"))
            continue
        if not isinstance(steps, list) or not walk.ok(here):
            continue
        walk.robots, walk.in_track, walk.last_cue, walk.played = (name,), True, None, set()
        total += _check_steps(walk, steps, here, looping=False)
    missing = [name for name in walk.declared if name not in tracks]
    if missing:
        walk.report.add(walk.doc.key_mark(("tracks",)), ("tracks",),
                        f"robot {missing[0]!r} has no track: give it one (a robot that stands still "
                        "can `wait:` for the show's length), or leave it out of `robots:`")
    _check_total(walk, ("tracks",), total)


def _unknown_robot(name: str, declared: tuple[str, ...], what: str) -> str:
    import difflib

    close = difflib.get_close_matches(name, declared, n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return f"{what} robot {name!r}, which `robots:` does not name: {hint}the robots are {', '.join(declared)}"


def _step_robots(walk: _Walk, step: dict[str, Any], here: JsonPath) -> tuple[str, ...]:
    """The robots a step is for, after checking its `robots:`; unknown names are reported."""
    given = step.get("robots")
    path = here + ("robots",)
    if given is None or not walk.ok(path):
        return walk.robots
    if not walk.declared:
        walk.report.add(walk.doc.key_mark(path), path, "a step's `robots:` picks among the show's "
                        "`robots:`; this show has one robot (`robot:`)")
        return walk.robots
    if walk.in_track:
        walk.report.add(walk.doc.key_mark(path), path, "a step in a track is that robot's own: "
                        "leave out `robots:` (or write the step in the shared `steps:`)")
        return walk.robots
    known = [name for name in given if isinstance(name, str) and name in walk.robots]
    for index, name in enumerate(given):
        if not isinstance(name, str):
            continue  # the schema has said what is wrong with it
        if name not in walk.declared:
            walk.report.add(walk.doc.mark(path + (index,)), path + (index,), _unknown_robot(name, walk.declared, "a step for"))
        elif name not in walk.robots:
            walk.report.add(walk.doc.mark(path + (index,)), path + (index,),
                            f"robot {name!r} is not among the repeat's robots ({', '.join(walk.robots)})")
    return tuple(known) or walk.robots


def _check_motion_table(walk: _Walk) -> None:
    """Two names for one slot are fine; two different durations for it are a contradiction."""
    durations: dict[int, tuple[float, str]] = {}
    for name, entry in walk.motions.items():
        hth4 = ("motions", name, "hth4_name")
        if isinstance(entry.get("hth4_name"), str) and walk.ok(hth4):
            _check_visible(walk, hth4, entry["hth4_name"], "the Heart to Heart 4 name")
        path = ("motions", name, "duration")
        number, duration = entry.get("number"), entry.get("duration")
        if not (walk.ok(path) and walk.ok(("motions", name, "number"))) or duration is None or not isinstance(number, (int, float)):
            continue
        first = durations.setdefault(int(number), (duration, name))
        if first[0] != duration:
            walk.report.add(walk.doc.mark(path), path, f"motion {int(number)} is also {first[1]!r} with duration {_value(first[0])}: give one duration")


def _check_motion_ref(walk: _Walk, path: JsonPath, ref: Any) -> None:
    if isinstance(ref, str) and ref not in walk.motions:
        walk.report.add(walk.doc.mark(path), path, _unknown_motion(ref, sorted(walk.motions)))


def _unknown_motion(name: str, known: list[str]) -> str:
    if not known:
        return f"unknown motion {name!r}: name it in `motions:` with its slot number, or play the number"
    import difflib

    close = difflib.get_close_matches(name, known, n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return f"unknown motion {name!r}: {hint}the show's motions are {', '.join(known)}"


def _check_steps(walk: _Walk, steps: list[Any], path: JsonPath, looping: bool) -> int:
    """Check a list of steps in run order; the number of plan steps it expands to."""
    total = 0
    for index, step in enumerate(steps):
        here = path + (index,)
        if not isinstance(step, dict) or not walk.ok(here):
            total += 1
            continue
        _check_cue(walk, step, here, looping)
        _check_label(walk, step, here)
        robots = _step_robots(walk, step, here)
        if "play" in step:
            if walk.ok(here + ("play",)):
                _check_motion_ref(walk, here + ("play",), step["play"])
            walk.played.update(robots)
            total += 1
        elif step.get("wait") == "done" and not walk.played.issuperset(robots):
            idle = [name for name in robots if name not in walk.played]
            whose = f" (robot {idle[0]!r} has played nothing yet)" if walk.declared and not walk.in_track else ""
            walk.report.add(walk.doc.mark(here + ("wait",)), here + ("wait",),
                            f"`wait: done` has no motion to wait for{whose}: play one before it")
            total += 1
        elif "repeat" in step and isinstance(step.get("steps"), list) and walk.ok(here + ("steps",)):
            repeat = step["repeat"]
            count = int(repeat) if walk.ok(here + ("repeat",)) and isinstance(repeat, (int, float)) else 1
            _check_repeat_label(walk, step, here)
            outer, walk.robots = walk.robots, robots
            inner = _check_steps(walk, step["steps"], here + ("steps",), looping or count > 1)
            walk.robots = outer
            total += min(count * inner, MAX_PLAN_STEPS + 1)
        else:
            total += 1
        total = min(total, MAX_PLAN_STEPS + 1)
    return total


def _check_cue(walk: _Walk, step: dict[str, Any], here: JsonPath, looping: bool) -> None:
    at = step.get("at")
    path = here + ("at",)
    if at is None or not walk.ok(path) or isinstance(at, bool) or at == GO:
        return  # a GO cue may be anywhere: in a repeat, every pass waits for its GO
    mark = walk.doc.mark(path)
    if isinstance(at, dict):
        at = _beat_seconds(walk, at, path)
        if at is None:
            return
    if looping:
        walk.report.add(mark, path, "a cue inside a repeat would be late on every pass after the first: put `at:` on the repeat step")
        return
    if walk.last_cue is not None and at < walk.last_cue[0]:
        prev, prev_path = walk.last_cue
        line = walk.doc.mark(prev_path)[0]
        walk.report.add(mark, path, f"cue at {at:g} s comes after the cue at {prev:g} s ({format_path(prev_path)}, line {line}): cues must not go back in time")
        return
    walk.last_cue = (at, path)


def _beat_seconds(walk: _Walk, at: dict[str, Any], path: JsonPath) -> float | None:
    """A bar-and-beat cue in seconds; None (reported) without a usable tempo or past the bar."""
    tempo = walk.doc.data.get("tempo")
    if not isinstance(tempo, dict) or not walk.ok(("tempo",)):
        if not isinstance(tempo, dict):
            walk.report.add(walk.doc.mark(path), path, "a cue in bars and beats needs the music's `tempo:` "
                            "(e.g. `tempo: {bpm: 120, offset: 0.5, meter: 4}`), or give seconds")
        return None
    bar, beat = at.get("bar"), at.get("beat", 1)
    fields_ok = all(walk.ok(("tempo", key)) for key in tempo) and all(walk.ok(path + (key,)) for key in at)
    if not fields_ok or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (bar, beat)):
        return None  # the schema has said what is wrong with them
    built = _tempo(tempo)
    beat = float(beat)
    if beat >= built.meter + 1:  # type: ignore[union-attr]
        walk.report.add(walk.doc.mark(path + ("beat",)), path + ("beat",),
                        f"beat {_value(at.get('beat'))}: a bar has {built.meter} beats (tempo.meter), "  # type: ignore[union-attr]
                        f"so beats run from 1 to below {built.meter + 1}")  # type: ignore[union-attr]
        return None
    return built.seconds(int(bar), beat)  # type: ignore[union-attr, arg-type]


def _check_visible(walk: _Walk, path: JsonPath, text: str, what: str) -> bool:
    """Text that choreo prints (names, labels) holds no control or invisible characters: they
    would reach terminals and logs raw (an escape sequence, a right-to-left override)."""
    hidden = hidden_character(text)
    if hidden is None:
        return True
    name = unicodedata.name(hidden, "a control character")
    walk.report.add(walk.doc.mark(path), path, f"{what} holds U+{ord(hidden):04X} ({name}), which is "
                                               "invisible or controls the terminal: remove it")
    return False


def _check_label(walk: _Walk, step: dict[str, Any], here: JsonPath) -> None:
    label = step.get("label")
    path = here + ("label",)
    if not isinstance(label, str) or not walk.ok(path) or not _check_visible(walk, path, label, "the label"):
        return
    first = walk.labels.get(label)
    if first is not None:
        line = walk.doc.mark(first)[0]
        walk.report.add(walk.doc.mark(path), path, f"label {label!r} is already used by {format_path(first[:-1])} (line {line}): labels must be unique")
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
            where = path + ("label",)
            line = walk.doc.mark(here + ("label",))[0]
            walk.report.add(walk.doc.mark(where), where, f"this label and the repeat's label {step['label']!r} (line {line}) would name the same step: keep one")
            return
        if "repeat" not in inner:
            return


# --------------------------------------------------------------------------- records


def _build_show(file: str, source: bytes, doc: _Doc, folder: Path | None = None) -> Show:
    """The records from data that passed every check (so types are what the schema says)."""
    data = doc.data
    motions = {
        name: Motion(name, int(entry["number"]), _seconds(entry.get("duration")))
        for name, entry in (data.get("motions") or {}).items()
    }
    robots = {name: _robot(entry or {}, motions) for name, entry in (data.get("robots") or {}).items()}
    robot = _robot(data.get("robot") or {}, motions) if not robots else next(iter(robots.values()))
    abort = data.get("on_abort")
    tempo = _tempo(data.get("tempo"))
    tracks = {name: _build_steps(steps, ("tracks", name), doc, motions, tempo)
              for name, steps in (data.get("tracks") or {}).items()}
    return Show(
        path=file,
        name=data.get("name") or Path(file).stem,
        source=source,
        robot=robot,
        motions=motions,
        on_abort=None if abort is None else _motion_number(abort, motions),
        steps=_build_steps(data["steps"], ("steps",), doc, motions, tempo) if "steps" in data else (),
        robots=robots,
        tracks=tracks,
        tempo=tempo,
        music=_music(data.get("music"), folder),
    )


def _music(entry: dict[str, Any] | None, folder: Path | None) -> Music | None:
    if not entry:
        return None
    return Music(entry["file"], float(entry.get("start", 0.0)), str(folder) if folder is not None else ".")


def _tempo(entry: dict[str, Any] | None) -> Tempo | None:
    if not entry:
        return None
    return Tempo(float(entry["bpm"]), float(entry.get("offset", 0.0)), int(entry.get("meter", 4)))


def _cue(at: Any, tempo: Tempo | None) -> tuple[float | None, tuple[int, float] | None]:
    """A cue as seconds, and as bar and beat if it was written so (checked: tempo exists)."""
    if isinstance(at, dict):
        bar, beat = int(at["bar"]), float(at.get("beat", 1))
        assert tempo is not None, "a bar-and-beat cue without a tempo passed the checks"
        return tempo.seconds(bar, beat), (bar, beat)
    return _seconds(at), None


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


def _build_steps(steps: list[dict[str, Any]], path: JsonPath, doc: _Doc, motions: dict[str, Motion],
                 tempo: Tempo | None = None) -> tuple[Step | Repeat, ...]:
    built: list[Step | Repeat] = []
    for index, step in enumerate(steps):
        here = path + (index,)
        line, column = doc.mark(here)
        robots = tuple(step["robots"]) if "robots" in step else None
        go = step.get("at") == GO
        at, at_beat = _cue(None if go else step.get("at"), tempo)
        common = dict(path=format_path(here), line=line, column=column, label=step.get("label"),
                      at=at, at_beat=at_beat, go=go, robots=robots)
        if "repeat" in step:
            inner = _build_steps(step["steps"], here + ("steps",), doc, motions, tempo)
            built.append(Repeat(count=int(step["repeat"]), steps=inner, **common))
        elif "play" in step:
            ref = step["play"]
            name = ref if isinstance(ref, str) else None
            built.append(Step(kind=StepKind.PLAY, motion=_motion_number(ref, motions), motion_name=name, **common))
        elif step["wait"] == "done":
            timeout = _seconds(step.get("timeout"))
            built.append(Step(kind=StepKind.WAIT_DONE, seconds=DEFAULT_DONE_TIMEOUT_S if timeout is None else timeout, **common))
        else:
            built.append(Step(kind=StepKind.WAIT, seconds=float(step["wait"]), **common))
    return tuple(built)


def _motion_number(ref: int | float | str, motions: dict[str, Motion]) -> int:
    return motions[ref].number if isinstance(ref, str) else int(ref)


def _seconds(value: Any) -> float | None:
    return None if value is None else float(value)
