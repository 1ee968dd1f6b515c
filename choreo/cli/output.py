"""The one writer every command's output (stdout) goes through, so that a failed write is known.

A write that fails (a full disk, `/dev/full`, a device gone) is not the command's fault and
must not look like one of its reads: `choreo.cli.main` wraps stdout in `Output` for the whole
command, `--help` included, and whatever failed writing is reported once, as "cannot write the
output" with exit 2 (README, "Exit codes"), even if the command swallowed the exception. A
failed read of an input file is an `InputError` from `choreo.userfile`, never this.

A reader that went away (`choreo log frames LOG | head`) is not a failure: BrokenPipeError
passes through, and the CLI ends the command quietly.
"""

from __future__ import annotations

import os
from typing import Any

from choreo.errors import OutputError

OUTPUT_ERROR_EXIT = OutputError.exit_code


class Output:
    """A text stream (stdout) whose failed writes raise `OutputError` and are remembered."""

    def __init__(self, stream: Any) -> None:
        self.wrapped = stream
        self.failure: str | None = None  # what the system said when a write failed

    def write(self, text: str) -> int:
        return self._guard(self.wrapped.write, text)

    def writelines(self, lines: Any) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        self._guard(self.wrapped.flush)

    @property
    def buffer(self) -> _BinaryOutput:
        """The bytes under the text (`choreo import` writes its UTF-8 there), guarded alike."""
        return _BinaryOutput(self.wrapped.buffer, self)

    def __getattr__(self, name: str) -> Any:  # fileno, isatty, encoding...: the stream's own
        return getattr(self.wrapped, name)

    def _guard(self, call: Any, *args: Any) -> Any:
        if self.failure is not None:
            return 0  # already reported once: what follows goes nowhere
        try:
            return call(*args)
        except BrokenPipeError:
            raise
        except OSError as exc:
            self.failure = exc.strerror or str(exc)
            drop_output(self.wrapped)
            raise OutputError(self.message()) from None

    def message(self) -> str:
        return f"choreo: cannot write the output: {self.failure}"


class _BinaryOutput:
    def __init__(self, stream: Any, owner: Output) -> None:
        self._stream = stream
        self._owner = owner

    def write(self, data: bytes) -> int:
        return self._owner._guard(self._stream.write, data)

    def flush(self) -> None:
        self._owner._guard(self._stream.flush)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def drop_output(stream: Any) -> None:
    """Point the stream's descriptor at /dev/null: the interpreter's last flush must not fail
    again (and turn the exit status into 120) once the failure, or a closed pipe, is handled."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, stream.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass
