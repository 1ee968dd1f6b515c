"""What a command given `--json` prints on stdout when it fails: one JSON object of one shape.

A script that asked for JSON reads stdout and nothing else, so a failure must be JSON too, or
the script sees an empty string where it expects an object. Every command's failure object is
`{"ok": false, "exit": CODE, "error": "the message"}` (a bad show file adds `problems`, each
located), the same keys `run --json` puts in its result. stderr says the same as without --json.
`choreo.cli.main` prints it for every command whose `--json` is a flag (`args.json is True`),
unless the command's parser sets `own_json_failure` (it prints its own record, as `run` does).
"""

from __future__ import annotations

import argparse
import contextlib
import json

from choreo.errors import ChoreoError, Interrupted, Problem, ShowError


def problem_record(problem: Problem) -> dict:
    """One located problem of a show file."""
    return {"file": problem.file, "line": problem.line, "column": problem.column,
            "path": problem.path, "message": problem.message}


def error_record(exc: ChoreoError) -> dict:
    """The failure object: what went wrong, and the exit status the command ends with."""
    record: dict = {"ok": False, "exit": exc.exit_code, "error": " / ".join(exc.lines())}
    if isinstance(exc, ShowError):
        record["problems"] = [problem_record(p) for p in exc.problems]
    return record


def print_json(record: dict) -> None:
    """One object, one line, flushed: a reader that went away is not an error of ours."""
    with contextlib.suppress(BrokenPipeError):
        print(json.dumps(record, ensure_ascii=False), flush=True)


def report_failure(args: argparse.Namespace, exc: BaseException) -> None:
    """Print the failure object if this command was asked for JSON and does not print its own."""
    if getattr(args, "json", None) is not True or getattr(args, "own_json_failure", False):
        return
    if isinstance(exc, KeyboardInterrupt):
        exc = Interrupted("interrupted")
    if isinstance(exc, ChoreoError):
        print_json(error_record(exc))
