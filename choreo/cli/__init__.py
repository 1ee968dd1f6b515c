"""The `choreo` command: parse arguments, call the library, print, map errors to exit codes.

Each command group lives in its own module here with a `register(subparsers)` that declares its
arguments and points at a handler. Handlers import the library lazily so that `choreo --help`
and `choreo validate` do not pay for serial, mcap or matplotlib.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from choreo import __version__
from choreo.errors import ChoreoError

# Command modules, in the order `choreo --help` lists them.
COMMAND_MODULES = ("run", "show", "importer", "frames", "sim", "log", "ports")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
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
    return parser



def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args) or 0)
    except ChoreoError as exc:
        for line in exc.lines():
            print(line, file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader of our output went away (`choreo log frames LOG | head`): not an error.
        sys.stderr.close()
        return 0
