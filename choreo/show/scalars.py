"""A YAML scalar's value, read the way editors read it, and what a show file may not hold in one.

PyYAML reads YAML 1.1, where `010` is 8 (octal), `1:30` is 90 (base 60) and `yes` is true,
while editors and the YAML 1.2 language server read 10, text and text: the same file would mean
two things, and a wrong slot is the worst error a show runner can make. So plain scalars are
resolved here by YAML 1.2's core schema, and a whole number with a leading zero is refused as
ambiguous. Tagged scalars are accepted for plain data tags only (no tag constructs an object),
and numbers are bounded: Python would not even turn one of more than 4,300 digits into text.

YAML 1.2 has two line breaks, LF and CR; PyYAML (YAML 1.1) also breaks lines at NEL, LS and PS,
which shifts every line number after one (editors do not count them) and ends a comment in the
middle. The reader hides them as stand-ins from Unicode's private use area before parsing
(`HIDE_BREAKS`); every text value puts them back (`restore_breaks`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import Any

import yaml

from choreo.show.report import JsonPath, Mark, Report

STR = "tag:yaml.org,2002:str"
INT = "tag:yaml.org,2002:int"
FLOAT = "tag:yaml.org,2002:float"
BOOL = "tag:yaml.org,2002:bool"
NULL = "tag:yaml.org,2002:null"
TIMESTAMP = "tag:yaml.org,2002:timestamp"
MAP = "tag:yaml.org,2002:map"
SEQ = "tag:yaml.org,2002:seq"
_STANDARD = "tag:yaml.org,2002:"

# YAML 1.2 core schema (https://yaml.org/spec/1.2.2/#1032-tag-resolution).
_CORE_NULL = re.compile(r"~|null|Null|NULL|")
_CORE_TRUE = re.compile(r"true|True|TRUE")
_CORE_FALSE = re.compile(r"false|False|FALSE")
_CORE_INT = re.compile(r"[-+]?[0-9]+")
_CORE_OCT = re.compile(r"0o[0-7]+")
_CORE_HEX = re.compile(r"0x[0-9a-fA-F]+")
_CORE_FLOAT = re.compile(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?")
_CORE_INF = re.compile(r"[-+]?\.(inf|Inf|INF)")
_CORE_NAN = re.compile(r"\.(nan|NaN|NAN)")
_LEADING_ZERO = re.compile(r"[-+]?0[0-9]+")
_WHOLE_NUMBER = re.compile(r"[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+")
_NUMBER_DIGITS_MAX = 30  # characters of a whole number; a show's largest values have 6
_NUMBER_BITS_MAX = 100  # and its value (a tagged `!!int` is converted by PyYAML, not here)

BREAKS_1_1 = {"\x85": "\ue085", "\u2028": "\ue028", "\u2029": "\ue029"}  # YAML 1.1's extra breaks: stand-ins
HIDE_BREAKS = str.maketrans(BREAKS_1_1)
_SHOW_BREAKS = str.maketrans({v: k for k, v in BREAKS_1_1.items()})


def restore_breaks(text: str) -> str:
    """Text as the file wrote it: the stand-ins of YAML 1.1's extra line breaks put back."""
    return text.translate(_SHOW_BREAKS)


def tag_text(tag: str) -> str:
    """A tag as it is written in YAML: `!!python/object`, not `tag:yaml.org,2002:python/object`."""
    return "!!" + tag[len(_STANDARD):] if tag.startswith(_STANDARD) else tag


class Scalars:
    """Reads scalar events into values, reporting (and reading as None) what it refuses."""

    def __init__(self, report: Report) -> None:
        self.report = report
        constructor = yaml.constructor.SafeConstructor()
        self._construct: dict[str, Callable[[yaml.ScalarNode], Any]] = {
            STR: constructor.construct_yaml_str,
            INT: constructor.construct_yaml_int,
            FLOAT: constructor.construct_yaml_float,
            BOOL: constructor.construct_yaml_bool,
            NULL: constructor.construct_yaml_null,
            TIMESTAMP: lambda n: n.value,  # a date-like name or label: keep the text as written
        }

    def value(self, event: yaml.ScalarEvent, path: JsonPath, mark: Mark) -> Any:
        """The scalar's value by YAML's core rules; only plain data tags are accepted."""
        tag = event.tag
        if tag is None and event.implicit[0]:  # plain: YAML 1.2's core schema, as editors read it
            return self._core(event, path, mark)
        if tag in (None, "!"):  # quoted, or the non-specific `!`: a string
            return restore_breaks(event.value)
        return self._tagged(event, tag, path, mark)

    def _tagged(self, event: yaml.ScalarEvent, tag: str, path: JsonPath, mark: Mark) -> Any:
        """A scalar with a tag of YAML's own (`!!int 3`), converted as PyYAML does."""
        construct = self._construct.get(tag)
        if construct is None:
            self.report.add(mark, path, f"tag {tag_text(tag)} is not allowed in a show file: remove it")
            return None
        try:
            value = construct(yaml.ScalarNode(tag, event.value))
        except (ValueError, KeyError, TypeError, ArithmeticError, yaml.YAMLError):
            shown = event.value if len(event.value) <= 40 else event.value[:40] + "…"
            self.report.add(mark, path, f"cannot read {shown!r} as {tag.rsplit(':', 1)[-1]}")
            return None
        return self._bounded(value, event, path, mark)

    def _core(self, event: yaml.ScalarEvent, path: JsonPath, mark: Mark) -> Any:
        """A plain scalar by YAML 1.2's core schema; a whole number with a leading zero is refused."""
        text = event.value
        if len(text) > _NUMBER_DIGITS_MAX and _WHOLE_NUMBER.fullmatch(text):
            self._too_long_number(event, path, mark)
            return None
        if _LEADING_ZERO.fullmatch(text):
            self.report.add(mark, path, _leading_zero_problem(text))
            return None
        value = core_value(text)
        if isinstance(value, str):
            return restore_breaks(value)
        return None if self._nan(value, path, mark) else value

    def _nan(self, value: Any, path: JsonPath, mark: Mark) -> bool:
        """True (and reported) if the value is not a number: no field of a show takes one."""
        if isinstance(value, float) and math.isnan(value):
            self.report.add(mark, path, "not-a-number (.nan) is not allowed here")
            return True
        return False

    def _bounded(self, value: Any, event: yaml.ScalarEvent, path: JsonPath, mark: Mark) -> Any:
        """A tagged scalar's value, unless it is .nan or a whole number past any a show holds."""
        if self._nan(value, path, mark):
            return None
        if isinstance(value, int) and abs(value).bit_length() > _NUMBER_BITS_MAX:
            self._too_long_number(event, path, mark)
            return None
        return value

    def _too_long_number(self, event: yaml.ScalarEvent, path: JsonPath, mark: Mark) -> None:
        """A whole number far past any value a show holds: Python would not even turn one of more
        than 4,300 digits into text (a ValueError in the middle of a message)."""
        self.report.add(mark, path, f"a whole number {len(event.value)} characters long "
                        f"({event.value[:12]}…): no value in a show needs more than {_NUMBER_DIGITS_MAX}")


def _leading_zero_problem(text: str) -> str:
    """`010`: octal 8 to PyYAML, decimal 10 to an editor; say both."""
    digits = text.lstrip("+-")
    sign = "-" if text.startswith("-") else ""
    octal = int(digits, 8) if set(digits) <= set("01234567") else "not octal"
    return (f"{text} is ambiguous: YAML 1.1 reads a leading zero as octal ({sign}{octal}), "
            f"YAML 1.2 as decimal ({sign}{int(digits, 10)}): write it without the leading zero")


def core_value(text: str) -> Any:
    """A plain scalar's value by YAML 1.2's core schema (text if no other type matches)."""
    if _CORE_NULL.fullmatch(text):
        return None
    if _CORE_TRUE.fullmatch(text) or _CORE_FALSE.fullmatch(text):
        return text.lower() == "true"
    if _CORE_INT.fullmatch(text):
        return int(text, 10)
    if _CORE_OCT.fullmatch(text):
        return int(text[2:], 8)
    if _CORE_HEX.fullmatch(text):
        return int(text[2:], 16)
    if _CORE_FLOAT.fullmatch(text):
        return float(text)
    if _CORE_INF.fullmatch(text):
        return -math.inf if text.startswith("-") else math.inf
    if _CORE_NAN.fullmatch(text):
        return math.nan
    return text
