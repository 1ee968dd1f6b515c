"""A show file's bytes to located plain data (`Doc`), or every reason they cannot be read.

The file is read whole (refused over `MAX_BYTES`), decoded as strict UTF-8 and fed to the YAML
*parser* only (`yamlwalk` builds the data from its events). What the parser cannot be trusted
with is handled here, before and around it: YAML 1.1's extra line breaks are hidden from it
(`scalars.HIDE_BREAKS`), nesting past `MAX_DEPTH` is found before its scanner's own limits can
decide the message, and its syntax errors are located and said in a show author's words.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from choreo.errors import InputError
from choreo.show.nesting import too_deep_at
from choreo.show.report import Doc, Mark, Report, kind_text
from choreo.show.scalars import BREAKS_1_1, HIDE_BREAKS
from choreo.show.yamlwalk import MAX_DEPTH, TOO_DEEP, Stop, YamlWalk
from choreo.userfile import read_input

# An hour-long show with a step a second is about 50 KiB. The limit bounds the work a file can
# cause: checking costs about 0.1 ms a step, so the largest file answers in a few seconds.
MAX_BYTES = 256 * 1024

# libyaml's parser when available: the pure-Python one is about 20 times slower on big files.
_Parser = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def read_file(path: Path, report: Report) -> bytes | None:
    """The show file's bytes; None (reported) if it is not a file that can be read."""
    try:
        return read_input(path, "show file", MAX_BYTES)
    except InputError as exc:
        report.add((0, 0), "", exc.reason)
        return None


def read_document(source: bytes, report: Report) -> Doc | None:
    """The document as data with marks; None (and problems reported) if there is none to check."""
    if len(source) > MAX_BYTES:
        report.add((0, 0), "", f"the file is over {MAX_BYTES // 1024} KiB, too big for a show file")
        return None
    text = _decode(source, report)
    return _parse(text, report) if text is not None else None


def _decode(data: bytes, report: Report) -> str | None:
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line_start = data.rfind(b"\n", 0, exc.start) + 1
        line = data.count(b"\n", 0, exc.start) + 1
        column = len(data[line_start : exc.start].decode("utf-8", "replace")) + 1
        report.add((line, column), "", f"not UTF-8 (byte 0x{data[exc.start]:02x}): save the file as UTF-8")
        return None
    return text[1:] if text.startswith("\ufeff") else text


def _parse(text: str, report: Report) -> Doc | None:
    stand_in = next((ch for ch in BREAKS_1_1.values() if ch in text), None)
    if stand_in is not None:
        report.add(_mark_at(text, text.index(stand_in)), "",
                   f"character U+{ord(stand_in):04X} (private use) is not allowed in a show file")
        return None
    text = text.translate(HIDE_BREAKS)
    if _too_deep(text, report):
        return None
    walk = _walk(text, report)
    if walk is None:
        return None
    if walk.documents == 0 or walk.root is None:
        report.add((1, 1), "", "the file holds no show: start with `version: 1` and `steps:`")
        return None
    if not isinstance(walk.root, dict):
        report.add(walk.root_mark or (1, 1), "",
                   f"the top level must be a mapping (`version: 1`, `steps:` ...), not {kind_text(walk.root)}")
        return None
    # Aliases, tags and duplicate keys reported so far do not stop the checks: the rest of the
    # file is still checked, and a second report at the same node is dropped by `Report`.
    return Doc(walk.root, walk.where)


def _walk(text: str, report: Report) -> YamlWalk | None:
    """The whole text's events walked; None (reported) if the parser or the walk stopped."""
    walk = YamlWalk(report)
    try:
        try:
            for event in yaml.parse(text, Loader=_Parser):
                walk.feed(event)
        finally:
            walk.finish()
    except Stop:
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
    return walk


def _mark_at(text: str, index: int) -> Mark:
    """The 1-based line and column of a character of the text."""
    return text.count("\n", 0, index) + 1, index - (text.rfind("\n", 0, index) + 1) + 1


# --------------------------------------------------------------------------- nesting


def _too_deep(text: str, report: Report) -> bool:
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
        report.add(_mark_at(text, deep.index), "", TOO_DEEP)
        return True
    return False


_TOO_DEEP = "too deep"


def _walk_prefix(prefix: str, report: Report) -> yaml.YAMLError | str | None:
    """Walk the events of the text's first part: `_TOO_DEEP` (reported) if it nests past the
    limit, else the parser's error on it (None if it parses); other problems are not reported."""
    scratch = Report(report.file)
    walk = YamlWalk(scratch)
    try:
        for event in yaml.parse(prefix, Loader=_Parser):
            walk.feed(event)
    except Stop:
        for problem in scratch.problems():
            report.add((problem.line, problem.column), problem.path, problem.message)
        return _TOO_DEEP
    except yaml.YAMLError as exc:
        return exc
    return None


def _earlier_problem(text: str, exc: yaml.MarkedYAMLError, report: Report) -> bool:
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
        if isinstance(found, yaml.MarkedYAMLError) and found.problem_mark is not None \
                and prefix[found.problem_mark.index:].strip():
            _report_syntax(found, report)
            return True
        prefix = prefix.rstrip()[:-1]  # an error at the prefix's end is its cut, not the file's
    return False


def _report_syntax(exc: yaml.MarkedYAMLError, report: Report) -> None:
    """The parser's error located; its own nesting limit (reached where the walk could not judge
    the text before it: a key the scanner had not resolved) is said in choreo's words."""
    mark = exc.problem_mark or exc.context_mark
    where = (mark.line + 1, mark.column + 1) if mark else (0, 0)
    what = exc.problem or "syntax error"
    if "nesting" in what:
        report.add(where, "", TOO_DEEP)
        return
    context = f" ({exc.context})" if exc.context else ""
    report.add(where, "", f"YAML syntax error: {what}{context}")
