"""One family of errors, each carrying the exit code the CLI maps it to.

Library code raises these with messages a user can act on; only the CLI turns them into a
printed line and an exit status, in one place (`choreo.cli.main`).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from dataclasses import dataclass

from choreo.textfit import visible


def did_you_mean(given: str, known: Iterable[str]) -> str:
    """`: did you mean 'summary'?` when one of `known` is close to `given`, else ''."""
    close = closest(given, known)
    return f": did you mean '{close}'?" if close else ""


def closest(given: str, known: Iterable[str]) -> str | None:
    """The one of `known` closest to `given`, if close enough to be a slip of the fingers; the
    caller chooses what may be suggested (OSC never offers a GO for a typo)."""
    close = difflib.get_close_matches(given, list(known), n=1, cutoff=0.6)
    return close[0] if close else None


MESSAGE_CHARS = 1000  # an error line printed at most this long: a value from outside may be megabytes


def one_line(text: str) -> str:
    """`text` with its line breaks (and every other control or invisible character) escaped."""
    return visible(text)


def bounded(line: str) -> str:
    """An error line cut to MESSAGE_CHARS, saying how much was left out: `--host` given 100 KB
    of name printed 200 KB (its text escaped), and any option or file's text could."""
    if len(line) <= MESSAGE_CHARS:
        return line
    return f"{line[:MESSAGE_CHARS]}… ({len(line) - MESSAGE_CHARS} more characters)"


class ChoreoError(Exception):
    """Base of every error choreo reports to its user."""

    exit_code = 1

    def lines(self) -> list[str]:
        """The message as the one-problem-a-line text the CLI prints: one line, whatever a name
        from outside put in it (a port or file named with a line break, a log's text)."""
        return [bounded(one_line(str(self)))]


class UsageError(ChoreoError):
    """Bad arguments: nothing was sent to the robot."""

    exit_code = 2


class InputError(UsageError):
    """A file the user named that cannot be read as what it should be (`choreo.userfile`)."""

    def __init__(self, path: str, reason: str) -> None:
        self.path = path
        self.reason = reason
        super().__init__(f"{one_line(path)}: {reason}")


class OutputError(ChoreoError):
    """The command's output (stdout) cannot be written: a full disk, a closed device."""

    exit_code = 2


class MotionRangeError(UsageError, ValueError):
    """A motion number outside the controller's slots 0..119."""


@dataclass(frozen=True)
class Problem:
    """One located problem in a show file: `FILE:LINE:COL: PATH: WHAT` (1-based line/col)."""

    file: str
    line: int
    column: int
    path: str
    message: str

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}:{self.column}" if self.line else self.file
        return f"{where}: {self.path}: {self.message}" if self.path else f"{where}: {self.message}"


class ShowError(ChoreoError):
    """A show file that cannot be run, with every problem found in it."""

    exit_code = 2

    def __init__(self, problems: list[Problem]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems))

    def lines(self) -> list[str]:
        return [bounded(one_line(str(p))) for p in self.problems]


class LinkError(ChoreoError):
    """The robot link failed: port would not open, no reply or NAK after retries, port lost."""

    exit_code = 3


class LogError(ChoreoError):
    """A run log that cannot be written, or read back."""

    exit_code = 2


class Interrupted(ChoreoError):
    """The user stopped the run (Ctrl-C or SIGTERM)."""

    exit_code = 130
