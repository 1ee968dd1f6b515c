"""Every `# type: ignore` and `# noqa` in choreo/ names what it silences and says why.

Why: a bare ignore silences every error on its line, today's and tomorrow's, and one without a
reason cannot be judged by the next reader (is the checker wrong, or the code?). mypy's
ignore-without-code catches the first half for `type: ignore`; nothing catches a missing reason,
nor a `noqa` without a code. Read with tokenize, so only real comments count, not strings.
"""

from __future__ import annotations

import io
import re
import tokenize

import pytest

from choreo_source import PACKAGE, source_files


_IGNORE = re.compile(r"type:\s*ignore(?P<codes>\[[^\]]*\])?")
_NOQA = re.compile(r"\bnoqa\b(?P<codes>:\s*[A-Z]+[0-9]+(?:\s*,\s*[A-Z]+[0-9]+)*)?", re.IGNORECASE)
_WORD = re.compile(r"[A-Za-z]{2,}")
_REASON_WORDS = 2  # "imported lazily", "the table's size is the point": one word is a label, not a reason


def silencing_problems(source: str) -> list[str]:
    """The ignores and noqas in `source` that lack an error code or a reason, as 'line N: what'."""
    problems: list[str] = []
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type != tokenize.COMMENT:
            continue
        line = token.start[0]
        found = [(match, "type: ignore") for match in _IGNORE.finditer(token.string)]
        found += [(match, "noqa") for match in _NOQA.finditer(token.string)]
        if not found:
            continue
        for match, kind in found:
            codes = match.group("codes")
            if not codes or not codes.strip("[]: ,"):
                problems.append(f"line {line}: `{kind}` names no error code")
        reason = token.string
        for match, _ in found:
            reason = reason.replace(match.group(0), " ")
        if len(_WORD.findall(reason)) < _REASON_WORDS:
            problems.append(f"line {line}: `{found[0][1]}` gives no reason")
    return problems


def test_every_ignore_and_noqa_in_the_package_names_its_code_and_says_why():
    found = []
    for path in source_files():
        for problem in silencing_problems(path.read_text(encoding="utf-8")):
            found.append(f"{path.relative_to(PACKAGE.parent)} {problem}")
    assert found == []


@pytest.mark.parametrize("line, problems", [
    ("x = f()  # type: ignore\n", ["line 1: `type: ignore` names no error code",
                                   "line 1: `type: ignore` gives no reason"]),
    ("x = f()  # type: ignore  # the stub is wrong about f\n", ["line 1: `type: ignore` names no error code"]),
    ("x = f()  # type: ignore[]  # the stub is wrong about f\n", ["line 1: `type: ignore` names no error code"]),
    ("x = f()  # type: ignore[arg-type]\n", ["line 1: `type: ignore` gives no reason"]),
    ("x = f()  # type: ignore[arg-type]  # stub\n", ["line 1: `type: ignore` gives no reason"]),
    ("import os  # noqa\n", ["line 1: `noqa` names no error code", "line 1: `noqa` gives no reason"]),
    ("import os  # noqa: F401\n", ["line 1: `noqa` gives no reason"]),
    ("import os  # NOQA - kept for the plugins\n", ["line 1: `noqa` names no error code"]),
    ("\n\nx = f()  # type: ignore[index]\n", ["line 3: `type: ignore` gives no reason"]),
])
def test_an_ignore_without_a_code_or_a_reason_is_found(line, problems):
    assert silencing_problems(line) == problems


@pytest.mark.parametrize("line", [
    "x = f()  # type: ignore[arg-type]  # the stub says str; bytes work too\n",
    "x = f()  # type: ignore[union-attr, index]  # set in start(), before any call\n",
    "import os  # noqa: F401 - re-exported for the plugins\n",
    "except Exception:  # noqa: BLE001 - the next key must still work\n",
    "x = f()  # the stub is wrong; type: ignore[arg-type]\n",
    "text = '# type: ignore and # noqa in a string are not comments'\n",
    "x = 1  # a plain comment\n",
])
def test_a_coded_ignore_with_a_reason_passes(line):
    assert silencing_problems(line) == []
