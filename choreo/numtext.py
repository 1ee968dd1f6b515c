"""A whole number written as text by someone else: a log's metadata, an option, a URL's query.

`str.isdigit()` is not the test for it: it is true of `²` and `١` (which `int()` refuses or reads
as another digit) and of 5,000 digits (past which `int()` raises ValueError, and which no
value choreo reads needs). Every such text goes through `whole_number`, so a hostile one is
"not a number" to the caller, never an exception halfway through a message.
"""

from __future__ import annotations

MAX_DIGITS = 19  # nanoseconds since 1970 have 19; no count, baud or index choreo reads needs more


def whole_number(text: str, max_digits: int = MAX_DIGITS) -> int | None:
    """`text` (surrounding blanks allowed) as a non-negative int if it is 1..max_digits ASCII
    digits; None if not."""
    text = text.strip()
    if not text or len(text) > max_digits or not (text.isascii() and text.isdigit()):
        return None
    return int(text)
