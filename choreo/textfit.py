"""Human-facing text: made safe to show, measured and fitted to a width.

Text from outside (a show's names, an OSC address, an imported project, a file name) may hold
bytes a terminal obeys: escape sequences that retitle the window or move the cursor, bidi
overrides that show a name backwards, zero-width characters that hide in it. `visible` writes
every such character as an escape a reader can see (`\\x1b`, `\\u202e`), the one place that
decides what a human may be shown raw. `display_width` measures text the way a terminal lays it
out (a Japanese character takes two columns), and `fit` cuts a line to a width by it: the CLI
measures the terminal, the review modules lay out to a given width; both cut here.
"""

from __future__ import annotations

import re
import unicodedata

ELLIPSIS = "…"

# Categories a terminal does not simply print: controls (C0, DEL, C1), format characters (bidi
# overrides and isolates, zero-width space and joiners, the BOM, soft hyphen), line and
# paragraph separators, and lone surrogates (undecodable bytes of a file name).
_HIDDEN_CATEGORIES = frozenset(("Cc", "Cf", "Zl", "Zp", "Cs"))
# Characters that print as nothing although Unicode gives them a letter's or a mark's category.
_BLANK = frozenset("\u034f\u115f\u1160\u17b4\u17b5\u3164\uffa0")
# Unicode's default-ignorable code points a category does not catch: variation selectors (marks
# that print as nothing: `bow` and `bow\ufe0f` look alike), Mongolian ones, and the blocks kept
# for more of them (unassigned today, zero-width on a terminal that knows them tomorrow).
_IGNORABLE = ((0x180B, 0x180F), (0x2065, 0x2065), (0xFE00, 0xFE0F), (0xFFF0, 0xFFF8), (0xE0000, 0xE0FFF))
# Anything outside printable ASCII is looked at one by one; printable ASCII never needs to be.
_SUSPECT = re.compile(r"[^\x20-\x7e]")


def _escape(char: str) -> str:
    """`\\x1b` for a C0 control (which JSON output always escapes itself), `\\u202e` for the
    rest, a pair of UTF-16 escapes beyond the BMP: the text stays valid inside a JSON string."""
    code = ord(char)
    if code < 0x20:
        return f"\\x{code:02x}"
    if code <= 0xFFFF:
        return f"\\u{code:04x}"
    code -= 0x10000
    return f"\\u{0xD800 + (code >> 10):04x}\\u{0xDC00 + (code & 0x3FF):04x}"


def is_hidden(char: str) -> bool:
    """Whether a terminal would obey `char`, or show it as nothing, rather than print it."""
    if unicodedata.category(char) in _HIDDEN_CATEGORIES or char in _BLANK:
        return True
    code = ord(char)
    return any(first <= code <= last for first, last in _IGNORABLE)


def visible(text: str, keep: str = "") -> str:
    """`text` with every control, format or invisible character written as an escape; the
    characters in `keep` (say "\\n" for a whole output stream) stay as they are. Idempotent:
    what it returns is printable, and a second pass changes nothing."""
    if text.isascii() and text.isprintable():
        return text

    def one(match: re.Match[str]) -> str:
        char = match.group()
        return _escape(char) if char not in keep and is_hidden(char) else char

    return _SUSPECT.sub(one, text)


def char_width(char: str) -> int:
    """Columns a terminal gives `char`: 2 for East Asian wide and fullwidth characters, 0 for
    combining marks and hidden characters, else 1."""
    if char.isascii():
        return 1 if char.isprintable() else 0
    if unicodedata.combining(char) or is_hidden(char):
        return 0
    return 2 if unicodedata.east_asian_width(char) in ("W", "F") else 1


def display_width(text: str) -> int:
    """Columns `text` takes on a terminal (not `len`: `ロボット` takes 8)."""
    if text.isascii():
        return len(text)
    return sum(char_width(char) for char in text)


def fit(line: str, width: int | None) -> str:
    """`line` made visible, whole if it fits `width` columns, else its start and '…' in at most
    `width` columns (None: no width, whole). A wide character that would straddle the edge is
    left out whole, so the line may end a column short."""
    line = visible(line)
    if width is None or display_width(line) <= width:
        return line
    if width <= 0:
        return ""
    room = width - 1  # the ellipsis takes one column
    used = 0
    end = len(line) - 1  # as if the last character overflowed: the line is wider than `width`
    for index, char in enumerate(line):
        used += char_width(char)
        if used > room:
            end = index
            break
    return line[:end] + ELLIPSIS


def pad(text: str, width: int) -> str:
    """`text` and spaces to `width` columns, by display width (str.ljust counts characters)."""
    return text + " " * max(width - display_width(text), 0)
