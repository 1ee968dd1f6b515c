"""Hostile values on the command line and in a `sim://` URL (issue 21, item 6): a number the
parser takes is one the code after it can use, else one line and exit 2, never a traceback."""

from __future__ import annotations

import pytest

from choreo.sim.options import parse_options

TINY = ["1e-320", "5e-324", "1e-300", "1e-12"]


@pytest.mark.parametrize("value", TINY)
def test_a_refresh_period_taken_is_one_the_board_can_tick_by(value):
    """`--refresh-ms 1e-320` was taken and the board's first status read divided by it: an
    OverflowError traceback from `choreo sim` and from a run on sim://."""
    try:
        options = parse_options({"refresh_ms": value})
    except ValueError as exc:
        assert "refresh period" in str(exc)
        return
    board = options.board(power_on=0.0)
    board.advance(3.5)  # raised OverflowError: (now - power_on) / refresh_s was infinite


JAPANESE_SHOW = """\
version: 1
name: 日本語のショー
motions:
  歩く: {number: 4, duration: 0.5}
steps:
  - play: 歩く
    label: 始め
"""


@pytest.mark.parametrize("encoding", ["ascii", "latin-1", "cp1252"])
def test_a_console_that_cannot_show_the_names_gets_escapes_not_a_traceback(tmp_path, encoding):
    """Issue 21, item 6: on a console whose encoding lacks the show's characters (LC_ALL=C, a
    cp1252 console) `plan` of a show with Japanese names was a UnicodeEncodeError traceback, exit 1."""
    import json
    import os
    import subprocess
    import sys

    show = tmp_path / "jp.yaml"
    show.write_text(JAPANESE_SHOW, encoding="utf-8")
    env = dict(os.environ, PYTHONIOENCODING=encoding)
    for argv in (["plan", str(show)], ["validate", str(show)], ["plan", "--json", str(show)]):
        done = subprocess.run([sys.executable, "-m", "choreo", *argv], capture_output=True, env=env, timeout=60)
        assert done.returncode == 0 and b"Traceback" not in done.stderr, done.stderr
        assert b"\\u6b69\\u304f" in done.stdout  # 歩く, escaped
    assert json.loads(done.stdout)["name"] == "日本語のショー"  # JSON's own escapes: still the name
