"""The user's terminal: how wide it is, the one fact every human-facing output is fitted to
(`choreo.textfit.fit` does the cutting), and the streams every command prints through, which
show outside text safely (`choreo.textfit.visible`)."""

from __future__ import annotations

import os
import select
import sys
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import Any, TextIO

from choreo.numtext import whole_number
from choreo.textfit import fit, visible

# Where the output is not a terminal (a file, a pipe, a test) and COLUMNS does not say: lines
# that need a width (the timeline's bars) use this; lines that are data (log frames) stay whole.
UNKNOWN_COLUMNS = 100


def columns(stream: TextIO | None = None) -> int | None:
    """The terminal's width, `COLUMNS` where set (as pytest and pip honour it), else None (a
    terminal that says it has 0 columns, as a fresh pseudo-terminal does, does not know)."""
    stream = stream if stream is not None else sys.stdout
    try:
        if stream.isatty() and (width := os.get_terminal_size(stream.fileno()).columns) > 0:
            return width
    except (OSError, ValueError, AttributeError):
        pass
    given = whole_number(os.environ.get("COLUMNS", ""), max_digits=6)  # `²` or 5,000 digits: no width
    return given if given else None


def print_fitted(line: str, file: TextIO | None = None) -> None:
    """A line for a person on stdout (or `file`: stderr), cut to the terminal's width (with
    `…`) where it is one; to a file or a pipe, whole."""
    stream = file if file is not None else sys.stdout
    print(fit(line, columns(stream) if stream.isatty() else None), file=stream, flush=True)


class VisibleStream:
    """A text stream (stdout or stderr) that shows outside text safely: everything written
    through it is made `visible` (newlines kept), so no show name, file name, OSC address or
    log content printed by any command can drive the terminal, whichever line printed it.
    JSON stays JSON: the escapes it writes are JSON's own inside a string. Its `buffer` (where
    `choreo import` writes its UTF-8) shows the same text the same way. Everything else
    (fileno, isatty, flush) is the stream's own."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream

    def write(self, text: str) -> int:
        shown = visible(text, keep="\n")
        try:
            self.stream.write(shown)
        except UnicodeEncodeError as exc:
            # a console whose encoding lacks the characters (LC_ALL=C, PYTHONIOENCODING=ascii, a
            # cp1252 console): a show's Japanese name was a traceback; shown as \u escapes instead,
            # as Python shows them on stderr
            self.stream.write(shown.encode(exc.encoding, "backslashreplace").decode(exc.encoding))
        return len(text)

    @property
    def buffer(self) -> VisibleBytes:
        return VisibleBytes(self.stream.buffer)

    def writelines(self, lines: Iterable[str]) -> None:
        for line in lines:
            self.write(line)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.stream, name)


class VisibleBytes:
    """The bytes under a VisibleStream: UTF-8 text (as every command writes there), made
    visible like the text above it; a byte that is not UTF-8 is shown as its escape."""

    def __init__(self, stream: Any) -> None:
        self.stream = stream

    def write(self, data: bytes) -> int:
        text = bytes(data).decode("utf-8", errors="surrogateescape")
        self.stream.write(visible(text, keep="\n").encode("utf-8"))
        return len(data)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.stream, name)


def visible_stream(stream: TextIO) -> TextIO:
    """`stream`, writing visible text (as it is if it does already)."""
    return stream if isinstance(stream, VisibleStream) else VisibleStream(stream)  # type: ignore[return-value]  # a TextIO by duck typing: the rest passes through


def raw_stream(stream: TextIO) -> TextIO:
    """The stream under a VisibleStream: for what draws the terminal itself (the console's
    own escape sequences), having made its text visible first."""
    return stream.stream if isinstance(stream, VisibleStream) else stream


@contextmanager
def visible_output() -> Iterator[None]:
    """stdout and stderr as VisibleStreams inside the block, as they were after it."""
    saved = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = (visible_stream(s) if s is not None else s for s in saved)
    try:
        yield
    finally:
        sys.stdout, sys.stderr = saved


class StatusWriter:
    """Lines, and on a terminal a status line redrawn in place below them, written to a
    terminal or pipe by a thread of its own, so that whoever calls `line` or `redraw` (a
    robot's runner) never waits for the output: a terminal stopped with Ctrl-S, a pipe nobody
    reads, a slow ssh link. Lines wait in a bounded queue; past CAPACITY they are dropped and
    counted, and the count is said as soon as the output takes lines again. The status line is
    never queued: each draw takes the latest (`status(columns)`), every REDRAW_S, measuring the
    terminal's width at each draw (it may have been resized). On a terminal (`fit`) every line
    is cut to its width; every line is made visible either way."""

    CAPACITY = 100
    REDRAW_S = 0.25

    def __init__(self, out: TextIO, *, fit_lines: bool, status: Callable[[int], str] | None = None,
                 what: str = "progress line") -> None:
        self.out: TextIO | None = raw_stream(out)
        self.fit_lines = fit_lines
        self.status = status
        self.what = what  # what a line is, in the count of those dropped
        self.dropped_total = 0
        self._lock = threading.Lock()
        self._lines: deque[str] = deque()
        self._dropped = 0
        self._shown = False  # a status line is on screen
        self._closing = False
        self._wake = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="choreo-output", daemon=True)
        self._thread.start()

    def line(self, text: str) -> None:
        """Queue a line (never waits); dropped and counted if CAPACITY lines already wait."""
        with self._lock:
            if len(self._lines) >= self.CAPACITY:
                self._dropped += 1
                self.dropped_total += 1
            else:
                self._lines.append(text)
        self._wake.set()

    def redraw(self) -> None:
        """The status line changed: draw it now (never waits)."""
        self._wake.set()

    def close(self, wait_s: float = 1.0) -> None:
        """Write what waits, clear the status line, and stop; an output that takes nothing
        for `wait_s` is left behind (its thread ends with the process). Once: a second close
        (a run's `finally` after its end) does not wait for a stuck output again."""
        if self._closing:
            return
        self._closing = True
        self._wake.set()
        if self._thread is not threading.current_thread():
            self._thread.join(wait_s)

    def _loop(self) -> None:
        while self.out is not None:
            self._wake.wait(self.REDRAW_S if self.status is not None else None)
            self._wake.clear()
            closing = self._closing
            try:
                self._write(self._next(closing))
            except (OSError, ValueError):
                self.out = None  # the screen is not the show: a closed output silences it
            if closing:
                return

    def _next(self, closing: bool) -> str:
        """What to write now: the status line cleared, the waiting lines, the status again."""
        with self._lock:
            lines, dropped = list(self._lines), self._dropped
            self._lines.clear()
            self._dropped = 0
        if dropped:
            lines.append(f"({dropped} {self.what}{'s' if dropped != 1 else ''} not shown: "
                         "the output did not keep up)")
        width = (columns(self.out) or UNKNOWN_COLUMNS) if self.fit_lines else None
        text = "\r\x1b[K" if self._shown and (lines or self.status is not None) else ""
        self._shown = False
        text += "".join(fit(line, width) + "\n" for line in lines)
        status = self.status(width or UNKNOWN_COLUMNS) if self.status is not None and not closing else ""
        if status:
            text += visible(status)
            self._shown = True
        return text

    def _write(self, text: str) -> None:
        """All of `text`, by the descriptor where there is one (past any buffer: no flush to
        wait for elsewhere), else through the stream."""
        out = self.out
        if not text or out is None:
            return
        try:
            fd = out.fileno()
        except (OSError, ValueError, AttributeError):
            out.write(text)
            out.flush()
            return
        data = text.encode(getattr(out, "encoding", None) or "utf-8", errors="backslashreplace")
        while data:
            try:
                data = data[os.write(fd, data):]
            except BlockingIOError:  # a descriptor another process made non-blocking: wait for room
                select.select([], [fd], [], self.REDRAW_S)
