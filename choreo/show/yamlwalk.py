"""The YAML parser's events turned into plain data with the line and column of every value and key.

We never let PyYAML build Python objects. This walk builds the JSON-like data itself, recording
where each value and key came from as it goes. That is what makes messages point at the right
character, and it is also the safety story: no tag can construct an object, aliases are refused
outright (so an alias bomb costs nothing), duplicate keys are caught (PyYAML would keep the last
one silently), and nesting is bounded without recursion (an explicit stack of open collections).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import yaml

from choreo.show.report import JsonPath, Mark, Report, Where
from choreo.show.scalars import MAP, SEQ, Scalars, restore_breaks, tag_text

MAX_DEPTH = 40  # nesting levels of YAML lists and mappings (repeats inside repeats, ...)
TOO_DEEP = f"nested more than {MAX_DEPTH} levels deep"


class Stop(Exception):
    """Parsing cannot usefully go on (a second document, nesting too deep): it is reported."""


_DISCARD = object()  # the pending key of a mapping entry whose value is thrown away

_Collection = (yaml.MappingStartEvent, yaml.SequenceStartEvent)


@dataclass
class _Frame:
    """An open list or mapping while the event stream is walked."""

    container: dict[str, Any] | list[Any] | None  # None: inside something thrown away
    path: JsonPath
    is_key: bool = False  # this collection is itself a mapping key (refused)
    key: Any = None  # mapping: the key waiting for its value (or _DISCARD)
    key_mark: Mark | None = None
    expect_key: bool = True
    keys: dict[str, Mark] = field(default_factory=dict)


def mark_of(event: yaml.Event) -> Mark:
    """Where an event starts, 1-based."""
    mark = event.start_mark
    return (1, 1) if mark is None else (mark.line + 1, mark.column + 1)


class YamlWalk:
    """Turns YAML events into JSON-like data and a map of marks, refusing what is unsafe.

    Feed it every event (`feed`), then `finish`; `root` is the document's data and `where`
    the marks by path. `Stop` is raised when the rest of the stream cannot be read usefully."""

    def __init__(self, report: Report) -> None:
        self.report = report
        self.scalars = Scalars(report)
        self.where: dict[JsonPath, Where] = {}
        self.stack: list[_Frame] = []
        self.root: Any = None
        self.root_mark: Mark | None = None
        self.documents = 0
        self.first_alias: tuple[Mark, JsonPath, str] | None = None
        self.more_aliases = 0

    def feed(self, event: yaml.Event) -> None:
        if isinstance(event, yaml.DocumentStartEvent):
            self.documents += 1
            if self.documents > 1:
                self.report.add(mark_of(event), "", "a show file holds one YAML document; remove the second `---`")
                raise Stop
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            self._close()
        elif isinstance(event, (yaml.ScalarEvent, yaml.AliasEvent, *_Collection)):
            self._node(event)

    def finish(self) -> None:
        """Report what is counted along the way rather than reported one by one."""
        if self.first_alias is not None:
            mark, path, anchor = self.first_alias
            more = f" ({self.more_aliases} more after this one)" if self.more_aliases else ""
            self.report.add(mark, path, f"aliases (*{anchor}) are not allowed in a show file: "
                                        f"write the value out{more}")

    def _node(self, event: yaml.NodeEvent) -> None:
        parent: _Frame | None = self.stack[-1] if self.stack else None
        if parent is not None and isinstance(parent.container, dict) and parent.expect_key:
            self._key(parent, event)
            return
        path, discard = _place(parent)
        if isinstance(event, yaml.CollectionStartEvent):
            self._open(event, path, discard)
            return
        if discard:
            if parent is not None and isinstance(parent.container, dict):
                parent.expect_key = True
            return
        mark = mark_of(event)
        value: Any = None
        text: str | None = None
        if isinstance(event, yaml.AliasEvent):
            self._alias(event, mark, path)
        elif isinstance(event, yaml.ScalarEvent):
            value = self.scalars.value(event, path, mark)
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                text = event.value  # as written: `12.50` is the float 12.5 (a cue number keeps its text)
        self._attach(path, value, mark, empty=_is_empty(event), text=text)

    def _alias(self, event: yaml.AliasEvent, mark: Mark, path: JsonPath) -> None:
        """Refused: reported once at the first, counted after it (a bomb holds thousands)."""
        self.report.silence(path)
        if self.first_alias is None:
            self.first_alias = (mark, path, event.anchor or "")
        else:
            self.more_aliases += 1

    def _key(self, parent: _Frame, event: yaml.NodeEvent) -> None:
        parent.expect_key = False
        mark = mark_of(event)
        if not isinstance(event, yaml.ScalarEvent):
            self.report.add(mark, parent.path, "a key must be plain text (no lists, mappings or aliases as keys)")
            parent.key = _DISCARD
            if isinstance(event, yaml.CollectionStartEvent):
                self._push(_Frame(None, parent.path, is_key=True))
            return
        name = restore_breaks(event.value)
        first = parent.keys.get(name)
        if first is not None:
            self.report.add(mark, parent.path + (name,),
                            f"duplicate key {name!r} (first given at line {first[0]}): keep one")
            parent.key = _DISCARD
            return
        parent.keys[name] = mark
        parent.key, parent.key_mark = name, mark

    def _open(self, event: yaml.CollectionStartEvent, path: JsonPath, discard: bool) -> None:
        mark = mark_of(event)
        is_map = isinstance(event, yaml.MappingStartEvent)
        if discard:
            self._push(_Frame(None, path))
            return
        if event.tag not in (None, "!", MAP if is_map else SEQ):
            self.report.add(mark, path, f"tag {tag_text(event.tag)} is not allowed in a show file: remove it")
        if self.root_mark is None:
            self.root_mark = mark
        key_mark = self.stack[-1].key_mark if self.stack and isinstance(self.stack[-1].container, dict) else None
        self.where[path] = Where(mark, key_mark)
        self._push(_Frame({} if is_map else [], path))

    def _push(self, frame: _Frame) -> None:
        if len(self.stack) >= MAX_DEPTH:
            mark = (1, 1) if not self.stack else self.where.get(self.stack[-1].path, Where((1, 1))).value
            self.report.add(mark, self.stack[-1].path if self.stack else (), TOO_DEEP)
            raise Stop
        self.stack.append(frame)

    def _close(self) -> None:
        frame = self.stack.pop()
        parent: _Frame | None = self.stack[-1] if self.stack else None
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

    def _attach(self, path: JsonPath, value: Any, mark: Mark, empty: bool, text: str | None = None) -> None:
        parent: _Frame | None = self.stack[-1] if self.stack else None
        if parent is None:
            self.root, self.root_mark = value, mark
            self.where[path] = Where(mark)
            return
        if isinstance(parent.container, dict):
            self.where[path] = Where(mark, parent.key_mark, empty, text)
            parent.container[parent.key] = value
            parent.expect_key = True
        else:
            assert isinstance(parent.container, list)
            self.where[path] = Where(mark, text=text)
            parent.container.append(value)


def _place(parent: _Frame | None) -> tuple[JsonPath, bool]:
    """The path of the next value inside `parent`, and whether it is thrown away (the value of
    a refused key, or anything inside something thrown away)."""
    if parent is None:
        return (), False
    if parent.container is None:
        return parent.path, True
    if isinstance(parent.container, dict):
        if parent.key is _DISCARD:
            return parent.path, True
        return parent.path + (parent.key,), False
    return parent.path + (len(parent.container),), False


def _is_empty(event: yaml.Event) -> bool:
    return isinstance(event, yaml.ScalarEvent) and event.value == "" and event.implicit[0] and event.tag is None
