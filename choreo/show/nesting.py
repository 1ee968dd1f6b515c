"""Where a YAML text's flow nesting first gets too deep, found without the YAML parser.

Why this exists: the show loader bounds nesting while it walks the parser's events, but the
parser's scanner runs ahead of its events (a `[` may start a simple key, so it looks up to a line
or 1,024 characters ahead before emitting anything). PyYAML 6.0.4's scanner has a nesting limit of
its own (1,000) and hits it inside that look-ahead for `[[[[…`: the loader would never see an
event past depth 40 and would report the parser's message, not its own. This pass finds the first
opening bracket past the limit by reading the text itself, so the loader can hand the parser only
the text before it and report the depth in its own words, whatever the parser's limits are (the
text it is handed nests at most `limit` deep in flow and, the event walk having passed it, `limit`
deep in block context: any parser limit of twice choreo's or more is out of reach).

The pass reads the flow structure the way YAML does (quoted scalars, comments, block scalars,
plain scalars in block context are skipped), but it need not be exact: a count too high only
costs one extra parse of a prefix (the loader's event walk decides); a count too low leaves the
parser's own limit as the last guard.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

_OPEN = "[{"
_CLOSE = "]}"
_BLANKS = " \t"
_BREAKS = "\r\n"
_NODE_PROPERTIES = "&!"  # an anchor or a tag before a node
_LINE_BREAK = re.compile("[\r\n]")


@dataclass(frozen=True)
class TooDeep:
    """Where flow nesting first goes past the limit."""

    index: int  # the opening bracket past the limit
    outermost: int  # the opening bracket of the flow collection it is inside, at depth 1


@dataclass(frozen=True)
class _LineEnd:
    """The scan of a line's nodes is over (`found`: the bracket past the limit, if any)."""

    found: int | None = None


_LINE_END = _LineEnd()


def too_deep_at(text: str, limit: int) -> TooDeep | None:
    """The first opening bracket that makes flow nesting deeper than `limit`, or None."""
    scan = _Scan(text, limit)
    found = scan.run()
    return None if found is None else TooDeep(found, scan.outermost)


class _Scan:
    """One pass over the text: block lines, flow collections, scalars skipped whole."""

    def __init__(self, text: str, limit: int) -> None:
        self.text = text
        self.limit = limit
        self.i = 0
        self.depth = 0
        self.outermost = 0  # where the flow collection being read opened

    def run(self) -> int | None:
        text = self.text
        while self.i < len(text):
            found = self._block_line()
            if found is not None:
                return found
        return None

    # ------------------------------------------------------------------ block context

    def _block_line(self) -> int | None:
        """One line in block context, from its indentation to its end (or a flow's end)."""
        self._skip(_BLANKS)
        if self.text.startswith(("---", "..."), self.i) and self._blank_or_end(self.i + 3):
            self.i += 3
        return self._node_start()

    def _node_start(self) -> int | None:
        """From a place where a node may start to the end of the line (or a flow's end).

        A loop, not recursion: `a: b: c: …` on one line must not cost a stack frame a key.
        `parent` is the column of the block node a block scalar here belongs to (the key's in
        `- play: |`, the entry's in `- |`): its text is the lines indented deeper than that.
        """
        text = self.text
        line_start = text.rfind("\n", 0, self.i) + 1
        parent = None
        while True:
            self._skip(_BLANKS)
            if self.i >= len(text):
                return None
            column = self.i - line_start
            after = self._node(column, column if parent is None else parent)
            if isinstance(after, _LineEnd):
                return after.found
            parent = after

    def _node(self, column: int, parent: int) -> int | _LineEnd:
        """Past one token at `column`: the parent column for what follows on the line, or the
        line's end (with the bracket past the limit, if the token was a flow that had one)."""
        char = self.text[self.i]
        if char in "-?:" and self._blank_or_end(self.i + 1):
            self.i += 1
            return parent if char == ":" else column
        if char in _NODE_PROPERTIES:
            self._skip_word()
            return parent
        if char in _OPEN:
            found = self._flow()
            return _LineEnd(found) if found is not None or not self._value_follows() else column
        if char in "'\"":
            self._quoted(char)
            return column if self._value_follows() else _LINE_END
        if char in "|>":
            self._block_scalar(parent)
            return _LINE_END
        if char == "#" or char in _BREAKS:
            self._to_next_line()
            return _LINE_END
        return column if self._plain_in_block() else _LINE_END

    def _plain_in_block(self) -> bool:
        """Past a key or plain scalar (brackets inside it are text): True if `: ` starts a value."""
        text = self.text
        while self.i < len(text) and text[self.i] not in _BREAKS:
            char = text[self.i]
            if char == ":" and self._blank_or_end(self.i + 1):
                self.i += 1
                return True
            if char == "#" and text[self.i - 1] in _BLANKS:
                break
            self.i += 1
        self._to_next_line()
        return False

    def _value_follows(self) -> bool:
        """After a quoted scalar or a flow collection in block context: True at `: value`."""
        self._skip(_BLANKS)
        if self.i < len(self.text) and self.text[self.i] == ":" and self._blank_or_end(self.i + 1):
            self.i += 1
            return True
        self._to_next_line()
        return False

    def _block_scalar(self, indent: int) -> None:
        """`|` or `>`: every following line indented deeper than its parent node, or blank."""
        self._to_next_line()
        text = self.text
        while self.i < len(text):
            end = self._line_end(self.i)
            line = text[self.i:end]
            if line.strip(_BLANKS) and len(line) - len(line.lstrip(" ")) <= indent:
                return
            self.i = end
            self._to_next_line()

    # ------------------------------------------------------------------ flow context

    def _flow(self) -> int | None:
        """From an opening bracket to just past the bracket that closes the outermost collection."""
        text = self.text
        token_start = True
        self.outermost = self.i
        while self.i < len(text):
            char = text[self.i]
            if char in _OPEN:
                self.depth += 1
                if self.depth > self.limit:
                    return self.i
                token_start = True
            elif char in _CLOSE:
                self.depth -= 1
                if self.depth <= 0:
                    self.depth = 0
                    self.i += 1
                    return None
                token_start = False
            elif char in "'\"" and token_start:
                self._quoted(char)
                token_start = False
                continue
            elif char == "#" and (self.i == 0 or text[self.i - 1] in _BLANKS + _BREAKS):
                self.i = self._line_end(self.i)
                continue
            elif char in ",?:":
                token_start = True
            elif char not in _BLANKS + _BREAKS:
                token_start = False
            self.i += 1
        return None

    # ------------------------------------------------------------------ pieces

    def _quoted(self, quote: str) -> None:
        """Past a quoted scalar: `''` is a quote in single quotes, a backslash escapes in double."""
        text = self.text
        self.i += 1
        while self.i < len(text):
            char = text[self.i]
            if quote == '"' and char == "\\":
                self.i += 2
                continue
            if char == quote:
                if quote == "'" and text.startswith("''", self.i):
                    self.i += 2
                    continue
                self.i += 1
                return
            self.i += 1

    def _skip(self, chars: str) -> None:
        while self.i < len(self.text) and self.text[self.i] in chars:
            self.i += 1

    def _skip_word(self) -> None:
        while self.i < len(self.text) and self.text[self.i] not in _BLANKS + _BREAKS:
            self.i += 1

    def _line_end(self, start: int) -> int:
        found = _LINE_BREAK.search(self.text, start)
        return found.start() if found else len(self.text)

    def _to_next_line(self) -> None:
        self.i = self._line_end(self.i)
        if self.text.startswith("\r\n", self.i):
            self.i += 2
        elif self.i < len(self.text):
            self.i += 1

    def _blank_or_end(self, index: int) -> bool:
        return index >= len(self.text) or self.text[index] in _BLANKS + _BREAKS
