"""Lines fitted to a width: the one way choreo cuts a human-facing line (the CLI measures the
terminal, the review modules lay out to a given width; both cut here)."""

from __future__ import annotations


def fit(line: str, width: int | None) -> str:
    """`line`, or its start and '…' in exactly `width` characters (None: no width, whole)."""
    if width is None or len(line) <= width:
        return line
    return line[:max(width - 1, 0)] + "…"
