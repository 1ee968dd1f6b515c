"""The `choreo` command: parse arguments, call the library, print, map errors to exit codes.

Each command group lives in its own module here with a `register(subparsers)` that declares its
arguments and points at a handler. Handlers import the library lazily so that `choreo --help`
and `choreo validate` do not pay for serial, mcap or matplotlib.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING

from choreo import __version__
from choreo.cli.parser import ChoreoParser
from choreo.errors import ChoreoError

if TYPE_CHECKING:
    from choreo.__main__ import SignalGuard
    from choreo.clock import TimeSource

# Command modules, in the order `choreo --help` lists them.
COMMAND_MODULES = ("run", "show", "beats", "importer", "frames", "sim", "probe", "doctor", "log", "ports", "devices", "schema")


def build_parser() -> argparse.ArgumentParser:
    parser = ChoreoParser(
        prog="choreo",
        description="Play stored motions on a Kondo RCB-4 robot from a YAML show file, "
        "byte-exact and on time, and record every frame to an MCAP log.",
        epilog="Exit codes: 0 done; 2 bad show file or bad arguments (nothing was sent); "
        "3 the robot link failed; 130 interrupted (Ctrl-C, SIGTERM). "
        "`choreo COMMAND --help` tells more.",
    )
    parser.add_argument("--version", action="version", version=f"choreo {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    subparsers.required = True
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(f"choreo.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"choreo.cli.{name}":
                raise
            continue  # a command group not built yet
        module.register(subparsers)
    _remember_leaf_parsers(parser)
    return parser


def main(argv: Sequence[str] | None = None, *, signals: SignalGuard | None = None,
         time_source: TimeSource | None = None) -> int:
    """Run one command; every error and interruption becomes one message and an exit code here.

    `signals` (from the process entry, `choreo.__main__`) interrupts the command on Ctrl-C,
    SIGTERM or SIGHUP while it runs, and no longer once its outcome is being reported.
    `time_source`: the time a run or replay keeps (the machine's unless given; an embedding
    program or a test may pass `VirtualTime` to run shows on the in-process simulator at once).
    """
    try:
        return _command(argv, signals, time_source)
    except ChoreoError as exc:
        for line in exc.lines():
            print(line, file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader of our output went away (`choreo log frames LOG | head`): not an error.
        _drop_stdout()
        sys.stderr.close()
        return 0
    except OSError as exc:
        if not _is_output_error(exc):
            raise
        _drop_stdout()
        print(f"choreo: cannot write the output: {exc.strerror or exc}", file=sys.stderr)
        return OUTPUT_ERROR_EXIT


def _remember_leaf_parsers(parser: argparse.ArgumentParser) -> None:
    """Each command's own parser is in its parsed arguments (`args.parser`), so that arguments
    it does not take are reported with its usage, not the top-level one."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                sub.set_defaults(parser=sub)
                _remember_leaf_parsers(sub)


OUTPUT_ERROR_EXIT = 2  # like a log that cannot be written: the user's output, not the robot
_OUTPUT_ERRNOS = frozenset((errno.ENOSPC, errno.EIO, errno.EFBIG, getattr(errno, "EDQUOT", errno.ENOSPC)))


def _is_output_error(exc: OSError) -> bool:
    """A write or flush of stdout that failed (it names no file, unlike an open or a read)."""
    return exc.filename is None and exc.errno in _OUTPUT_ERRNOS


def _drop_stdout() -> None:
    """Point stdout at /dev/null: the interpreter's last flush must not fail a second time."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass


def _command(argv: Sequence[str] | None, signals: SignalGuard | None,
             time_source: TimeSource | None = None) -> int:
    if signals is not None:
        signals.arm()  # a signal that came while choreo loaded interrupts here
    try:
        parser = build_parser()
        args, extra = parser.parse_known_args(argv)
        if extra:
            getattr(args, "parser", parser).unknown_arguments(extra)
        args.time_source = time_source
        try:
            code = int(args.handler(args) or 0)
        except (ChoreoError, KeyboardInterrupt) as exc:
            from choreo.cli.jsonout import report_failure

            report_failure(args, exc)  # --json: the failure as JSON on stdout too
            raise
        sys.stdout.flush()  # a full output fails here, inside the one place errors are mapped
        return code
    finally:
        if signals is not None:
            signals.disarm()
