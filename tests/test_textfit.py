"""Human-facing text: outside text made visible, measured by display width, fitted to a width."""

from __future__ import annotations

import json
import unicodedata

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from choreo.textfit import display_width, fit, is_hidden, pad, visible

HOSTILE = [
    ("\x1b]0;pwned\x07", "\\x1b]0;pwned\\x07"),  # retitles the terminal window
    ("\x1b[2J\x1b[H", "\\x1b[2J\\x1b[H"),  # clears the screen
    ("a\rb", "a\\x0db"),  # overwrites the line it is on
    ("\x9b31m", "\\u009b31m"),  # an 8-bit CSI
    ("\x7f", "\\u007f"),
    ("abc\u202edef", "abc\\u202edef"),  # right-to-left override
    ("\u2066x\u2069", "\\u2066x\\u2069"),  # bidi isolates
    ("a\u200bb\u200dc\ufeff", "a\\u200bb\\u200dc\\ufeff"),  # zero-width space, joiner, BOM
    ("\u2028", "\\u2028"),  # line separator
    ("name\udcff", "name\\udcff"),  # an undecodable byte of a file name
    ("\U000e0041", "\\udb40\\udc41"),  # a tag character (invisible), beyond the BMP
    ("\u3164", "\\u3164"),  # Hangul filler: a letter that prints as nothing
    ("bow\ufe0f", "bow\\ufe0f"),  # a variation selector: a mark that prints as nothing (issue 21, item 4)
    ("a\u180bb\u180f", "a\\u180bb\\u180f"),  # Mongolian variation selectors
    ("w\U000e0100ave", "w\\udb40\\udd00ave"),  # a variation selector beyond the BMP
    ("\u2065\ufff0", "\\u2065\\ufff0"),  # default-ignorable, unassigned: zero-width once assigned
]


@pytest.mark.parametrize("raw, shown", HOSTILE)
def test_visible_escapes_what_a_terminal_would_obey_or_hide(raw: str, shown: str) -> None:
    assert visible(raw) == shown


def test_visible_leaves_ordinary_text_alone() -> None:
    for text in ("step 3 'intro': play 12", "ロボット 踊る", "Ünïcødé — ok…", "tab\\x1b literal backslash"):
        assert visible(text) == text


def test_visible_keeps_only_what_it_is_told() -> None:
    assert visible("a\nb\tc") == "a\\x0ab\\x09c"
    assert visible("a\nb\tc\x1b", keep="\n\t") == "a\nb\tc\\x1b"


def test_visible_stays_valid_inside_json() -> None:
    """JSON written raw (ensure_ascii=False) and then made visible still reads back the same."""
    record = {"name": "a\u202eb\u200b\U000e0041\x1b\x7f\x9b\udcff"[:-1]}
    text = visible(json.dumps(record, ensure_ascii=False))
    assert text.isascii() or all(not is_hidden(c) for c in text)
    assert json.loads(text) == record


@given(st.text())
@settings(max_examples=500, deadline=None)
def test_visible_output_has_nothing_hidden_and_is_idempotent(text: str) -> None:
    shown = visible(text)
    assert not any(is_hidden(char) for char in shown)
    assert visible(shown) == shown


def test_display_width_counts_wide_characters_twice() -> None:
    assert display_width("robot") == 5
    assert display_width("ロボット") == 8
    assert display_width("ＡＢ") == 4  # fullwidth
    assert display_width("e\u0301") == 1  # a combining accent takes no column


def test_fit_cuts_by_display_width() -> None:
    assert fit("abcdef", 4) == "abc…" and fit("abcdef", 1) == "…" and fit("abc", 3) == "abc"
    assert fit("ロボットの踊り", 6) == "ロボ…"  # 4 columns of text and the ellipsis
    assert fit("ロボットの踊り", 7) == "ロボッ…"
    assert fit("aロボ", 4) == "aロ…"
    assert fit("ロボ", 4) == "ロボ"
    assert fit("a" * 500, None) == "a" * 500
    assert fit("abc", 0) == ""


def test_fit_makes_the_line_visible_before_measuring() -> None:
    assert fit("\x1b]0;x\x07", None) == "\\x1b]0;x\\x07"
    assert fit("\x1b[2Jabcdef", 6) == "\\x1b[…"


@given(st.text(), st.integers(min_value=0, max_value=200))
@settings(max_examples=500, deadline=None)
def test_fit_never_exceeds_the_width(text: str, width: int) -> None:
    line = fit(text, width)
    assert display_width(line) <= width
    assert not any(is_hidden(char) for char in line)
    if display_width(visible(text)) <= width:
        assert line == visible(text)
    elif width:
        assert line.endswith("…")


def test_pad_pads_to_display_width() -> None:
    assert pad("ロボ", 6) == "ロボ  " and display_width(pad("ロボ", 6)) == 6
    assert pad("toolong", 3) == "toolong"


def test_every_hidden_category_is_escaped() -> None:
    for code in (0x00, 0x1B, 0x85, 0xAD, 0x061C, 0x200E, 0x200F, 0x202A, 0x2060, 0xFFF9):
        char = chr(code)
        assert unicodedata.category(char) in ("Cc", "Cf") and visible(char) != char
