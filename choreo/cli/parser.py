"""The argument parser every `choreo` command uses: errors name the command they belong to and
suggest what the user probably meant."""

from __future__ import annotations

import argparse
import re
from collections.abc import Sequence
from typing import NoReturn

from choreo.errors import UsageError, bounded, did_you_mean, one_line
from choreo.textfit import fit

_INVALID_CHOICE = re.compile(r"invalid choice: '(?P<given>[^']*)' \(choose from (?P<choices>.*)\)")
_QUOTED = re.compile(r"'([^']{%d,})'" % 200)  # a value given, quoted in argparse's message
_QUOTED_KEPT = 80  # characters of an over-long value the message keeps


class FittedHelpFormatter(argparse.HelpFormatter):
    """argparse's help, every line of it within the terminal's width: argparse wraps the text,
    but not a usage line indented under a long command, nor an option's choices (`--format
    {csv,json,jsonl,parquet}`): those are cut with `…` on a narrow terminal."""

    def format_help(self) -> str:
        columns = self._width + 2  # argparse leaves 2 of the terminal's columns
        return "\n".join(fit(line, columns) for line in super().format_help().split("\n"))


class ParagraphHelpFormatter(FittedHelpFormatter):
    """Help whose description and epilog keep their paragraphs (a blank line apart), each
    wrapped to the terminal's width as argparse wraps the rest: written out by hand, their
    lines ran past a narrower terminal's edge (`choreo sim --help` at 80 columns)."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        return "\n\n".join(super(ParagraphHelpFormatter, self)._fill_text(paragraph, width, indent)
                             for paragraph in text.split("\n\n"))


class ChoreoParser(argparse.ArgumentParser):
    """argparse, with a suggestion after an unknown command, choice or option, and the usage of
    the subcommand whose arguments were wrong (not the top-level one)."""

    _given: Sequence[str] = ()

    def __init__(self, *args, **kwargs) -> None:  # argparse's own arguments, passed on
        kwargs.setdefault("formatter_class", FittedHelpFormatter)
        super().__init__(*args, **kwargs)

    def parse_known_args(self, args=None, namespace=None):  # argparse's own arguments, passed on
        """Remembered, so that a bad argument of a command asked for JSON is answered in JSON."""
        self._given = list(args) if args is not None else []
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> NoReturn:
        match = _INVALID_CHOICE.search(message)
        if match:
            choices = re.findall(r"'([^']*)'", match.group("choices"))
            message += did_you_mean(match.group("given")[:_QUOTED_KEPT], choices)
        message = bounded(one_line(_QUOTED.sub(_cut_value, message)))
        if self._wants_json():
            from choreo.cli.jsonout import error_record, print_json

            print_json(error_record(UsageError(f"{self.prog}: {message}")))
        super().error(message)

    def _wants_json(self) -> bool:
        """`--json` given to a command whose --json is a flag (not `log export --json FILE`)."""
        flag = any(isinstance(a, argparse._StoreTrueAction) and "--json" in a.option_strings for a in self._actions)
        return flag and "--json" in self._given

    def unknown_arguments(self, extra: Sequence[str]) -> NoReturn:
        """Arguments no parser took: this parser's usage, with the closest option it has."""
        options = [o for action in self._actions for o in action.option_strings]
        first = next((a.split("=", 1)[0] for a in extra if a.startswith("-")), None)
        hint = did_you_mean(first, options) if first else ""
        self.error(f"unrecognized arguments: {' '.join(extra)}{hint}")


def _cut_value(match: re.Match[str]) -> str:
    """A value given to an option, as an error quotes it, cut (argparse quotes it whole: a
    100 KB `--kind` printed 100 KB, and the choices after it were lost in a cut of the line)."""
    value = match.group(1)
    return f"'{value[:_QUOTED_KEPT]}…' ({len(value) - _QUOTED_KEPT} more characters)"
