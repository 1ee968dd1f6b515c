"""choreo's own source, for the tests that check it as code (layers, wiring, facts, probes,
silenced warnings, citations): its files, and each one's syntax tree parsed once."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "choreo"


def source_files(package: Path = PACKAGE) -> list[Path]:
    """Every module under `package`, in a steady order."""
    return sorted(package.rglob("*.py"))


def syntax_tree(path: Path) -> ast.Module:
    """`path`'s syntax tree; the same text is parsed only once however many checks read it."""
    return _parse(path.read_text(encoding="utf-8"), str(path))


@functools.cache
def _parse(text: str, filename: str) -> ast.Module:
    return ast.parse(text, filename)
