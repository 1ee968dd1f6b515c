"""The process entry of `choreo` (the console script) and `python -m choreo`.

Kept tiny and import-light on purpose: it runs before anything else of choreo, so it is where
the process is made safe to run in. Two things cannot wait for the CLI's imports (argparse, the
library, serial, mcap: tens of milliseconds):

- Standard streams a caller closed (`choreo run show.yaml 2>&-`) are reopened onto /dev/null.
  Otherwise the next file opened (the run's log) would take descriptor 2, and whatever is
  written to "stderr" would land in the log.
- Ctrl-C, SIGTERM and SIGHUP are caught from here on (`choreo.signals.SignalGuard`). While
  choreo loads, a signal is only noted and acted on once it has loaded; from then on it
  interrupts the command (exit 130, "interrupted"), until `choreo run` installs its own
  handlers for the show.

- A traceback (a bug) is printed with control characters escaped, as all output is
  (`show_crashes_visibly`): the CLI's escaping streams are gone by the time Python prints it.

What remains is the interpreter's own start-up, before this module runs (docs/running.md, "Stopping").
The entry imports the CLI; nothing imports the entry (the signals live in `choreo.signals`).
"""

from __future__ import annotations

import os
import sys
import threading
from types import TracebackType

from choreo.signals import SignalGuard

STANDARD_FDS = (0, 1, 2)


def main() -> int:
    """Make the process safe, then hand over to the CLI."""
    reopen_closed_standard_fds()
    show_crashes_visibly()
    signals = SignalGuard()
    signals.install()
    from choreo.cli import main as cli_main  # a signal now is noted, and acted on in cli_main

    return cli_main(signals=signals)


def reopen_closed_standard_fds() -> None:
    """Give every closed descriptor 0, 1, 2 /dev/null, and Python a stream on it."""
    for fd in STANDARD_FDS:
        try:
            os.fstat(fd)
        except OSError:
            null = os.open(os.devnull, os.O_RDWR)
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
    for name, fd in (("stdin", 0), ("stdout", 1), ("stderr", 2)):
        if getattr(sys, name) is None:  # Python found the descriptor closed at start-up
            mode = "r" if fd == 0 else "w"
            stream = open(fd, mode, buffering=1 if fd else -1, closefd=False,  # noqa: SIM115 - the process's own stream, open for its life
                          errors="backslashreplace")
            setattr(sys, name, stream)


def show_crashes_visibly() -> None:
    """A traceback (a bug: every error choreo knows is one line) is printed with its control
    characters escaped like every other output: an exception's message may hold outside text
    (a file name, an OSC address), and the CLI's visible streams are gone by the time Python
    prints it. A thread's too."""
    sys.excepthook = _print_visibly
    threading.excepthook = lambda hook: _print_visibly(hook.exc_type, hook.exc_value, hook.exc_traceback,
                                                       hook.thread)


def _print_visibly(kind: type[BaseException] | None, value: BaseException | None, trace: TracebackType | None,
                   thread: threading.Thread | None = None) -> None:
    import traceback

    from choreo.textfit import visible

    if sys.stderr is None or kind is SystemExit:
        return
    where = f"Exception in thread {thread.name}:\n" if thread is not None else ""
    sys.stderr.write(visible(where + "".join(traceback.format_exception(kind, value, trace)), keep="\n"))
    sys.stderr.flush()


if __name__ == "__main__":
    sys.exit(main())
