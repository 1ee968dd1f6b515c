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
