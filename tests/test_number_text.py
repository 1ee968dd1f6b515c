"""Whole numbers written by someone else (a log's metadata, an option, a URL) are read by
`choreo.numtext.whole_number`: `²`, `١` and 5,000 digits pass `str.isdigit()` and then make
`int()` raise (found: --audio-device ², sim://?drop=², a log whose start_ns or baud was either)."""

from __future__ import annotations

import pytest

from choreo.errors import UsageError
from choreo.music.player import Output, pick_output
from choreo.numtext import whole_number
from choreo.sim.faults import Trigger

HOSTILE = ["²", "١", "1" * 5000, "", " ", "-1", "1.0", "0x10"]


@pytest.mark.parametrize("text", HOSTILE)
def test_text_that_is_no_plain_whole_number_is_none(text):
    assert whole_number(text) is None


def test_plain_digits_read_as_themselves():
    assert whole_number(" 115200 ") == 115200 and whole_number("9" * 19) == int("9" * 19)


@pytest.mark.parametrize("given", ["²", "1" * 5000])
def test_an_audio_device_number_that_is_no_number_is_no_such_output(given):
    with pytest.raises(UsageError, match="no such output"):
        pick_output(given, lambda: [Output(1, "speakers", "test")])


@pytest.mark.parametrize("given", ["²", "³"])
def test_a_fault_trigger_that_is_no_number_is_refused_in_words(given):
    with pytest.raises(ValueError, match="neither a whole number"):
        Trigger.parse(given)
