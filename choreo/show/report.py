"""What the passes over a show file share: where each value is, and the problems found so far.

Loading runs in passes (`read`, `schema`, `checks`), each reporting everything it finds before
the next runs on what survived. They meet here: `Doc` is the parsed file as plain data with the
line and column of every value and key, and `Report` collects problems so that one found twice
(by the schema and by a check, at the same node) is said once, and a later pass can leave alone
a value an earlier one has already found wrong. The words for values in messages live here too,
so that every pass says `the number 3` and `true` the same way.

Messages are `FILE:LINE:COL: PATH: WHAT` (`choreo.errors.Problem`); paths are written
`steps[3].play`, list indexes 0-based as in the file's order.
"""

from __future__ import annotations

import difflib
import json
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, Union

from choreo.errors import Problem

JsonPath = tuple[Union[str, int], ...]
Mark = tuple[int, int]  # 1-based line and column

MAX_SHOWN = 50  # problems said of one file, the first in file order; the rest are counted in one line
MAX_FOUND = 1000  # problems sought in one file: past these the schema stops looking (`Report.stop_looking`)


class Report:
    """Collects problems, dropping a second report of the same path at the same place.

    A file of 256 KiB can hold 60,000 wrong list entries: saying each took 5 s and 60,000
    lines that no one reads. The first `MAX_SHOWN` are said, in file order, and the rest
    counted; past `MAX_FOUND` the schema stops looking, so the cost is bounded too."""

    def __init__(self, file: str) -> None:
        self.file = file
        self._problems: list[Problem] = []
        self._seen: set[tuple[int, int, str]] = set()
        self._flagged: set[JsonPath] = set()  # paths that already have a problem
        self._silenced: set[JsonPath] = set()  # values replaced by a placeholder: no schema reports below
        self._stopped = False  # a pass stopped looking: there may be more than were found

    def add(self, mark: Mark, path: JsonPath | str, message: str) -> None:
        text = path if isinstance(path, str) else format_path(path)
        key = (mark[0], mark[1], text)
        if key in self._seen:
            return
        self._seen.add(key)
        if not isinstance(path, str):
            self._flagged.add(path)
        self._problems.append(Problem(self.file, mark[0], mark[1], text, message))

    def stop_looking(self) -> None:
        """A pass found `MAX_FOUND` problems and looked no further: what it did not reach is
        unchecked, so the passes after it must not read the document (`stopped`)."""
        self._stopped = True

    def stopped(self) -> bool:
        return self._stopped

    def silence(self, path: JsonPath) -> None:
        """The value at `path` was refused and read as nothing (an alias): what is said of the
        placeholder or below it would be noise; the refusal is reported on its own."""
        self._silenced.add(path)
        self._flagged.add(path)

    def passed(self, path: JsonPath) -> bool:
        """Whether nothing has been reported at `path` or above it (so the value is the type
        the schema says, and a check can read it)."""
        return all(path[:n] not in self._flagged for n in range(len(path) + 1))

    def silenced(self, path: JsonPath) -> bool:
        """Whether the value at `path`, or one it is inside, was refused and read as nothing."""
        return any(path[:n] in self._silenced for n in range(len(path) + 1))

    def any(self) -> bool:
        return bool(self._problems)

    def problems(self) -> list[Problem]:
        """In file order, which is how an author fixes them: the first `MAX_SHOWN`, then one
        line (no place) that counts the rest."""
        ordered = sorted(self._problems, key=lambda p: (p.line, p.column))
        if len(ordered) <= MAX_SHOWN:
            return ordered
        more = ("at least " if self._stopped else "") + f"{len(ordered) - MAX_SHOWN:,}"
        return [*ordered[:MAX_SHOWN], Problem(self.file, 0, 0, "", f"and {more} more problems (fix these first)")]


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


@dataclass(frozen=True)
class Where:
    """Where a value sits: its own mark, and its key's mark when it is a mapping value."""

    value: Mark
    key: Mark | None = None
    empty: bool = False  # `key:` with nothing after it: point at the key
    text: str | None = None  # a number as written (`12.50`, `1e3`): a cue number keeps its text


@dataclass
class Doc:
    """The parsed file: plain data, and where each path came from."""

    data: Any
    where: dict[JsonPath, Where]

    def mark(self, path: JsonPath) -> Mark:
        """The value at `path` (its key if the value is empty), else its nearest ancestor."""
        while path not in self.where and path:
            path = path[:-1]
        where = self.where.get(path)
        if where is None:
            return (1, 1)
        return where.key if where.empty and where.key else where.value

    def text(self, path: JsonPath) -> str | None:
        """The number at `path` as the file wrote it (None: not a number): `12.50` is read as
        the float 12.5, but a cue number is text, compared and shown as written."""
        where = self.where.get(path)
        return where.text if where is not None else None

    def key_mark(self, path: JsonPath) -> Mark:
        where = self.where.get(path)
        if where is not None and where.key is not None:
            return where.key
        return self.mark(path)


def value_text(value: Any) -> str:
    """A value as the author would write it in YAML."""
    if value is None:
        return "nothing"
    if value is True or value is False:
        return "true" if value else "false"
    if isinstance(value, float) and math.isinf(value):
        return ".inf" if value > 0 else "-.inf"
    if isinstance(value, (int, float, str)):
        return repr(value)
    return kind_text(value)


def kind_text(value: Any) -> str:
    """What a value is, for `expected X, not Y`."""
    if value is None:
        return "an empty value"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return f"the number {value_text(value)}"
    if isinstance(value, str):
        return f"the text {value!r}"
    if isinstance(value, list):
        return "a list"
    return "a mapping"


def closest(name: str, known: Iterable[str]) -> str | None:
    """The one of `known` that `name` is most likely a typo of, if any is close."""
    close = difflib.get_close_matches(name, list(known), n=1)
    return close[0] if close else None
