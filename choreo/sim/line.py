"""The serial line between a client and a `SimBoard`: framing, line settings and wire time.

Both transports (the in-process `sim://` port and the pseudo-terminal server) hand the bytes a
client wrote to a `Line`, together with the time they were written, and take from it the reply
bytes whose time has come. The line does what the board's UART and firmware do with a byte
stream:

- Wire time in: bytes written at `now` arrive one after another, 11 bit times each at the
  board's baud (after whatever is still on the line), so a 19-byte stop frame written at t
  has fully arrived at t + 19 * 11 / 115200 s = t + 1.81 ms. A pseudo-terminal or an in-process
  write delivers instantly, so this is where the frame's own wire time is put back. A write the
  `hold` fault hits leaves only `hold_ms` later (the client's OS or adapter held it); what is
  written after it waits behind it.
- Framing: the size byte comes first and says how many bytes make the frame. An idle gap longer
  than `gap_s` between two bytes drops an incomplete frame (the real board's gap is about
  150 us). A first byte that cannot be a size (below 3, above 128) starts a burst of noise that
  ends at the next such gap; the board answers it with a NAK.
- One reply at a time: the board does not answer a frame that starts arriving before its
  previous reply is all on the wire (see `SimBoard.receive`); a client must read each reply
  before it writes the next frame.
- Line settings: bytes sent with other settings than the board's (baud, 8 data bits, even
  parity, 1 stop bit) are garbage to a real board, which then never answers; the line drops them
  and notes why in the board's journal.
"""

from __future__ import annotations

import math

from collections import deque
from dataclasses import dataclass, field

from choreo.wire.protocol import MAX_FRAME_SIZE
from choreo.sim.board import SimBoard

REAL_GAP_S = 0.00015  # the board drops a frame after ~150 us without a byte
PTY_GAP_S = 0.020  # a pseudo-terminal and a scheduler are far less punctual than a UART


@dataclass(frozen=True)
class LineSettings:
    """A client's serial settings. None means unknown (not visible through the transport)."""

    baud: int | None
    bytesize: int | None = 8
    parity: str | None = "E"
    stopbits: float | None = 1

    def mismatch(self, board_baud: int) -> str | None:
        """Why a board at `board_baud` 8E1 could not read this client, or None if it can."""
        problems = []
        if self.baud is not None and self.baud != board_baud:
            problems.append(f"baud {self.baud}, the board's is {board_baud}")
        if self.bytesize is not None and self.bytesize != 8:
            problems.append(f"{self.bytesize} data bits, the board's are 8")
        if self.parity is not None and self.parity != "E":
            problems.append(f"parity {self.parity}, the board's is even (E)")
        if self.stopbits is not None and self.stopbits != 1:
            problems.append(f"{self.stopbits:g} stop bits, the board's is 1")
        return "; ".join(problems) or None

    def __str__(self) -> str:
        def shown(value: object) -> str:
            return "?" if value is None else f"{value:g}" if isinstance(value, float) else str(value)

        return f"{shown(self.baud)} {shown(self.bytesize)}{shown(self.parity)}{shown(self.stopbits)}"


@dataclass(frozen=True)
class Unit:
    """What the framer hands on: a `frame`, a burst of `noise`, or a `partial` frame dropped."""

    kind: str
    data: bytes
    at: float  # when the board acts on it: its last byte, or the end of the gap that closed it
    first: float | None = None  # when its first byte had fully arrived


class Framer:
    """Splits a timed byte stream into frames the way the board does (size byte first, gaps)."""

    def __init__(self, gap_s: float) -> None:
        if gap_s <= 0:
            raise ValueError(f"inter-byte gap must be > 0 s, not {gap_s}")
        self.gap_s = gap_s
        self._buf = bytearray()
        self._last = 0.0
        self._first = 0.0
        self._noise = False

    def push(self, byte: int, at: float, byte_time: float) -> list[Unit]:
        """Take one byte that has fully arrived at `at`; return the units it completes or closes."""
        units = []
        if self._buf and at - byte_time - self._last > self.gap_s:
            units.append(self._close())
        if not self._buf:
            self._noise = not 3 <= byte <= MAX_FRAME_SIZE
            self._first = at
        self._buf.append(byte)
        self._last = at
        if not self._noise and len(self._buf) == self._buf[0]:
            units.append(Unit("frame", bytes(self._buf), at, self._first))
            self._buf.clear()
        return units

    def deadline(self) -> float | None:
        """When the bytes held so far will be closed by the gap, or None if none are held."""
        return self._last + self.gap_s if self._buf else None

    def expire(self, now: float) -> Unit | None:
        """Close what is held if the gap has passed by `now`."""
        if self._buf and now > self._last + self.gap_s:
            return self._close()
        return None

    def _close(self) -> Unit:
        unit = Unit("noise" if self._noise else "partial", bytes(self._buf), self._last + self.gap_s, self._first)
        self._buf.clear()
        return unit


FTDI_PACKET = 62  # reply bytes an FTDI chip sends at once, without waiting for its timer


@dataclass
class LatencyTimer:
    """An FTDI USB adapter between the board and the client: reply bytes wait in the chip
    until its latency timer fires (every `period_s`, 16 ms by default on a real adapter), or
    until `FTDI_PACKET` bytes are waiting. The timer is modelled free-running from power-on,
    so a short reply waits anything from 0 to `period_s`, `period_s / 2` on average: the
    cautious reading of FTDI's note (it restarts on every transfer, which no log shows)."""

    period_s: float
    origin: float = 0.0
    held: list[tuple[float, int]] = field(default_factory=list)

    def release(self, arrivals: list[tuple[float, int]]) -> list[tuple[float, int]]:
        """The same bytes, at the times the client sees them."""
        out: list[tuple[float, int]] = []
        for at, byte in arrivals:
            if self.held and at > self._tick(self.held[0][0]):
                out.extend(self._flush(self._tick(self.held[0][0])))
            self.held.append((at, byte))
            if len(self.held) >= FTDI_PACKET:
                out.extend(self._flush(at))
        if self.held:
            out.extend(self._flush(self._tick(self.held[0][0])))
        return out

    def _tick(self, at: float) -> float:
        """The first timer expiry at or after `at`."""
        ticks = math.ceil((at - self.origin) / self.period_s - 1e-9)
        return self.origin + max(ticks, 0) * self.period_s

    def _flush(self, at: float) -> list[tuple[float, int]]:
        flushed, self.held = [(max(at, arrived), byte) for arrived, byte in self.held], []
        return flushed


class Line:
    """Client <-> board, on the board's clock. Single-threaded: the transport drives it."""

    def __init__(self, board: SimBoard, gap_s: float = REAL_GAP_S, latency_s: float = 0.0) -> None:
        self.board = board
        self.timer = LatencyTimer(latency_s, board.power_on) if latency_s > 0 else None
        self.framer = Framer(gap_s)
        self.settings: LineSettings | None = None  # None: unknown, assumed right
        self._in_free = float("-inf")
        self._out: deque[tuple[float, int]] = deque()

    def send(self, data: bytes, now: float) -> None:
        """The client wrote `data` at `now`: put it on the wire to the board."""
        if not data or self.board.lost:
            return
        wrong = self.settings.mismatch(self.board.baud) if self.settings else None
        if wrong:
            self.board.note("ignored", now, data, f"client line {self.settings} cannot be read by the board: {wrong}")
            return
        held = self.board.held_s(data)
        if held:
            self.board.note("held", now, data, f"held {held * 1e3:g} ms by the client's OS or adapter "
                            "before it left (fault hold)")
        bt = self.board.byte_time
        start = max(now + held, self._in_free)
        for i, byte in enumerate(bytes(data)):
            for unit in self.framer.push(byte, start + (i + 1) * bt, bt):
                self._handle(unit)
                if self.board.lost:
                    return
        self._in_free = start + len(data) * bt

    def poll(self, now: float) -> None:
        """Let time pass up to `now`: a gap may close a partial frame or a burst of noise."""
        unit = self.framer.expire(now)
        if unit is not None and not self.board.lost:
            self._handle(unit)

    def available(self, now: float) -> int:
        """Reply bytes that have fully arrived at the client by `now`."""
        count = 0
        for at, _ in self._out:
            if at > now:
                break
            count += 1
        return count

    def take(self, now: float, limit: int) -> bytes:
        """Up to `limit` reply bytes that have arrived by `now`, removed from the line."""
        got = bytearray()
        while self._out and len(got) < limit and self._out[0][0] <= now:
            got.append(self._out.popleft()[1])
        return bytes(got)

    def discard(self, now: float) -> int:
        """Drop the bytes that have arrived by `now` (a client's input flush); return how many.

        Bytes still on the wire arrive afterwards, as they would after a real flush.
        """
        dropped = 0
        while self._out and self._out[0][0] <= now:
            self._out.popleft()
            dropped += 1
        return dropped

    def next_event(self) -> float | None:
        """The next time something happens by itself: a reply byte arrives or a gap closes."""
        times = [t for t in (self._out[0][0] if self._out else None, self.framer.deadline()) if t is not None]
        return min(times) if times else None

    def pending(self) -> int:
        """Reply bytes scheduled but not yet taken, whether they have arrived or not."""
        return len(self._out)

    def _handle(self, unit: Unit) -> None:
        if unit.kind == "partial":
            expected = unit.data[0]
            self.board.note(
                "partial", unit.at, unit.data,
                f"{len(unit.data)} of {expected} bytes, then more than {self.framer.gap_s * 1e3:g} ms "
                "without a byte: dropped (write each frame in one write call)",
            )
            return
        sent = self.board.receive(unit.data, unit.at, unit.first)
        if sent is not None:
            arrivals = list(zip(sent.times, sent.data, strict=True))  # a time for each byte
            self._out.extend(self.timer.release(arrivals) if self.timer is not None else arrivals)
