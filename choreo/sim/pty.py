"""Serve a `SimBoard` on a pseudo-terminal, so any serial program can talk to it as to a board.

The server holds both ends of the pty: it reads and writes the master, and keeps the slave open
itself, so that a client closing its end (and opening it again) does not hang up the master.
It is a single loop around `select`: bytes read from the master go onto the `Line` at the time
they were read, reply bytes are written to the master when their scheduled time comes (wire
time and reply delay emulated), and a gap longer than `gap_s` between a client's bytes drops a
partial frame (20 ms by default: a pty and a scheduler are far less punctual than a UART).

Line settings: the server reads the client's settings through the slave (baud, stop bits, odd
parity; data bits and parity enable too where the platform keeps them: Linux's pty driver
forces CS8 and clears PARENB, so there even parity cannot be told from none) and, like a real
board, does not answer a client whose settings it cannot read.

Reopening: Debian's and Ubuntu's C library refuses (EINVAL) a tcsetattr on a pty whose only
change is even parity, which is what pyserial sends when it opens a pty already set up by an
earlier client; the server keeps the pty "re-armed" so that never happens (see `rearm`).

`stop()` is safe to call from a signal handler: it writes one byte to a pipe the loop watches.
"""

from __future__ import annotations

import array
import contextlib
import errno
import os
import select
import termios
import time
import tty
from enum import Enum

from choreo.sim.board import SimBoard
from choreo.sim.line import PTY_GAP_S, Line, LineSettings

_TCGETS2 = 0x802C542A  # Linux: termios2 with the actual speeds (custom bauds use BOTHER)
_TCSETS2 = 0x402C542B
_BOTHER = 0o010000
_MAX_WAIT_S = 0.1  # idle tick: re-arm the pty for the next client (see rearm)
# termios speed codes (B9600, B115200, ...) -> baud; BOTHER is not among them.
_SPEEDS = {
    getattr(termios, name): int(name[1:])
    for name in dir(termios)
    if name.startswith("B") and name[1:].isdigit() and getattr(termios, name) != _BOTHER
}


class ServeEnd(str, Enum):
    """Why `serve` returned."""

    STOPPED = "stopped"  # stop() was called (SIGINT, SIGTERM)
    LOST = "lost"  # a `lose` fault: the pty was closed under the client


class PtyServer:
    """A simulated board on a pseudo-terminal. Use as a context manager, or open/serve/close."""

    def __init__(self, board: SimBoard, gap_s: float = PTY_GAP_S, check_settings: bool = True,
                 latency_s: float = 0.0) -> None:
        self.board = board
        self.line = Line(board, gap_s, latency_s)
        self.check_settings = check_settings
        self.path: str | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._wake: tuple[int, int] | None = None
        self._parity_visible = False
        self._unsent = bytearray()

    def __enter__(self) -> PtyServer:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self) -> str:
        """Create the pty (raw, at the board's settings) and return the slave's device path."""
        master, slave = os.openpty()
        self._master, self._slave = master, slave
        tty.setraw(slave)
        _set_line(slave, self.board.baud)
        self._parity_visible = _parity_is_visible(slave)
        rearm(slave)
        os.set_blocking(master, False)
        wake_r, wake_w = os.pipe()
        os.set_blocking(wake_r, False)
        os.set_blocking(wake_w, False)
        self._wake = (wake_r, wake_w)
        self.path = os.ttyname(slave)
        return self.path

    def stop(self) -> None:
        """Ask `serve` to return (async-signal-safe: one write to a pipe)."""
        if self._wake is not None:
            with contextlib.suppress(OSError):  # pipe full: a stop is already pending
                os.write(self._wake[1], b"x")

    def close(self) -> None:
        for fd in (self._master, self._slave, *(self._wake or ())):
            if fd is not None:
                with contextlib.suppress(OSError):  # already closed: nothing left to release
                    os.close(fd)
        self._master = self._slave = self._wake = None

    def client_settings(self) -> LineSettings | None:
        """The settings the client has set on the pty, as far as the platform shows them."""
        if self._slave is None:
            return None
        return read_settings(self._slave, parity_visible=self._parity_visible)

    def serve(self) -> ServeEnd:
        """Answer the client until `stop()` or a `lose` fault (which closes the pty)."""
        if self._master is None or self._wake is None:
            raise RuntimeError("PtyServer.serve() before open()")
        master, wake_r = self._master, self._wake[0]
        while True:
            now = time.monotonic()
            self.line.poll(now)  # first: what a gap closed happened before `now`
            self.board.advance(now)  # a motion that has ended is journalled (shown by -v) on time
            self._unsent += self.line.take(now, 1 << 16)
            self._flush(master)
            if self.board.lost:
                self.close()
                return ServeEnd.LOST
            if self._slave is not None:
                rearm(self._slave)  # a client may have just configured the port
            readable, _, _ = select.select(
                [master, wake_r], [master] if self._unsent else [], [], self._timeout(now)
            )
            if wake_r in readable:
                _drain(wake_r)
                return ServeEnd.STOPPED
            if master in readable:
                self._receive(master)

    def _timeout(self, now: float) -> float:
        times = [t for t in (self.line.next_event(), self.board.motion_end()) if t is not None]
        return min(max(min(times) - now, 0.0), _MAX_WAIT_S) if times else _MAX_WAIT_S

    def _receive(self, master: int) -> None:
        try:
            data = os.read(master, 4096)
        except BlockingIOError:
            return
        except OSError as exc:
            if exc.errno != errno.EIO:  # EIO: no client has the slave open; we hold it, so rare
                raise
            time.sleep(0.01)
            return
        now = time.monotonic()
        if self.check_settings:
            self.line.settings = self.client_settings()
        self.line.send(data, now)

    def _flush(self, master: int) -> None:
        if not self._unsent:
            return
        try:
            written = os.write(master, bytes(self._unsent))
        except BlockingIOError:
            return  # the client is not reading; its buffer is full
        del self._unsent[:written]


def read_settings(fd: int, parity_visible: bool = True) -> LineSettings | None:
    """A terminal's baud, data bits, parity and stop bits; None where they cannot be read.

    With `parity_visible` False (a Linux pty), data bits and parity enable are reported as
    unknown; odd parity (PARODD) and stop bits are still seen.
    """
    try:
        _, _, cflag, _, _, ospeed, _ = termios.tcgetattr(fd)
    except termios.error:
        return None
    baud = _speed(fd, ospeed)
    odd = bool(cflag & termios.PARODD)
    if parity_visible:
        bytesize = {termios.CS5: 5, termios.CS6: 6, termios.CS7: 7, termios.CS8: 8}[cflag & termios.CSIZE]
        parity: str | None = ("O" if odd else "E") if cflag & termios.PARENB else "N"
    else:
        bytesize, parity = None, "O" if odd else None
    stopbits = 2.0 if cflag & termios.CSTOPB else 1.0
    return LineSettings(baud, bytesize, parity, stopbits)


def _speed(fd: int, code: int) -> int | None:
    """The baud of a termios speed code; custom speeds through Linux's termios2."""
    if code in _SPEEDS:
        return _SPEEDS[code]
    return _termios2_speed(fd)


def _termios2_speed(fd: int) -> int | None:
    buf = _termios2(fd)
    if buf is None:
        return None
    return int(buf[10]) or None


def _set_line(fd: int, baud: int) -> None:
    """Start the pty at the board's settings, so a client that sets nothing is understood.

    Through termios2 where there is one (exact custom speeds, and no C library second-guessing
    the result); a plain tcsetattr otherwise, whose refusal is harmless (clients set their own).
    """
    buf = _termios2(fd)
    if buf is not None:
        buf[2] = (buf[2] & ~(termios.CSIZE | termios.PARODD | termios.CSTOPB | termios.CBAUD)) | (
            termios.CS8 | termios.PARENB | _BOTHER
        )
        buf[9] = buf[10] = baud
        if _set_termios2(fd, buf):
            return
    try:
        attrs = termios.tcgetattr(fd)
        attrs[2] = (attrs[2] & ~(termios.CSIZE | termios.PARODD | termios.CSTOPB)) | termios.CS8 | termios.PARENB
        code = getattr(termios, f"B{baud}", None)
        if code is not None:
            attrs[4] = attrs[5] = code
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except termios.error:
        pass


def rearm(fd: int) -> None:
    """Set IGNBRK on the pty, so that the next client's tcsetattr always changes something.

    Debian's and Ubuntu's C library reads the settings back after tcsetattr and fails with
    EINVAL when nothing but bits the pty driver forces (CS8, CREAD, no PARENB) would change:
    pyserial opening an already-configured pty with even parity hits exactly that (pyserial
    issue 196), so a second `choreo run` on the same `choreo sim` would fail to open. pyserial
    and cfmakeraw clear IGNBRK, which means nothing on a pty (no line, no breaks), so with it set
    every client configuration is a real change. The server re-sets it whenever it finds it
    cleared; a client reconfiguring twice within microseconds could race with that, nothing else.
    """
    buf = _termios2(fd)
    if buf is not None:
        if not buf[0] & termios.IGNBRK:
            buf[0] |= termios.IGNBRK
            _set_termios2(fd, buf)
        return
    try:
        attrs = termios.tcgetattr(fd)
        if not attrs[0] & termios.IGNBRK:
            attrs[0] |= termios.IGNBRK
            termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except termios.error:
        pass


def _termios2(fd: int) -> array.array | None:
    """Linux's termios2 (flags and exact speeds) as pyserial reads it, or None elsewhere."""
    try:
        import fcntl

        buf = array.array("i", [0] * 64)
        fcntl.ioctl(fd, _TCGETS2, buf)
        return buf
    except (ImportError, OSError):
        return None


def _set_termios2(fd: int, buf: array.array) -> bool:
    try:
        import fcntl

        fcntl.ioctl(fd, _TCSETS2, buf)
        return True
    except (ImportError, OSError):
        return False


def _parity_is_visible(fd: int) -> bool:
    """Whether this platform's pty keeps PARENB (Linux clears it), probed once at start."""
    return bool(termios.tcgetattr(fd)[2] & termios.PARENB)


def _drain(fd: int) -> None:
    try:
        while os.read(fd, 64):
            pass
    except BlockingIOError:
        pass
