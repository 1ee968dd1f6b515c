"""The argument parser every `choreo` command uses: errors name the command they belong to and
suggest what the user probably meant."""

from __future__ import annotations

import argparse
import re
from collections.abc import Sequence
from typing import NoReturn

from choreo.errors import did_you_mean

_INVALID_CHOICE = re.compile(r"invalid choice: '(?P<given>[^']*)' \(choose from (?P<choices>.*)\)")


class ChoreoParser(argparse.ArgumentParser):
    """argparse, with a suggestion after an unknown command, choice or option, and the usage of
    the subcommand whose arguments were wrong (not the top-level one)."""

    def error(self, message: str) -> NoReturn:
        match = _INVALID_CHOICE.search(message)
        if match:
            choices = re.findall(r"'([^']*)'", match.group("choices"))
            message += did_you_mean(match.group("given"), choices)
        super().error(message)

    def unknown_arguments(self, extra: Sequence[str]) -> NoReturn:
        """Arguments no parser took: this parser's usage, with the closest option it has."""
        options = [o for action in self._actions for o in action.option_strings]
        first = next((a.split("=", 1)[0] for a in extra if a.startswith("-")), None)
        hint = did_you_mean(first, options) if first else ""
        self.error(f"unrecognized arguments: {' '.join(extra)}{hint}")
