"""Settings every test shares."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def output_to_a_pipe(monkeypatch):
    """pytest-xdist's workers export COLUMNS=80, which choreo (like pip) takes as the terminal's
    width and fits its lines to: tests see whole lines, as through a pipe, unless they set one."""
    monkeypatch.delenv("COLUMNS", raising=False)
