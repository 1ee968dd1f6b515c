"""The stop signals, and the guard that turns them into an interruption for a command that is
not running a show.

A base module: the process entry (`choreo.__main__`) installs the guard before the CLI loads,
the CLI arms and disarms it around a command, and `choreo run` installs its own handlers for the
show over the same signals. Both read them here, so the entry point imports the CLI and nothing
imports the entry point.
"""

from __future__ import annotations

import signal

# Ctrl-C, `kill`, and a closed terminal or SSH session: the same stop.
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


class SignalGuard:
    """The stop signals for a command that is not running a show.

    Noted only (not armed) while choreo loads and once the command is over, so that neither an
    import nor the last lines are cut short; armed, the first signal interrupts the command
    with KeyboardInterrupt, which the CLI maps to exit 130, and later ones are only noted.
    """

    def __init__(self) -> None:
        self.armed = False
        self.signalled: int | None = None

    def install(self) -> None:
        for signum in STOP_SIGNALS:
            signal.signal(signum, self._handle)

    def _handle(self, signum: int, frame: object) -> None:
        first = self.signalled is None
        self.signalled = signum
        if first and self.armed:
            self.armed = False
            raise KeyboardInterrupt

    def arm(self) -> None:
        """From now on a signal interrupts the command; one that came while loading does now."""
        if self.signalled is not None:
            raise KeyboardInterrupt
        self.armed = True

    def disarm(self) -> None:
        self.armed = False
