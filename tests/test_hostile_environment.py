"""The environment is outside input too: a COLUMNS or LINES that is no width is no width."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import pytest

from choreo.cli.console import Console
from choreo.cli.terminal import columns
from choreo.live.controls import Live
from choreo.events import StopRequest
from choreo.run.session import Session
from choreo.run.settings import RunRequest

ROOT = Path(__file__).resolve().parent.parent
HOSTILE = ["²", "١٢٠", "9" * 5000, "-80", "0", "80x", " ", "\x1b[2J"]


@pytest.mark.parametrize("value", HOSTILE)
def test_a_columns_that_is_no_width_is_no_width(monkeypatch, value):
    monkeypatch.setenv("COLUMNS", value)
    assert columns(io.StringIO()) is None


def test_a_columns_that_is_a_width_is_taken(monkeypatch):
    monkeypatch.setenv("COLUMNS", " 72 ")
    assert columns(io.StringIO()) == 72


@pytest.mark.parametrize("value", HOSTILE)
def test_the_console_is_built_whatever_columns_and_lines_say(tmp_path, monkeypatch, value):
    """rich reads COLUMNS and LINES with int() when it is built: `²` was a ValueError."""
    monkeypatch.setenv("COLUMNS", value)
    monkeypatch.setenv("LINES", value)
    show = tmp_path / "show.yaml"
    show.write_text("version: 1\nsteps:\n  - play: 1\n")
    session = Session.prepare(RunRequest(str(show), no_log=True))
    console = Console(session, Live(StopRequest()), out=io.StringIO(), keys=io.StringIO())
    assert console.renderable(60) is not None


@pytest.mark.parametrize("value", ["²", "9" * 5000])
def test_plan_with_a_columns_that_is_no_width_is_not_a_traceback(value):
    env = {"COLUMNS": value, "PATH": "/usr/bin:/bin"}
    done = subprocess.run([sys.executable, "-m", "choreo", "plan", str(ROOT / "shows" / "minimal.yaml")],
                          capture_output=True, text=True, env=env, timeout=60)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
