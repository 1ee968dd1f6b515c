"""The `choreo` command: parse arguments, call the library, print, map errors to exit codes.

Each command group lives in its own module here with a `register(subparsers)` that declares its
arguments and points at a handler. Handlers import the library lazily so that `choreo --help`
and `choreo validate` do not pay for serial, mcap or matplotlib.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from contextlib import suppress
from collections.abc import Sequence
from typing import TYPE_CHECKING, cast

from choreo import __version__
from choreo.cli.parser import ChoreoParser
from choreo.cli.terminal import visible_output
from choreo.cli.output import OUTPUT_ERROR_EXIT, Output, drop_output
from choreo.errors import ChoreoError, Interrupted, LinkError, OutputError, UsageError

if TYPE_CHECKING:
    from choreo.clock import TimeSource
    from choreo.signals import SignalGuard

# Command modules, in the order `choreo --help` lists them.
COMMAND_MODULES = ("run", "show", "beats", "importer", "frames", "sim", "probe", "doctor", "log", "ports", "devices",
                   "schema")


def build_parser() -> argparse.ArgumentParser:
    parser = ChoreoParser(
        prog="choreo",
        description="Play stored motions on a Kondo RCB-4 robot from a YAML show file, "
        "byte-exact and on time, and record every frame to an MCAP log.",
        epilog=f"Exit codes: 0 done; {UsageError.exit_code} bad show file or bad arguments (nothing was sent); "
        f"{LinkError.exit_code} the robot link failed; {Interrupted.exit_code} interrupted (Ctrl-C, SIGTERM). "
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

    `signals` (installed by the process entry, `choreo.__main__`) interrupts the command on Ctrl-C,
    SIGTERM or SIGHUP while it runs, and no longer once its outcome is being reported.
    `time_source`: the time a run or replay keeps (the machine's unless given; an embedding
    program or a test may pass `VirtualTime` to run shows on the in-process simulator at once).
    """
    with visible_output():  # every line printed, a show's names and error messages too, made visible
        output = Output(sys.stdout)  # every command's output: a failed write is known and reported
        sys.stdout = output
        try:
            code = _outcome(argv, signals, time_source, output)
        finally:
            sys.stdout = output.wrapped
        if output.failure is not None:  # reported here, even if a command swallowed the exception
            _tell(output.message())
            return code or OUTPUT_ERROR_EXIT  # a command that failed anyway keeps its own status
        return code


def _outcome(argv: Sequence[str] | None, signals: SignalGuard | None, time_source: TimeSource | None,
             output: Output) -> int:
    """The command's exit status, every error and interruption printed as one message."""
    try:
        code = _command(argv, signals, time_source)
        output.flush()  # a full output fails here, inside the one place errors are mapped
        return code
    except OutputError:
        return OUTPUT_ERROR_EXIT  # `main` says it, once
    except SystemExit:  # argparse's --help, --version and usage errors: their text must get out too
        try:
            output.flush()
        except OutputError:
            return OUTPUT_ERROR_EXIT
        raise
    except ChoreoError as exc:
        for line in exc.lines():
            _tell(line)
        return exc.exit_code
    except KeyboardInterrupt:
        _tell("interrupted")
        return Interrupted.exit_code
    except BrokenPipeError:
        # The reader of our output went away (`choreo log frames LOG | head`): not an error.
        drop_output(output.wrapped)
        sys.stderr.close()
        return 0
    except OSError as exc:
        # Every read of a user's file and every write of the output says which it was (an
        # InputError, an OutputError); anything else the system refused is still one line.
        _tell(f"choreo: {exc.strerror or exc}" + (f": {exc.filename}" if exc.filename else ""))
        return 2


def _tell(line: str) -> None:
    """An error line on stderr, if stderr takes it: a stderr that cannot be written (`2>/dev/full`)
    has no one to tell, and its failure must not become the exit status (a traceback's 1, where
    the error's own status was due)."""
    with suppress(OSError, ValueError):
        print(line, file=sys.stderr)


def _remember_leaf_parsers(parser: argparse.ArgumentParser) -> None:
    """Each command's own parser is in its parsed arguments (`args.parser`), so that arguments
    it does not take are reported with its usage, not the top-level one."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                sub.set_defaults(parser=sub)
                _remember_leaf_parsers(sub)


def _command(argv: Sequence[str] | None, signals: SignalGuard | None,
             time_source: TimeSource | None = None) -> int:
    if signals is not None:
        signals.arm()  # a signal that came while choreo loaded interrupts here
    try:
        parser = build_parser()
        # the time a run keeps travels with the arguments: every handler is given only those
        args, extra = parser.parse_known_args(argv, namespace=argparse.Namespace(time_source=time_source))
        if extra:
            # the subcommand's own parser (see `_remember_leaf_parsers`): argparse makes it of its parent's class
            leaf = cast(ChoreoParser, getattr(args, "parser", parser))
            leaf.unknown_arguments(extra)
        try:
            code = int(args.handler(args) or 0)
        except (ChoreoError, KeyboardInterrupt) as exc:
            from choreo.cli.jsonout import report_failure

            # --json: the failure as JSON on stdout too; an output that fails is said by `main`,
            # and the failure itself is still told on stderr, with its exit status
            with suppress(OutputError):
                report_failure(args, exc)
            raise
        return code
    finally:
        if signals is not None:
            signals.disarm()
