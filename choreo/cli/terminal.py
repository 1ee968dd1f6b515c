"""How wide the user's terminal is, the one fact every human-facing output is fitted to
(`choreo.textfit.fit` does the cutting)."""

from __future__ import annotations

import os
import sys
from typing import TextIO

# Where the output is not a terminal (a file, a pipe, a test) and COLUMNS does not say: lines
# that need a width (the timeline's bars) use this; lines that are data (log frames) stay whole.
UNKNOWN_COLUMNS = 100


def columns(stream: TextIO | None = None) -> int | None:
    """The terminal's width, `COLUMNS` where set (as pytest and pip honour it), else None."""
    stream = stream if stream is not None else sys.stdout
    try:
        if stream.isatty():
            return os.get_terminal_size(stream.fileno()).columns
    except (OSError, ValueError, AttributeError):
        pass
    given = os.environ.get("COLUMNS", "")
    return int(given) if given.isdigit() and int(given) > 0 else None
